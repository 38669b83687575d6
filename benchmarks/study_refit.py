"""The library-coefficient refit on a large support: IPOPT against Gauss-Newton on the same segment (issue 14).

Run: ``.venv/bin/python benchmarks/study_refit.py --result RESULTS/E013.identify.nc --t0 589 --t1 1389
[--event CAMPAIGN/E013.nc --support truth] [--ipopt-wall 300] [--figure refit_benchmark.png] [--json OUT]``.

Each solver runs in its own child process (so each peak resident memory is
its own, imports included) on the same segment and support, from the same
start (the equation-error least-squares fit on the support). Reported per
solver: wall and CPU time of the child, the refit's own wall time (building
and solving), the iterations (IPOPT iterations; Gauss-Newton
linearisations), the status, the final objective (scaled data sum of
squares plus ridge, the same function for both), the largest continuity
defect and the NMSE of the refit model simulated from the first measured A
(None when it blows up). IPOPT gets a wall-clock limit (``--ipopt-wall``).
The figure shows the measured envelope and both refit simulations, and the
time, memory and NMSE side by side. It asserts nothing.
"""

from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import json  # noqa: E402
import resource  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

SOLVERS = ("ipopt", "gauss-newton")


def _child(args) -> None:
    """Refit once with one solver; write a JSON summary and the simulation (npz)."""
    from vivbench.io.event import event_arrays, read_event
    from vivbench.io.result import read_result
    from vivbench.models.refit import RefitConfig, refit_event

    t_wall, t_cpu = time.perf_counter(), time.process_time()
    result = read_result(args.result)
    truth = event_arrays(read_event(args.event)).get("coef") if args.event else None
    config = RefitConfig(solver=args.child, max_wall_time=args.ipopt_wall if args.child == "ipopt" else None)
    ev = refit_event(result, t0=args.t0, t1=args.t1, support=args.support, truth_coef=truth, config=config)
    fit = ev.fit
    sim = fit.simulation
    out = {"solver": args.child, "refit_wall_s": fit.wall_time, "process_wall_s": time.perf_counter() - t_wall,
           "process_cpu_s": time.process_time() - t_cpu,
           "peak_rss_gb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024**2,
           "status": fit.status, "success": fit.success, "iterations": fit.iterations, "objective": fit.objective,
           "max_defect": fit.max_defect, "start": fit.start, "support_size": fit.support_size.tolist(),
           "rank": fit.rank.tolist(), "cond": fit.cond.tolist(), "stopped": sim.stopped,
           "nmse": None if sim.stopped else sim.nmse.tolist(),
           "nmse_mean": None if sim.stopped else float(np.mean(sim.nmse)),
           "nmse_lsq_mean": ev.summary()["nmse_lsq_mean"], "t0": ev.t0, "t1": ev.t1}
    Path(args.child_out).write_text(json.dumps(out))
    np.savez(Path(args.child_out).with_suffix(".npz"), t=sim.t, A_sim=sim.A_sim, A=sim.A_meas)


def _figure(path, rows, sims, title) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (a1, a2) = plt.subplots(1, 2, figsize=(12, 4), constrained_layout=True, gridspec_kw={"width_ratios": [2, 1]})
    colours = {"ipopt": "#7570b3", "gauss-newton": "#d95f02"}
    first = next(iter(sims.values()))
    k = int(np.argmax(np.nanmax(first["A"], axis=0)))
    a1.plot(first["t"], first["A"][:, k] * 1e3, color="k", lw=1.5, label=f"measured A (section {k + 1})")
    for name, s in sims.items():
        a1.plot(s["t"], s["A_sim"][:, k] * 1e3, color=colours[name], lw=1, ls="--" if name == "ipopt" else "-",
                label=f"{name} refit, simulated")
    a1.set_xlabel("time (s)")
    a1.set_ylabel("amplitude A (mm)")
    a1.set_title(title, fontsize=9, loc="left")
    a1.legend(fontsize=8)
    names = [r["solver"] for r in rows]
    x = np.arange(3)
    width = 0.38
    for i, r in enumerate(rows):
        nmse = r["nmse_mean"] if r["nmse_mean"] is not None else np.nan
        vals = [r["refit_wall_s"] / 60.0, r["peak_rss_gb"], nmse * 100.0]
        a2.bar(x + (i - 0.5) * width, vals, width, color=colours[r["solver"]], label=r["solver"])
        if r["nmse_mean"] is None:
            a2.text(2 + (i - 0.5) * width, 0.0, "blew up", rotation=90, ha="center", va="bottom", fontsize=8)
    a2.set_xticks(x, ["refit wall (min)", "peak RSS (GB)", "mean NMSE (%)"])
    a2.set_ylabel("min, GB or %")
    a2.set_title(" vs ".join(names), fontsize=9, loc="left")
    a2.legend(fontsize=8)
    fig.savefig(path, dpi=100, metadata={"Software": None})
    plt.close(fig)


