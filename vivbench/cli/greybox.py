"""``vivbench greybox``: the grey-box reference refit of Y1, e1, e2, C_L over a campaign (docs/field_workflow.md (the grey-box reference))."""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path

from vivbench.core.errors import InputError

_BRIDGE_KEYS = ("mass", "depth", "frequency", "damping_ratio", "air_density", "mode_shape", "tributary_lengths")


def _numbers(text: str, what: str) -> tuple[float, ...]:
    try:
        return tuple(float(x) for x in text.replace(",", " ").split())
    except ValueError:
        raise InputError(f"--{what} must be numbers separated by commas, e.g. 0.707,1,0.707; got {text!r}") from None


def bridge_from_args(args, result_files):
    """BridgeProperties from ``--bridge FILE`` (TOML, a ``[bridge]`` table or top-level keys) and the options.

    Options override the file; the frequency defaults to the one ``vivbench identify`` found.
    """
    from vivbench.analysis.greybox import results_frequency
    from vivbench.core.toml import load_toml
    from vivbench.models.greybox import BridgeProperties

    data: dict = {}
    if args.bridge:
        raw = load_toml(args.bridge, lambda d: d, what="bridge file")
        data = dict(raw.get("bridge", raw))
        unknown = set(data) - set(_BRIDGE_KEYS)
        if unknown:
            raise InputError(f"{args.bridge}: unknown bridge key(s) {sorted(unknown)}; allowed: {list(_BRIDGE_KEYS)}")
    for key in ("mass", "depth", "frequency", "damping_ratio", "air_density"):
        v = getattr(args, key)
        if v is not None:
            data[key] = v
    for key in ("mode_shape", "tributary_lengths"):
        v = getattr(args, key)
        if v is not None:
            data[key] = _numbers(v, key.replace("_", "-"))
    if "frequency" not in data:
        f = results_frequency(result_files)
        if f is None:
            raise InputError("no --frequency given and the results carry no mode frequency (f_mode_hz)")
        data["frequency"] = f
    missing = [k for k in ("mass", "depth", "damping_ratio") if k not in data]
    if missing:
        raise InputError(f"the bridge's {', '.join(missing)} must be given (--bridge FILE or "
                         f"{' '.join('--' + m.replace('_', '-') for m in missing)}): the fit never reads a truth")
    return BridgeProperties.from_dict(data)


