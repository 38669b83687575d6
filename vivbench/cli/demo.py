"""``vivbench demo``: the whole chain on the default synthetic campaign (the realistic generator mode).

Generate, identify, pool, cluster, forecast, refit, greybox, validate and report, each
step as the subcommand a user would run (its exact command is written to
``command.txt`` in the step's directory, so the report can cite it). A step
that fails is reported on one line and the later steps still run where they
can. Progress and the steps' own output go to stderr; stdout gets a short
summary: where the report is, and the headline recovery figures.

``--baseline in_library`` runs the same chain (without the refit) on an
``in_library`` campaign of the same seed and durations (the truth inside the
identification's model class: the inverse crime, docs/concepts.md (no inverse crime)) into
``OUT/baseline_in_library`` and passes it to ``vivbench report --baseline``,
which shows both campaigns' recovery side by side. It is off by default: it
roughly doubles the demo's time.
"""

from __future__ import annotations

import contextlib
import json
import math
import shlex
import subprocess
import sys
import tempfile
from pathlib import Path

from vivbench.cli.common import DEFAULT_WORKERS, duration, write_command
from vivbench.core.errors import InputError



# Each section's own terms: forcing (U^2), linear damping and its wind dependence, the two amplitude limits.
REFIT_TERMS = "U^2, A, A U, A^2 U, A^3 U"


def _f(x) -> str:
    return "n/a" if x is None or not isinstance(x, (int, float)) or not math.isfinite(x) else f"{x:.3f}"


def _minutes(seconds: tuple[float, float]) -> str:
    lo, hi = (s / 60.0 for s in seconds)
    return f"{lo:g}" if lo == hi else f"{lo:g}-{hi:g}"


def _step(argv: list[str], out_dir: Path | None, failures: list[str]) -> bool:
    """Run one subcommand in-process with its stdout sent to stderr; record its command."""
    from vivbench.cli import main

    print(f"[demo] vivbench {shlex.join(argv)}", file=sys.stderr)
    if out_dir is not None:
        out_dir.mkdir(parents=True, exist_ok=True)
        write_command(out_dir, argv)
    with contextlib.redirect_stdout(sys.stderr):
        code = main(argv)
    if code != 0:
        failures.append(f"{argv[0]} exited {code} (see the messages above)")
    return code == 0


class _Background:
    """One subcommand in a child process beside the in-process steps; its output replayed on :meth:`finish`.

    Why: the grey-box refit is the demo's longest step and single-threaded, and
    the steps after ``pool`` do not read its output, so on two cores it runs
    beside them (each step writes only its own directory: the same bytes as
    one after the other).
    """

    def __init__(self, argv: list[str], out_dir: Path):
        print(f"[demo] vivbench {shlex.join(argv)} (beside the next steps)", file=sys.stderr)
        out_dir.mkdir(parents=True, exist_ok=True)
        write_command(out_dir, argv)
        self.argv = argv
        self.log = tempfile.TemporaryFile(mode="w+")
        self.proc = subprocess.Popen([sys.executable, "-m", "vivbench", *argv], stdout=self.log,
                                     stderr=subprocess.STDOUT, text=True)

    def finish(self, failures: list[str]) -> bool:
        try:
            code = self.proc.wait()
        finally:
            if self.proc.poll() is None:  # interrupted while waiting: stop the child too
                self.proc.kill()
                self.proc.wait()
            self.log.seek(0)
            sys.stderr.write(self.log.read())
            self.log.close()
        if code != 0:
            failures.append(f"{self.argv[0]} exited {code} (see the messages above)")
        return code == 0


#: Subdirectory of ``--out`` that holds the in-library baseline run (``--baseline in_library``).
BASELINE_DIR = "baseline_in_library"


