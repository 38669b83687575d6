"""Benchmark: campaign models on realistic (misspecified) campaigns, against the truth's own (A, U).

Run::

    vivbench synth --events 31 --seed 1 --config realistic.toml --out CAMP --workers 2
    vivbench identify CAMP --out ID --workers 2
    .venv/bin/python benchmarks/study_misspecification.py --campaign CAMP --results ID [--campaign ... --results ...]

(``realistic.toml``: ``[aero] mode = "realistic"`` and ``[wind] felt_wind = "tributary"``.)

For each campaign, every model is fitted twice: on the identification's
records (measured A and U, dA/dt recomputed with ``CAMPAIGN_DERIVATIVE``, as
``vivbench pool`` does) and, to separate errors-in-variables from the basis,
on the truth's own (A, U, dA) (truth grid, dA = sum over orders of /truth/r).
Both are scored on the truth's (A, U):

- ``dA err``: per window and section, relative RMS error of the model's dA/dt
  against the truth's, over the (window, section) pairs with dynamics (true
  dA/dt RMS over the window >= 10 % of its RMS over the event); median and
  90th percentile;
- ``regime acc``: share of all (window, section) pairs whose regime from the
  model's order contributions on the truth's (A, U) equals the true regime;
- for the models fitted on measured data, the verdicts on the measured record
  (what a user would have): ``coverage`` (share of windows flagged
  identifiable) and ``flag acc`` (share of the flagged with the true regime);
  the noise-floor gate of ``vivbench pool`` (amplitude_snr < min_snr) applies.
  PooledSINDy's verdicts (``campaign_window_verdicts``) only with ``--pooled-verdicts`` (slow).

Models: PooledSINDy (STLSQ + AICc on A^i U^j, j <= 5) and VaryingCoefficientSINDy
(penalised cubic splines in U; M and lambda by 5-fold cross-validation over events),
with the mean wind's yaw as a second covariate in the "mean U, yaw" row (the
measured records carry the results' ``yaw``, or for older results the yaw
measured from the event's anemometers; the truth's record gets the latter on
its own grid). The "additive U, yaw" rows sum a curve of every section's
wind and yaw in each equation (``wind_input="additive"``), with
``SEED0_ADDITIVE_SETTINGS`` (chosen on the seed-0 campaign) or the model's own CV
("own CV"). ``--wind-smoothing S`` is the varying models' ``wind_smoothing_s``
(default: the model's, 30 s; ``cv``: chosen per campaign from ``WIND_SMOOTHING_GRID``
by the model's cross-validation over events): the fit on the measured records smooths their U
and yaw, the verdicts use ``model.measured_wind`` of the measured record, the
truth's (A, U) is evaluated as it is (the deck's own wind; fits on the truth
use no smoothing), ``--only TEXT`` fits only the models whose
name contains TEXT, ``--no-truth-fits`` skips the fits on the truth, ``--n-basis 6,8,...``
sets the varying models' candidate numbers of B-splines, ``--model-set-level L`` their
``model_set_level``, ``--no-eiv-weights`` their ``eiv_weights=False``, ``--wind-weights`` and
``--penalty-choice`` their ``wind_weights`` and ``penalty_choice`` (default: equal and cv, the settings of every
figure this benchmark gave).
``--substitute U,A,dA,U+A+dA`` adds, for the varying models, fits on
the measured records with some inputs replaced by the truth's (interpolated to the
measured grid, the measured gaps kept): which errors-in-variables cost most
(a replaced U is the deck's own wind and is fitted without smoothing; the
verdicts then use the replaced record too). The
verdict columns also count ``n_flag_self_excited_wrong`` (flagged regime 2-4
where the truth is regime 1) in the JSON.
Nothing is asserted; the table is printed and written to ``benchmarks/out/misspecification.json``.
"""

from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import json  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
import xarray as xr  # noqa: E402

import dataclasses  # noqa: E402