def run(args) -> int:
    import numpy as np
    import pandas as pd

    from vivbench.analysis.greybox import greybox_results
    from vivbench.cli.common import write_command
    from vivbench.io.greybox import GREYBOX_NAME
    from vivbench.io.netcdf import atomic_path
    from vivbench.io.result import list_results, select_results
    from vivbench.models.greybox import GreyBoxRefit
    from vivbench.report.greybox import (greybox_curves_figure, greybox_functions_figure,
                                         greybox_simulation_figure, greybox_yaw_figure)

    results_dir = Path(args.results)
    files = list_results(results_dir)
    if args.events is not None:
        files = select_results(files, args.events)
    bridge = bridge_from_args(args, files)
    out_dir = Path(args.out)
    out_dir.mkdir(parents=True, exist_ok=True)
    grid = None if args.penalty_grid.strip().lower() == "none" else _numbers(args.penalty_grid, "penalty-grid")
    estimator = GreyBoxRefit(n_basis=args.n_basis, penalty=args.penalty, penalty_grid=grid, band=args.band, dt=args.dt,
                             shooting_interval=args.interval, max_iter=args.max_iter, yaw_factor=not args.no_yaw,
                             n_starts=args.starts, seed=args.seed, block_s=args.block, n_boot=args.boot,
                             boot_iter=args.boot_iter, wind_draws=args.wind_draws, wind_scale=args.wind_scale,
                             wind_iter=args.wind_iter)
    t0 = time.perf_counter()

    def progress(it, cost, mu):
        print(f"\rvivbench greybox: Gauss-Newton iteration {it}, cost {cost:.6g}", end="", file=sys.stderr)

    outcome = greybox_results(files, bridge, model=estimator, warm_start=None if args.no_warm_start else "auto",
                              tau=args.tau, agreement=args.agreement, n_draws=args.draws, callback=progress,
                              wind_smoothing_s=args.wind_smoothing)
    print("", file=sys.stderr)
    seconds = time.perf_counter() - t0
    model = outcome.model
    path = model.save(out_dir / GREYBOX_NAME)
    events = pd.DataFrame(outcome.events)
    with atomic_path(out_dir / "greybox_events.csv", suffix=".csv") as tmp:
        events.to_csv(tmp, index=False, float_format="%.6g")
    w = outcome.windows
    rows = []
    for k, eq in enumerate(w["equation"].values):
        rows.append(pd.DataFrame({"event_id": w["event_id"].values, "window_start": w["window_start"].values,
                                  "window_end": w["window_end"].values, "equation": str(eq),
                                  "regime": w["regime"].values[:, k], "identifiable": w["identifiable"].values[:, k],
                                  "agreement": w["agreement"].values[:, k]}))
    table = pd.concat(rows, ignore_index=True)
    with atomic_path(out_dir / "greybox_windows.csv.gz", suffix=".gz") as tmp:
        table.to_csv(tmp, index=False, float_format="%.6g", compression="gzip")
    per_event = table.groupby("event_id").agg(windows=("regime", "size"), coverage=("identifiable", "mean"),
                                              **{f"share_regime_{r}": ("regime", lambda x, r=r: float(np.mean(x == r)))
                                                 for r in (1, 2, 3, 4)}).reset_index()
    with atomic_path(out_dir / "greybox_regimes.csv", suffix=".csv") as tmp:
        per_event.to_csv(tmp, index=False, float_format="%.4g")
    info = model.fit_info_
    summary = {"command": "vivbench " + " ".join(args.argv) if getattr(args, "argv", None) else None,
               "n_events": len(files), "warm_start": outcome.warm_start, "fit_seconds": info["seconds"],
               "total_seconds": seconds, "iterations": info["iterations"], "converged": info["converged"],
               "max_continuity_defect": info["max_defect"], "n_intervals": info["n_intervals"],
               "start": info["start"], "starts": info.get("starts", []), "yaw": info.get("yaw"),
               "penalty": info.get("penalty"), "penalty_criterion": info.get("penalty_criterion"),
               "penalty_selection": info.get("penalty_selection"), "band": info.get("band"),
               "band_info": info.get("band_info"),
               "bootstrap": info.get("bootstrap"),
               "yaw_coef": model.yaw_coef_, "yaw_coef_lower": float(model.yaw_curve()["yaw_coef_lower"]),
               "yaw_coef_upper": float(model.yaw_curve()["yaw_coef_upper"]), "wind_smoothing_s": args.wind_smoothing,
               "nmse_median": float(np.nanmedian(events["nmse"])), "regime_coverage": float(table["identifiable"].mean()),
               "verdict_bounds": w.attrs.get("verdict_bounds"), "verdict_reference": w.attrs.get("verdict_reference")}
    if info.get("wind_error"):
        from vivbench.core.terms import reference_section

        # how much of a_k1's band (reference section) the wind's errors-in-variables make, median over the winds
        comp = model.band_components()["band_sd"].isel(equation=reference_section(model.n_sections_), order=1)
        summary["wind_band_variance_share"] = float(np.nanmedian(comp.sel(component="wind") ** 2
                                                                 / (comp**2).sum("component")))
    campaign_curves = None
    truth_curves = truth_functions = truth_yaw = None
    from vivbench.analysis.pool import campaign_model_file, load_campaign_model
    cm_path = campaign_model_file(results_dir)
    if cm_path is not None:
        try:
            campaign_curves = load_campaign_model(cm_path).curves(model.default_wind())
        except (InputError, AttributeError, ValueError):
            campaign_curves = None
    if args.campaign:
        from vivbench.cli.common import event_paths
        from vivbench.io.event import read_event
        from vivbench.validate.campaign import event_truth_curves
        from vivbench.validate.greybox import greybox_recovery, truth_y1, truth_yaw_factor

        event_files = event_paths([args.campaign])
        v = greybox_recovery(model, event_files, outcome.windows, outcome.events, campaign_curves=campaign_curves,
                             tau=args.tau, records=outcome.records)
        with atomic_path(out_dir / "greybox_validation.json", suffix=".json") as tmp:
            tmp.write_text(json.dumps(v, indent=1, default=float) + "\n")
        summary.update({f"truth_{k}": val for k, val in v["summary"].items()})
        truth = read_event(event_files[0])["truth"].ds
        truth_curves = event_truth_curves(truth)
        ur = model.physical_curves()["reduced_velocity"].values
        wind = model.default_wind()
        y1 = truth_y1(truth, wind)
        if y1 is not None:
            truth_functions = {"Ur": ur, "Y1": y1}
        truth_yaw = truth_yaw_factor(truth, model.yaw_curve()["yaw"].values)
    greybox_functions_figure(model.physical_curves(), out_dir / "greybox_functions.png", truth=truth_functions)
    greybox_curves_figure(model.curves(), out_dir / "greybox_curves.png", campaign=campaign_curves, truth=truth_curves)
    measured_yaw = [r.yaw for r in outcome.records if r.yaw is not None]
    greybox_yaw_figure(model.yaw_curve(), out_dir / "greybox_yaw.png", truth=truth_yaw,
                       measured=np.concatenate([y.ravel() for y in measured_yaw]) if measured_yaw else None)
    order = np.argsort(-events["nmse"].fillna(np.inf).values)
    picks = [order[len(order) // 2], order[0], order[-1]] if len(order) >= 3 else list(order)
    from vivbench.analysis.pool import records_from_results
    recs = records_from_results([files[i] for i in picks], derivative=None, wind_smoothing_s=args.wind_smoothing)
    sims = [(r.event_id, model.simulate(r)) for r in recs]
    greybox_simulation_figure(sims, out_dir / "greybox_simulations.png")
    with atomic_path(out_dir / "summary.json", suffix=".json") as tmp:
        tmp.write_text(json.dumps(summary, indent=1, default=float) + "\n")
    write_command(out_dir, getattr(args, "argv", []) or [])
    print(f"wrote {path}: {len(files)} events, {info['iterations']} Gauss-Newton iterations in {info['seconds']:.1f} s "
          f"({'converged' if info['converged'] else 'NOT converged: ' + info['message']}), median simulation NMSE "
          f"{summary['nmse_median']:.3g}, regime coverage {summary['regime_coverage']:.3f}")
    yc = model.yaw_curve()
    bi = info.get("band_info") or {}
    print(f"penalty {info.get('penalty', model.penalty):g} ({info.get('penalty_criterion', 'given')}); bands: "
          f"{info.get('band', '')}, sigma^2 {bi.get('sigma2', float('nan')):.3g}, kappa "
          f"{bi.get('kappa', float('nan')):.3g}, edf {bi.get('edf', float('nan')):.1f}")
    wi = info.get("wind_error")
    if wi:
        share = summary["wind_band_variance_share"]
        print(f"wind's errors-in-variables: {wi['n_draws']} refits with drawn wind errors (anemometers' RMS relative "
              f"spread {wi['relative_spread_rms']:.3f}, scale {wi['scale']:g}) in {wi['seconds']:.1f} s; median share "
              f"of the wind component in the variance of a_k1's band {share:.2f}"
              + ("" if model.band == "sandwich_bias_wind" else f" (not in the band {model.band!r})"))
    print(f"start: {info['start']}; {info.get('yaw', '')}" + (
        f"; c = {model.yaw_coef_:.3g} [{float(yc['yaw_coef_lower']):.3g}, {float(yc['yaw_coef_upper']):.3g}]"
        if model.yaw_used_ else ""))
    if args.campaign:
        s = v["summary"]
        print(f"against the truth: a_k1 error {s['curve_error_linear']:.3f} (band coverage "
              f"{s['linear_band_coverage']:.2f}), Y1 error {s['y1_error']:.3f} (band coverage "
              f"{s['y1_band_coverage']:.2f}), dA/dt from the curves {s['curve_error_total']:.3f} (energy-weighted "
              f"{s['curve_error_energy']:.3f}), dA/dt on the true (A, U) median "
              f"{s['rhs_error_true_AU_median_active']:.3f} / energy-weighted {s['rhs_error_true_AU_energy']:.3f}, "
              "flagged windows "
              f"with the true regime {s.get('regime_precision_identifiable', float('nan')):.3f}")
    return 0


def register(sub) -> None:
    s = sub.add_parser("greybox", help="grey-box reference refit: Y1, e1, e2, C_L splines fitted by output error "
                                       "to all events (CasADi multiple shooting, Gauss-Newton)")
    s.add_argument("results", help="directory of <event_id>.identify.nc (and campaign.model.nc of vivbench pool, "
                                   "the warm start)")
    s.add_argument("--out", required=True, help="output directory (greybox.nc, tables, figures)")
    s.add_argument("--events", default=None, metavar="SPEC",
                   help="refit only these events: comma-separated ids and ranges in the campaign's order (E003, "
                        "E007.. from E007 on, ..E006, E002..E005), as vivbench pool --events")
    s.add_argument("--bridge", default=None, metavar="FILE",
                   help="TOML with the bridge's properties ([bridge] mass, depth, frequency, damping_ratio, "
                        "air_density, mode_shape, tributary_lengths)")
    s.add_argument("--mass", type=float, default=None, help="modal mass per unit length m, kg/m")
    s.add_argument("--depth", type=float, default=None, help="deck depth D, m")
    s.add_argument("--frequency", type=float, default=None,
                   help="mode frequency f, Hz (default: the one vivbench identify found)")
    s.add_argument("--damping-ratio", dest="damping_ratio", type=float, default=None,
                   help="structural damping ratio zeta (from free decays at quiet wind)")
    s.add_argument("--air-density", dest="air_density", type=float, default=None, help="air density, kg/m^3 "
                                                                                         "(default 1.225)")
    s.add_argument("--mode-shape", dest="mode_shape", default=None,
                   help="phi_k at the sections, e.g. 0.707,1,0.707 (default: |phi| from the amplitude ratios)")
    s.add_argument("--tributary-lengths", dest="tributary_lengths", default=None,
                   help="L_k of the sections' strips, m (default: equal)")
    s.add_argument("--n-basis", dest="n_basis", type=int, default=16, help="B-splines per function (default 16)")
    s.add_argument("--penalty", type=float, default=0.3,
                   help="relative roughness penalty of the first fit (default 0.3); the final one with "
                        "--penalty-grid none")
    s.add_argument("--penalty-grid", dest="penalty_grid", default="0.1,0.3,1",
                   help="penalties whose fits (continued from the one at --penalty) are scored by GCV with the "
                        "effective sample size of the correlated residuals; the best is kept (default 0.1,0.3,1; "
                        "'none': keep --penalty)")
    s.add_argument("--band", choices=("posterior", "sandwich", "sandwich_bias", "bootstrap", "bootstrap_bias",
                                      "sandwich_bias_wind"),
                   default="sandwich_bias_wind",
                   help="covariance of the bands: the Bayesian posterior sigma^2 kappa (J'J + R)^-1, the block "
                        "sandwich (variance only), the sandwich plus the prior-averaged squared smoothing bias "
                        "(the posterior alone is narrower than the sandwich), or the event "
                        "bootstrap's covariance (needs --boot >= 20), alone or plus the same bias, or sandwich_bias "
                        "plus the wind's errors-in-variables (default; needs --wind-draws >= 2)")
    s.add_argument("--wind-draws", dest="wind_draws", type=int, default=4, metavar="N",
                   help="refits with the wind perturbed by draws of the anemometers' error (other events' spread "
                        "between the sections' anemometers), for the band's wind component (default 4; 0: none, "
                        "then give another --band)")
    s.add_argument("--wind-scale", dest="wind_scale", type=float, default=1.0,
                   help="factor on the drawn wind error's size (default 1)")
    s.add_argument("--wind-iter", dest="wind_iter", type=int, default=2, metavar="K",
                   help="Levenberg-Marquardt iterations of a wind refit in each of its two continuation stages "
                        "(default 2)")
    s.add_argument("--boot", type=int, default=0, metavar="N",
                   help="event bootstrap replicates after the fit (refits on events drawn with replacement, "
                        "seeded by --seed; default 0: none; each costs up to 2 (--boot-iter + 1) Jacobians, "
                        "so tens of replicates take minutes)")
    s.add_argument("--boot-iter", dest="boot_iter", type=int, default=10, metavar="K",
                   help="Gauss-Newton iterations of a bootstrap replicate from the fit's optimum in each of its "
                        "two continuation stages (default 10)")
    s.add_argument("--dt", type=float, default=1.0, help="step of the fit grid, s (default 1)")
    s.add_argument("--interval", type=float, default=60.0, help="shooting interval, s (default 60)")
    s.add_argument("--max-iter", dest="max_iter", type=int, default=30,
                   help="Gauss-Newton iterations per continuation stage (default 30)")
    s.add_argument("--no-warm-start", dest="no_warm_start", action="store_true",
                   help="start from an equation-error fit instead of the campaign model's curves")
    s.add_argument("--no-yaw", dest="no_yaw", action="store_true",
                   help="no yaw factor: Y1 and C_L independent of the measured yaw (default: 1 - c sin^2(yaw), "
                        "c fitted, when the results carry the yaw)")
    s.add_argument("--starts", type=int, default=4,
                   help="multi-start: warm start, equation-error start and perturbed starts, screened by their "
                        "penalised cost (default 4; 1: the first only)")
    s.add_argument("--seed", type=int, default=0, help="seed of the perturbed starts (default 0)")
    s.add_argument("--block", type=float, default=86400.0, metavar="S",
                   help="block length of the sandwich covariance, s: residuals are taken as correlated within a "
                        "block of one event, independent between blocks (default a day: one block per event)")
    s.add_argument("--wind-smoothing", dest="wind_smoothing", type=float, default=30.0, metavar="S",
                   help="Gaussian smoothing of the measured wind and yaw in time, standard deviation in s "
                        "(the deck feels the tributary-averaged wind, the anemometer is a point; default 30; "
                        "0: none)")
    s.add_argument("--tau", type=float, default=0.2, help="regime threshold (docs/concepts.md (regimes))")
    s.add_argument("--agreement", type=float, default=0.95,
                   help="share of parameter draws that must agree on a window's regime (default 0.95)")
    s.add_argument("--draws", type=int, default=100, help="parameter draws for the verdicts (default 100)")
    s.add_argument("--campaign", default=None, metavar="DIR",
                   help="synthetic campaign: score the refit against its truth (validation only; the fit never "
                        "reads it)")
    s.set_defaults(func=run)