def _chain(out: Path, *, mode: str, events: int, seed: int, minutes: str, workers: int, failures: list[str],
           refit: bool = True, model: str = "varying") -> bool:
    """Generate, identify, pool, cluster, forecast, (refit) and validate one campaign into ``out``.

    Returns False when nothing could be identified (the later steps then have nothing to work on).
    """
    campaign, identify = out / "campaign", out / "identify"
    common = ["--workers", str(workers)]
    _step(["synth", "--events", str(events), "--seed", str(seed), "--duration", minutes, "--mode", mode,
           "--out", str(campaign), *common], None, failures)
    if not list(campaign.glob("E*.nc")):
        print(f"vivbench demo: no event was generated in {campaign}; nothing else to do", file=sys.stderr)
        return False
    _step(["identify", str(campaign), "--out", str(identify), *common], None, failures)
    if not list(identify.glob("*.identify.nc")):
        print(f"vivbench demo: no event was identified in {identify}; nothing else to do", file=sys.stderr)
        return False
    _step(["pool", str(identify), "--model", model, *common], None, failures)
    greybox = None
    if refit:
        # The grey-box reference refit is given the synthetic bridge's properties as a user would give
        # their bridge's (the demo knows its own generator configuration); the fit never reads /truth.
        # 50 parameter draws per window verdict (100 by default) keep the step within the demo's time budget.
        argv = ["greybox", str(identify), "--out", str(out / "greybox"), *_bridge_options(mode), "--draws", "50",
                "--campaign", str(campaign)]
        if workers >= 2:
            greybox = _Background(argv, out / "greybox")
        else:
            _step(argv, out / "greybox", failures)
    try:
        _after_pool(out, campaign, identify, refit, failures)
    finally:
        if greybox is not None:
            greybox.finish(failures)
    return True


def _after_pool(out: Path, campaign: Path, identify: Path, refit: bool, failures: list[str]) -> None:
    """Cluster, forecast, (refit) and validate one campaign after vivbench pool."""
    from vivbench.validate import clearest_plateau

    _step(["cluster", str(identify), "--out", str(out / "cluster"), "--campaign", str(campaign)], out / "cluster", failures)
    try:
        plateau = clearest_plateau(campaign)
        event_id = plateau.event_id
    except InputError as exc:  # no plateau in a small campaign: forecast the first event
        print(f"vivbench demo: {exc}; forecasting the first event instead", file=sys.stderr)
        event_id = sorted(p.name.split(".")[0] for p in identify.glob("*.identify.nc"))[0]
    result = identify / f"{event_id}.identify.nc"
    _step(["forecast", str(result), "--out", str(out / "forecast"), "--campaign", str(campaign)], out / "forecast", failures)
    if refit:
        # The refit on the full identified or true support does not converge in reasonable time;
        # the demo refits a small, identifiable support around the forecast's t0.
        t0 = _read_json(out / "forecast" / "summary.json").get("t0_s")
        window = []
        if isinstance(t0, (int, float)):
            from vivbench.io.result import read_result

            grid = read_result(result, variables=())["time"].values
            lo, hi = float(grid[0]), float(grid[-1])
            window = ["--t0", f"{max(lo, t0 - 500.0):g}", "--t1", f"{min(hi, t0 + 300.0):g}"]
        _step(["refit", str(result), "--out", str(out / "refit"), "--event", str(campaign / f"{event_id}.nc"),
               "--terms", REFIT_TERMS, *window], out / "refit", failures)
    validate = ["validate", str(campaign), str(identify), "--out", str(out / "validate")]
    if (out / "cluster" / "cluster_labels.csv").is_file():
        validate += ["--clusters", str(out / "cluster" / "cluster_labels.csv")]
    if list((out / "forecast").glob("forecast_*.csv")):
        validate += ["--forecasts", str(out / "forecast")]
    _step(validate, out / "validate", failures)