from vivbench.analysis import CAMPAIGN_DERIVATIVE, event_yaw, records_from_results  # noqa: E402
from vivbench.core.record import Record  # noqa: E402
from vivbench.models import PooledSINDy, VaryingCoefficientSINDy  # noqa: E402
from varying_settings import SEED0_ADDITIVE_SETTINGS  # noqa: E402
from vivbench.models.varying import WIND_SMOOTHING_GRID  # noqa: E402
from vivbench.regimes import (campaign_window_verdicts, model_window_regimes, truth_window_regimes,  # noqa: E402
                              varying_window_verdicts)

OUT = Path(__file__).resolve().parent / "out"


def _window_sums(x, t, start, end):
    lo, hi = np.searchsorted(t, start, side="left"), np.searchsorted(t, end, side="left")
    c = np.concatenate([np.zeros((1,) + x.shape[1:]), np.cumsum(x, axis=0)])
    return c[hi] - c[lo]


def load_campaign(camp: Path, results: Path, yaw: bool = True):
    """Measured records, truth records (with dA), truth datasets, windows and noise-floor flags per event.

    With ``yaw`` both records carry the mean wind's yaw measured from the event's
    anemometers (the truth's own yaw is not stored: its record gets the measured one).
    """
    files = sorted(results.glob("*.identify.nc"))
    measured = records_from_results(files, derivative=CAMPAIGN_DERIVATIVE, campaign=camp if yaw else None)
    events = []
    for f, rec in zip(files, measured):
        with xr.open_dataset(f) as ds:
            ws, we = ds["window_start"].values, ds["window_end"].values
            attrs = dict(ds.attrs)
            snr = ds["amplitude_snr"].values if "amplitude_snr" in ds else None
        min_snr = json.loads(attrs.get("identify_config_json", "{}")).get("min_snr")
        low = (snr < min_snr) if (snr is not None and min_snr is not None) else np.zeros((ws.size, rec.n_sections), bool)
        with xr.open_dataset(camp / attrs["source_file"], group="truth") as tr:
            truth = tr.load()
        trec = Record(event_id=rec.event_id, t=truth["time"].values, A=truth["A"].values, U=truth["U"].values,
                      dA=truth["r"].values.sum(axis=-1))
        if yaw:
            with xr.open_dataset(camp / attrs["source_file"], group="wind") as w:
                tw, u, v = w["time"].values, w["u"].values, w["v"].values
            with xr.open_dataset(camp / attrs["source_file"]) as root:
                az = float(root.attrs["span_azimuth_deg"])
            trec = dataclasses.replace(trec, yaw=event_yaw(tw, u, v, az, trec.t))
        else:
            rec = dataclasses.replace(rec, yaw=None)
        events.append({"id": rec.event_id, "measured": rec, "truth_rec": trec, "truth": truth, "ws": ws, "we": we,
                       "low_snr": low, "true_regime": truth_window_regimes(truth, ws, we)})
    return [ev["measured"] for ev in events], events


SUBSTITUTABLE = ("U", "A", "dA")


def substitute(ev: dict, what: tuple[str, ...]) -> Record:
    """The event's measured record with the inputs ``what`` (of ``SUBSTITUTABLE``) replaced by the truth's.

    The truth (its own grid) is interpolated linearly onto the measured grid;
    samples missing in the measured record stay missing.
    """
    rec, trec = ev["measured"], ev["truth_rec"]
    new = {}
    for name in what:
        src = getattr(trec, name)
        x = np.stack([np.interp(rec.t, trec.t, src[:, k], left=np.nan, right=np.nan) for k in range(src.shape[1])],
                     axis=1)
        new[name] = np.where(np.isfinite(getattr(rec, name)), x, np.nan)
    return dataclasses.replace(rec, **new)


