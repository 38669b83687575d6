"""Time and peak memory of the grey-box refit of a whole campaign (issue 14: at most 60 s and 2 GB on 2 cores).

Run: ``.venv/bin/python benchmarks/bench_greybox.py --results demo/identify --campaign demo/campaign
[--figure greybox_benchmark.png] [--starts 4] [--wind-smoothing 30]``. The bridge's properties are read
from the first event's generator configuration (a benchmark may; the fit never
does), the warm start is the campaign model beside the results. The fit is
the default one: yaw factor (when the results carry the yaw) and the
multi-start (screening of every start, then the final solve), the
penalty chosen by GCV from a grid (a fit continued at each value) and the
wind refits of the band's errors-in-variables component
(``--wind-draws 0``: none, band "sandwich_bias"). Reported:
wall and CPU time of ``GreyBoxRefit.fit`` alone (reading the results and
the window verdicts excluded), Gauss-Newton iterations, the process's peak
resident memory (imports included) and the cost after every accepted step
against time (screening steps included). The figure shows the cost history and the two budgets. It
asserts nothing (a loaded machine slows the wall time; CPU time is the
figure to compare with the budget on an idle one).
"""

from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import json  # noqa: E402
import resource  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

HERE = Path(__file__).resolve().parent


def _bridge(campaign: Path):
    from vivbench.io.event import list_events, read_event
    from vivbench.models.greybox import BridgeProperties

    truth = read_event(list_events(campaign)[0])["truth"].ds
    st = json.loads(truth.attrs["config_json"])["generator"]["structure"]
    return BridgeProperties(mass=st["mass"], depth=st["depth"], frequency=st["frequency"],
                            damping_ratio=st["damping_ratio"], air_density=st["air_density"],
                            mode_shape=tuple(st["mode_shape"]), tributary_lengths=tuple(st["tributary_lengths"]))