def run(args) -> int:
    out = Path(args.out)
    campaign, identify = out / "campaign", out / "identify"
    failures: list[str] = []
    minutes = _minutes(args.duration)
    if not _chain(out, mode=args.mode, events=args.events, seed=args.seed, minutes=minutes, workers=args.workers,
                  failures=failures, model=args.model):
        return 1
    baseline = None
    if args.baseline != "none":
        # The same bridge scripts and seed with the truth inside the model class (docs/concepts.md (no inverse crime)): the report
        # shows every recovery figure of both side by side. No refit: the report does not pair it.
        baseline = out / BASELINE_DIR
        n_base = args.baseline_events or args.events
        print(f"[demo] baseline: {n_base} {args.baseline} events (seed {args.seed}) into {baseline}", file=sys.stderr)
        if not _chain(baseline, mode=args.baseline, events=n_base, seed=args.seed, minutes=minutes,
                      workers=args.workers, failures=failures, refit=False, model=args.model):
            baseline = None
    report = ["report", "--campaign", str(campaign), "--results", str(identify), "--name", args.name,
              "--out-root", str(args.report_root if args.report_root else out / "reports")]
    for step in ("cluster", "forecast", "refit", "greybox", "validate"):
        if (out / step).is_dir():
            report += [f"--{step}", str(out / step)]
    if baseline is not None:
        report += ["--baseline", str(baseline)]
    _step(report, None, failures)

    report_md = Path(report[report.index("--out-root") + 1]) / args.name / "report.md"
    s = _read_json(out / "validate" / "summary.json")
    c = _read_json(out / "cluster" / "summary.json")
    fc = _read_json(out / "forecast" / "summary.json")
    print(f"report:   {report_md}" if report_md.is_file() else "report:   not written (see the messages above)")
    print(f"campaign: {len(list(campaign.glob('E*.nc')))} events in {campaign}; results in {identify}")
    if s:
        print(f"regimes:  {s.get('n_window_equations')} window-equations; window models (the paper's method): "
              f"coverage {_f(s.get('regime_coverage'))}, accuracy {_f(s.get('regime_accuracy_identifiable'))} "
              f"identifiable / {_f(s.get('regime_accuracy_all'))} all (chance {_f(s.get('truth_most_common_regime_share'))})")
        print(f"          campaign model (vivbench pool): coverage {_f(s.get('campaign_model_regime_coverage'))}, accuracy "
              f"{_f(s.get('campaign_model_regime_accuracy_identifiable'))} identifiable / {_f(s.get('campaign_model_regime_accuracy_all'))} all")
        if s.get("median_rhs_rel_error_active") is not None:  # an exact coefficient matrix (in_library truth)
            window, pooled, where = "median_rhs_rel_error_active", "campaign_model_median_rhs_rel_error_active", ""
        else:  # a truth outside the library (the realistic default): measured on the true (A, U)
            window, pooled = "median_rhs_error_true_AU_active", "campaign_model_median_rhs_error_true_AU_active"
            where = " (on the true A, U)"
        print(f"dynamics: median relative error of dA/dt on windows with dynamics{where}: window models "
              f"{_f(s.get(window))}, campaign model {_f(s.get(pooled))}; energy-weighted over every sample on the "
              f"true (A, U): window models {_f(s.get('energy_rhs_error_true_AU'))}, campaign model "
              f"{_f(s.get('campaign_model_energy_rhs_error_true_AU'))} (curves {_f(s.get('campaign_model_curve_error_energy'))})")
    if c:
        tags = sorted(k[len("n_clusters_"):] for k in c if k.startswith("n_clusters_"))
        print("clusters: " + "; ".join(f"{t}: {c.get('n_clusters_' + t)} clusters, ARI {_f(c.get('ari_' + t))}" for t in tags))
    rf = _read_json(out / "refit" / "summary.json")
    if rf:
        print(f"refit:    {rf.get('event_id')} [{rf.get('t0_s', float('nan')):.0f}, {rf.get('t1_s', float('nan')):.0f}] s on "
              f"'{REFIT_TERMS}' per section: {rf.get('solver', 'ipopt')} {rf.get('ipopt_status')}; mean NMSE refit {_g(rf.get('nmse_refit_mean'))}, "
              f"equation-error fit {_g(rf.get('nmse_lsq_mean'))}, true model {_g(rf.get('nmse_truth_mean'))}")
    gb = _read_json(out / "greybox" / "summary.json")
    if gb:
        print(f"greybox:  {gb.get('n_events')} events in {_g(gb.get('fit_seconds'))} s; median simulation NMSE "
              f"{_g(gb.get('nmse_median'))}; against the truth: a_k1 error {_f(gb.get('truth_curve_error_linear'))}, "
              f"Y1 error {_f(gb.get('truth_y1_error'))}, flagged windows with the true regime "
              f"{_f(gb.get('truth_regime_precision_identifiable'))} (coverage {_f(gb.get('regime_coverage'))})")
    if fc:
        ds = sorted((k for k in fc if k.startswith("nmse_S2_d") and "clip" not in k), key=lambda k: float(k[9:]))
        print(f"forecast: {fc.get('event_id')} from t0 = {fc.get('t0_s', float('nan')):.0f} s: window models NMSE(S2) "
              + ", ".join(f"d={k[9:]} s {_g(fc.get(k))}" for k in ds)
              + f"{'' if fc.get('forecasts_complete') else ' (stopped early)'}; campaign model {_g(fc.get('campaign_model_forecast_nmse_S2'))}")
    b = _read_json(baseline / "validate" / "summary.json") if baseline is not None else {}
    if b and s:
        # The same scores on both campaigns, on the true (A, U): the only dA/dt error a realistic truth has.
        print(f"baseline: in-library (truth inside the model class: the inverse crime), {b.get('n_events')} events, "
              f"in {baseline}, against realistic ({s.get('n_events')} events): campaign model coverage "
              f"{_f(b.get('campaign_model_regime_coverage'))} / {_f(s.get('campaign_model_regime_coverage'))}, accuracy all "
              f"{_f(b.get('campaign_model_regime_accuracy_all'))} / {_f(s.get('campaign_model_regime_accuracy_all'))}, median dA/dt "
              f"error on the true (A, U) {_f(b.get('campaign_model_median_rhs_error_true_AU_active'))} / "
              f"{_f(s.get('campaign_model_median_rhs_error_true_AU_active'))}, energy-weighted "
              f"{_f(b.get('campaign_model_energy_rhs_error_true_AU'))} / {_f(s.get('campaign_model_energy_rhs_error_true_AU'))}")
    for line in failures:
        print(f"vivbench demo: {line}", file=sys.stderr)
    return 1 if failures else 0