def window_dA_errors(pred: np.ndarray, ev: dict) -> np.ndarray:
    """Relative RMS errors of ``pred`` (the truth's grid, (n, S)) against the truth's dA/dt per (window, section).

    Only the pairs with dynamics: true dA/dt RMS over the window >= 10 % of its RMS over the event.
    """
    trec, ws, we = ev["truth_rec"], ev["ws"], ev["we"]
    t, true = trec.t, trec.dA
    okp = np.isfinite(pred) & np.isfinite(true)
    num = _window_sums(np.where(okp, (pred - true) ** 2, 0.0), t, ws, we)
    den = _window_sums(np.where(okp, true**2, 0.0), t, ws, we)
    cnt = _window_sums(okp.astype(float), t, ws, we)
    event_ms = np.nanmean(np.where(okp, true, np.nan) ** 2, axis=0)
    with np.errstate(invalid="ignore", divide="ignore"):
        dyn = (cnt > 0) & (den / np.maximum(cnt, 1) >= 0.01 * event_ms)  # RMS >= 10 % of the event's
        return np.sqrt(num / den)[dyn]


def score(model, events, verdicts: str | None = None, records=None) -> dict:
    """dA/dt error and regime accuracy on the truth's (A, U); verdicts on the measured record when asked.

    ``records`` (one per event) replaces the measured records of the verdicts (e.g. :func:`substitute`'s).
    """
    errs, hits, n_reg, flagged, flag_ok, n_win, flag_self = [], 0, 0, 0, 0, 0, 0
    for e, ev in enumerate(events):
        trec, ws, we = ev["truth_rec"], ev["ws"], ev["we"]
        errs.append(window_dA_errors(model.predict(trec), ev))
        reg = model_window_regimes(model, trec, ws, we)["regime"]
        tr = ev["true_regime"]
        valid = tr > 0
        hits += int(((reg == tr) & valid).sum())
        n_reg += int(valid.sum())
        if verdicts is not None:
            rec = ev["measured"] if records is None else records[e]
            if verdicts == "varying":
                v = varying_window_verdicts(model, model.measured_wind(rec), ws, we)
            else:
                v = campaign_window_verdicts(model, rec.t, rec.A, rec.U, ws, we)
            flag = v["identifiable"] & ~ev["low_snr"] & valid
            flagged += int(flag.sum())
            flag_ok += int((flag & (v["regime"] == tr)).sum())
            flag_self += int((flag & (v["regime"] >= 2) & (tr == 1)).sum())
            n_win += int((valid & (v["regime"] > 0)).sum())
    e = np.concatenate(errs)
    out = {"dA_err_median": float(np.median(e)), "dA_err_p90": float(np.percentile(e, 90)), "n_dyn": int(e.size),
           "regime_acc": hits / max(n_reg, 1)}
    if verdicts is not None:
        out["coverage"] = flagged / max(n_win, 1)
        out["flag_acc"] = flag_ok / flagged if flagged else float("nan")
        out["n_flagged"] = flagged
        out["n_flag_self_excited_wrong"] = flag_self  # flagged 2-4 where the truth is regime 1
    return out