def main(argv=None) -> dict:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--results", default=str(HERE.parent / "demo" / "identify"))
    p.add_argument("--campaign", default=str(HERE.parent / "demo" / "campaign"))
    p.add_argument("--figure", default=None, help="write the benchmark figure (PNG) here")
    p.add_argument("--starts", type=int, default=4, help="starts of the multi-start (default 4)")
    p.add_argument("--wind-smoothing", dest="wind_smoothing", type=float, default=30.0,
                   help="Gaussian smoothing of the wind, s (default 30, as vivbench greybox)")
    p.add_argument("--no-warm-start", dest="no_warm_start", action="store_true",
                   help="no campaign-model warm start (the equation-error starts alone)")
    p.add_argument("--penalty-grid", dest="penalty_grid", default="0.1,0.3,1",
                   help="penalties scored by GCV (default as vivbench greybox; 'none': the fixed 0.3)")
    p.add_argument("--boot", type=int, default=0,
                   help="event bootstrap replicates after the fit (default 0, as vivbench greybox); timed with it")
    p.add_argument("--boot-iter", dest="boot_iter", type=int, default=10,
                   help="iterations of a bootstrap replicate per continuation stage (default 10)")
    p.add_argument("--wind-draws", dest="wind_draws", type=int, default=None,
                   help="refits with drawn wind errors for the band's wind component (default: as vivbench greybox)")
    p.add_argument("--wind-iter", dest="wind_iter", type=int, default=None,
                   help="iterations of a wind refit per continuation stage (default: as vivbench greybox)")
    args = p.parse_args(argv)
    from vivbench.analysis.greybox import campaign_warm_start
    from vivbench.analysis.pool import curve_wind_grid, records_from_results
    from vivbench.io.result import list_results
    from vivbench.models.greybox import GreyBoxRefit

    files = list_results(args.results)
    records = records_from_results(files, derivative=None, wind_smoothing_s=args.wind_smoothing)
    wind = curve_wind_grid(np.concatenate([r.U.ravel() for r in records]))
    warm, source = (None, "none") if args.no_warm_start else campaign_warm_start(Path(args.results), wind)
    grid = None if args.penalty_grid.lower() == "none" else tuple(float(x) for x in args.penalty_grid.split(","))
    bridge = _bridge(Path(args.campaign))
    history = []
    t0, c0 = time.perf_counter(), time.process_time()
    wind_kw = {k: v for k, v in (("wind_draws", args.wind_draws), ("wind_iter", args.wind_iter)) if v is not None}
    if wind_kw.get("wind_draws") == 0:
        wind_kw["band"] = "sandwich_bias"
    model = GreyBoxRefit(bridge=bridge, warm_start=warm, n_starts=args.starts, penalty_grid=grid, n_boot=args.boot,
                         boot_iter=args.boot_iter, **wind_kw)
    model.fit(records, callback=lambda it, cost, mu: history.append((time.perf_counter() - t0, cost)))
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    peak_gb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024**2  # Linux: kB
    info = model.fit_info_
    out = {"events": len(records), "intervals": info["n_intervals"], "samples": info["n_samples"],
           "fit_wall_s": wall, "fit_cpu_s": cpu, "iterations": info["iterations"], "converged": info["converged"],
           "peak_rss_gb": peak_gb, "warm_start": source, "max_continuity_defect": info["max_defect"],
           "start": info["start"], "n_starts": len(info["starts"]) or 1, "yaw_coef": model.yaw_coef_,
           "yaw": info["yaw"], "penalty": info["penalty"], "penalty_criterion": info["penalty_criterion"],
           "bootstrap": info.get("bootstrap"), "wind_error": info.get("wind_error")}
    print(f"grey-box refit of {len(records)} events ({info['n_intervals']} shooting intervals, {info['n_samples']} "
          f"grid samples): {wall:.1f} s wall, {cpu:.1f} s CPU, {info['iterations']} Gauss-Newton iterations "
          f"({'converged' if info['converged'] else 'not converged'}), peak RSS {peak_gb:.2f} GB "
          f"(targets: 60 s, 2 GB); {out['n_starts']} starts, the winner: {info['start']}; yaw coefficient "
          f"{model.yaw_coef_:.3g} ({info['yaw']}); penalty {info['penalty']:g} ({info['penalty_criterion']})")
    if info.get("bootstrap"):
        b = info["bootstrap"]
        print(f"event bootstrap: {b['n_boot']} replicates of {b['n_events']} events in {b['seconds']:.1f} s (included "
              f"above), median {b['iterations_median']:g} iterations, last step's relative decrease median "
              f"{b['last_step_median']:.2g}, max {b['last_step_max']:.2g}")
    if info.get("wind_error"):
        w = info["wind_error"]
        print(f"wind's errors-in-variables: {w['n_draws']} refits (and one unperturbed) in {w['seconds']:.1f} s "
              f"(included above), median {w['iterations_median']:g} iterations")
    if args.figure:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        fig, (a1, a2) = plt.subplots(1, 2, figsize=(10, 3.8), constrained_layout=True)
        t, c = np.array(history).T if history else (np.zeros(0), np.zeros(0))
        a1.semilogy(t, c, "o-", ms=3, color="#d95f02")
        a1.axvline(60.0, color="k", ls="--", lw=1, label="budget 60 s")
        a1.set_xlabel("wall time since the fit started (s)")
        a1.set_ylabel("Gauss-Newton cost (-)")
        a1.set_title("cost after each accepted step (screening of the starts, then the final solve;\n"
                     "jumps: a new start or continuity weight x100)", fontsize=9, loc="left")
        a1.legend(fontsize=8)
        bars = [wall, cpu, peak_gb * 30.0]
        a2.bar(["fit wall (s)", "fit CPU (s)", "peak RSS (GB x 30)"], bars, color=["#d95f02", "#e6ab02", "#7570b3"])
        a2.axhline(60.0, color="k", ls="--", lw=1, label="budgets: 60 s, 2 GB")
        a2.set_ylabel("s, or GB x 30")
        a2.set_title(f"{len(records)} events, {info['n_intervals']} intervals", fontsize=9, loc="left")
        a2.legend(fontsize=8)
        fig.savefig(args.figure, dpi=100, metadata={"Software": None})
        plt.close(fig)
        out["figure"] = str(args.figure)
    return out


if __name__ == "__main__":
    main()