def main(argv=None) -> list:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--result", required=True, help="identification result <event_id>.identify.nc")
    p.add_argument("--event", default=None, help="the event file (for --support truth)")
    p.add_argument("--t0", type=float, default=None)
    p.add_argument("--t1", type=float, default=None)
    p.add_argument("--support", default="identified", choices=("identified", "window", "truth"))
    p.add_argument("--ipopt-wall", type=float, default=300.0, help="IPOPT wall-clock limit, s")
    p.add_argument("--solvers", default=",".join(SOLVERS), help="comma-separated, from " + ", ".join(SOLVERS))
    p.add_argument("--figure", default=None)
    p.add_argument("--json", default=None, help="write the rows here")
    p.add_argument("--child", default=None, help=argparse.SUPPRESS)
    p.add_argument("--child-out", default=None, help=argparse.SUPPRESS)
    args = p.parse_args(argv)
    if args.child:
        _child(args)
        return []
    rows, sims = [], {}
    with tempfile.TemporaryDirectory(prefix="bench-refit-") as tmp:
        for solver in args.solvers.split(","):
            out = Path(tmp) / f"{solver}.json"
            cmd = [sys.executable, __file__, "--result", args.result, "--support", args.support, "--ipopt-wall",
                   str(args.ipopt_wall), "--child", solver, "--child-out", str(out)]
            for flag, value in (("--event", args.event), ("--t0", args.t0), ("--t1", args.t1)):
                if value is not None:
                    cmd += [flag, str(value)]
            subprocess.run(cmd, check=True)
            row = json.loads(out.read_text())
            rows.append(row)
            with np.load(out.with_suffix(".npz")) as z:
                sims[solver] = {k: z[k] for k in z.files}
            nm = "blew up" if row["nmse_mean"] is None else f"{row['nmse_mean']:.3g}"
            print(f"{solver:>12}: refit {row['refit_wall_s']:.1f} s (process {row['process_wall_s']:.1f} s wall, "
                  f"{row['process_cpu_s']:.1f} s CPU), peak RSS {row['peak_rss_gb']:.2f} GB, {row['iterations']} "
                  f"iterations, {row['status']}, objective {row['objective']:.6g}, max defect {row['max_defect']:.2g}, "
                  f"mean NMSE {nm} (equation-error start {row['nmse_lsq_mean']})")
    if rows:
        r = rows[0]
        print(f"segment [{r['t0']:g}, {r['t1']:g}] s, {args.support} support: {r['support_size']} terms, "
              f"rank {r['rank']}, cond {[f'{c:.2g}' for c in r['cond']]}")
    if args.figure and sims:
        title = (f"{Path(args.result).name.split('.')[0]} [{rows[0]['t0']:g}, {rows[0]['t1']:g}] s, {args.support} "
                 f"support ({sum(rows[0]['support_size'])} terms)")
        _figure(args.figure, rows, sims, title)
    if args.json:
        Path(args.json).write_text(json.dumps(rows, indent=1) + "\n")
    return rows


if __name__ == "__main__":
    main()