def run(camp: Path, results: Path, pooled_verdicts: bool = False, select_orders: bool = False,
        only: str | None = None, truth_fits: bool = True, wind_smoothing_s: float | None = None,
        n_basis: tuple[int, ...] | None = None, model_set_level: float | None = None,
        substitutions: tuple[tuple[str, ...], ...] = (), eiv_weights: bool = True, wind_weights="equal",
        penalty_choice: str = "cv") -> dict:
    t0 = time.perf_counter()
    if wind_smoothing_s == "cv":  # chosen per campaign by the model's cross-validation over events
        vary = {"wind_smoothing_grid": WIND_SMOOTHING_GRID}
    else:
        vary = {} if wind_smoothing_s is None else {"wind_smoothing_s": float(wind_smoothing_s)}
    if n_basis is not None:
        vary["n_basis"] = tuple(n_basis)
    if model_set_level is not None:
        vary["model_set_level"] = float(model_set_level)
    if not eiv_weights:
        vary["eiv_weights"] = False
    vary["wind_weights"], vary["penalty_choice"] = wind_weights, penalty_choice
    measured, events = load_campaign(camp, results)
    truth_records = [ev["truth_rec"] for ev in events]
    print(f"{camp}: {len(events)} events, loaded in {time.perf_counter() - t0:.1f} s", flush=True)
    rows = {}
    specs = [
        ("PooledSINDy", lambda: PooledSINDy(n_bootstrap=100 if pooled_verdicts else 0), "pooled"),
        # The default evaluates the curves at the mean wind over the sections (chosen on the seed-0 campaign).
        ("VaryingCoefficientSINDy(mean U)", lambda: VaryingCoefficientSINDy(select_orders=select_orders, yaw_degree=0, **vary), "varying"),
        # The wind's yaw as a second covariate (chosen on the seed-0 campaign, benchmarks/study_floor.py).
        ("VaryingCoefficientSINDy(mean U, yaw)",
         lambda: VaryingCoefficientSINDy(select_orders=select_orders, yaw_degree=1, **vary), "varying"),
        # Every section's wind and yaw in every equation, summed over the sections like the truth's forces,
        # with its settings chosen on the seed-0 campaign (SEED0_ADDITIVE_SETTINGS; the options override them) ...
        ("VaryingCoefficientSINDy(additive U, yaw)",
         lambda: VaryingCoefficientSINDy(select_orders=select_orders, wind_input="additive", yaw_degree=1,
                                         **{**SEED0_ADDITIVE_SETTINGS, **vary}), "varying"),
        # ... and with the model's own cross-validated basis and penalty.
        ("VaryingCoefficientSINDy(additive U, yaw, own CV)",
         lambda: VaryingCoefficientSINDy(select_orders=select_orders, wind_input="additive", yaw_degree=1, **vary),
         "varying"),
        ("VaryingCoefficientSINDy(own U)",
         lambda: VaryingCoefficientSINDy(select_orders=select_orders, wind_input="section", yaw_degree=0, **vary),
         "varying"),
    ]
    for name, make, kind in specs:
        if only is not None and only not in name:
            continue
        for data, recs in (("measured", measured), ("truth", truth_records))[:2 if truth_fits else 1]:
            t1 = time.perf_counter()
            model = make()
            if kind == "varying" and data == "truth":
                # the deck's own wind: nothing to correct
                model.set_params(wind_smoothing_s=0.0, wind_smoothing_grid=None)
            model = model.fit(recs)
            fit_s = time.perf_counter() - t1
            want = None if data == "truth" or (kind == "pooled" and not pooled_verdicts) else kind
            row = score(model, events, verdicts=want)
            row["fit_s"] = fit_s
            if kind == "varying":
                row["n_basis"] = model.n_basis_.tolist()
                row["penalty"] = model.penalty_.tolist()
                row["edf"] = np.round(model.edf_, 1).tolist()
                row["orders"] = model.orders_.astype(int).tolist()
                row["wind_smoothing_s"] = model.fitted_wind_smoothing()
                row["wind_smoothing_cv"] = np.round(model.wind_smoothing_cv_, 5).tolist()
                row["wind_error_share"] = np.round(getattr(model, "wind_error_share_", np.zeros(0)), 3).tolist()
            rows[f"{name} fitted on {data}"] = row
            print(f"  {name:<32} on {data:<8} {json.dumps(row)}", flush=True)
        for what in substitutions if kind == "varying" else ():
            recs = [substitute(ev, what) for ev in events]
            t1 = time.perf_counter()
            model = make()
            if "U" in what:
                model.set_params(wind_smoothing_s=0.0, wind_smoothing_grid=None)  # the deck's own wind
            model = model.fit(recs)
            row = score(model, events, verdicts="varying", records=recs)
            row["fit_s"] = time.perf_counter() - t1
            row["wind_smoothing_s"] = model.fitted_wind_smoothing()
            label = "measured, true " + "+".join(what)
            rows[f"{name} fitted on {label}"] = row
            print(f"  {name:<32} on {label:<8} {json.dumps(row)}", flush=True)
    return rows