def _bridge_options(mode: str) -> list[str]:
    """The demo bridge's properties as ``vivbench greybox`` options (the structure of the mode's generator)."""
    from vivbench.synth import GeneratorConfig

    st = GeneratorConfig.from_mode(mode).structure
    join = lambda xs: ",".join(f"{x:g}" for x in xs)  # noqa: E731
    return ["--mass", f"{st.mass:g}", "--depth", f"{st.depth:g}", "--frequency", f"{st.frequency:g}",
            "--damping-ratio", f"{st.damping_ratio:g}", "--air-density", f"{st.air_density:g}",
            "--mode-shape", join(st.mode_shape), "--tributary-lengths", join(st.tributary_lengths)]


def _g(x) -> str:
    return "n/a" if x is None or not isinstance(x, (int, float)) or not math.isfinite(x) else f"{x:.3g}"


def _read_json(path: Path) -> dict:
    try:
        return json.loads(path.read_text())
    except (OSError, ValueError):
        return {}


def register(sub) -> None:
    s = sub.add_parser("demo", help="the whole chain on a synthetic campaign, ending in a report")
    s.add_argument("--out", default="demo", help="output directory (default ./demo)")
    s.add_argument("--seed", type=int, default=0)
    s.add_argument("--events", type=int, default=31, help="number of events (default 31)")
    s.add_argument("--duration", type=duration, default=(1200.0, 3600.0),
                   help="event duration in minutes: N or MIN-MAX (default 20-60)")
    s.add_argument("--workers", type=int, default=DEFAULT_WORKERS)
    s.add_argument("--name", default="demo", help="report name (default demo)")
    s.add_argument("--report-root", default=None, help="parent directory of the report (default OUT/reports)")
    s.add_argument("--mode", choices=("realistic", "in_library"), default="realistic",
                   help="generator mode of the main campaign (docs/concepts.md (no inverse crime); default realistic: the truth outside the "
                        "identification's model class)")
    s.add_argument("--model", choices=("pooled", "varying"), default="varying",
                   help="campaign model of the pool step (vivbench pool --model; default varying, as pool's)")
    s.add_argument("--baseline", choices=("none", "in_library"), default="none",
                   help="also run the chain on an in_library campaign of the same seed and durations (the truth "
                        f"inside the model class: the inverse crime) into OUT/{BASELINE_DIR}, and show both side by "
                        "side in the report (default none)")
    s.add_argument("--baseline-events", type=int, default=None, metavar="N",
                   help="events of the baseline campaign (default: --events); the report states the size")
    s.set_defaults(func=run)