def print_table(title: str, rows: dict) -> None:
    print(f"\n{title}")
    head = f"{'model':<62} {'dA err med':>10} {'p90':>6} {'regime acc':>10} {'coverage':>8} {'flag acc':>8} {'fit s':>6}"
    print(head)
    print("-" * len(head))
    for name, r in rows.items():
        cov = f"{r['coverage']:8.3f}" if "coverage" in r else f"{'-':>8}"
        acc = f"{r['flag_acc']:8.3f}" if "flag_acc" in r else f"{'-':>8}"
        print(f"{name:<62} {r['dA_err_median']:10.3f} {r['dA_err_p90']:6.2f} {r['regime_acc']:10.3f} {cov} {acc} "
              f"{r['fit_s']:6.1f}")


def main(argv=None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--campaign", action="append", required=True, type=Path)
    parser.add_argument("--results", action="append", required=True, type=Path)
    parser.add_argument("--pooled-verdicts", action="store_true")
    parser.add_argument("--select-orders", action="store_true")
    parser.add_argument("--wind-smoothing", default=None,
                        help="the varying models' wind_smoothing_s, s (default: the model's own, 30), or 'cv': "
                             "chosen by the model's cross-validation from WIND_SMOOTHING_GRID")
    parser.add_argument("--n-basis", default=None,
                        help="comma-separated candidate numbers of B-splines of the varying models (default: the model's)")
    parser.add_argument("--model-set-level", type=float, default=None,
                        help="the varying models' model_set_level (default: the model's)")
    parser.add_argument("--no-eiv-weights", action="store_true",
                        help="the varying models' eiv_weights=False (default: the model's, True: effective-variance "
                             "weights against the wind error)")
    parser.add_argument("--wind-weights", default="equal", choices=("equal", "modal"),
                        help="the varying models' wind_weights: the sections' weights in the mean wind (default: "
                             "equal, the setting of this benchmark's earlier figures)")
    parser.add_argument("--penalty-choice", default="cv", choices=("cv", "least", "loeo"),
                        help="the varying models' penalty_choice (default: cv)")
    parser.add_argument("--substitute", default="",
                        help="comma-separated truth substitutions for the varying models, each a '+'-joined "
                             "subset of U, A, dA (e.g. 'U,A,dA'): fits on the measured records with those inputs "
                             "replaced by the truth's")
    parser.add_argument("--only", default=None, help="fit only the models whose name contains this text")
    parser.add_argument("--json", type=Path, default=OUT / "misspecification.json", help="where the rows are written")
    parser.add_argument("--no-truth-fits", action="store_true", help="skip the fits on the truth's own (A, U, dA)")
    args = parser.parse_args(argv)
    if len(args.campaign) != len(args.results):
        parser.error("give one --results per --campaign")
    subs = tuple(tuple(x.split("+")) for x in args.substitute.split(",") if x)
    for what in subs:
        if not set(what) <= set(SUBSTITUTABLE):
            parser.error(f"--substitute: each variant is a '+'-joined subset of {', '.join(SUBSTITUTABLE)}; "
                         f"got {'+'.join(what)!r}")
    out = {}
    for camp, res in zip(args.campaign, args.results):
        out[str(camp)] = run(camp, res, args.pooled_verdicts, args.select_orders, args.only, not args.no_truth_fits,
                             args.wind_smoothing,
                             None if args.n_basis is None else tuple(int(x) for x in args.n_basis.split(",")),
                             args.model_set_level, subs, not args.no_eiv_weights, args.wind_weights,
                             args.penalty_choice)
    for camp, rows in out.items():
        print_table(f"{camp}: dA/dt error and regimes on the truth's (A, U)", rows)
    args.json.parent.mkdir(parents=True, exist_ok=True)
    args.json.write_text(json.dumps(out, indent=2) + "\n")
    return out


if __name__ == "__main__":
    main()
