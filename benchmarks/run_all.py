"""Run the benchmark suite and write its results page (``make bench``, ``make bench-quick``).

Usage::

    python benchmarks/run_all.py [--quick] [NAME ...]

Each benchmark of :data:`SUITE` is a ``bench_<name>.py`` whose ``main(**kwargs)`` returns a
dict of figures; it runs in this process with the keyword arguments of the mode (``--quick``:
smaller workloads, a reduced set), with ``sys.argv`` holding only its own name so that a
script's argument parser sees no foreign arguments. A benchmark whose reference package is
missing is reported as skipped, one that needs inputs that are absent (``make demo``'s
outputs) too, and one that fails is reported with its error; the others still run, and
nothing is faked. The figures go to ``benchmarks/out/results[_quick].json`` and the page
``benchmarks/results[_quick].md``, with the speed ratios against the reference packages
first. The accuracy studies (``study_<name>.py``) are not part of the suite: each is its own
command, ``python benchmarks/run_study.py NAME [ARGS ...]``, that writes its own page; the
suite's page lists them.
"""

from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")
os.environ.setdefault("MPLBACKEND", "Agg")

import importlib.util  # noqa: E402
import json  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
import traceback  # noqa: E402
from dataclasses import dataclass, field  # noqa: E402
from pathlib import Path  # noqa: E402

from _pages import figures_table, first_line, flatten, run_metadata, written_by  # noqa: E402
from run_study import STUDIES  # noqa: E402

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent


@dataclass(frozen=True, kw_only=True)
class Bench:
    """One benchmark of the suite: ``bench_<name>.py``'s ``main`` with the arguments of each mode."""

    name: str
    full: dict | None = field(default_factory=dict)  # None: not run by `make bench`
    quick: dict | None = None  # None: not run by `make bench-quick`
    needs: tuple[str, ...] = ()  # paths (relative to the repository) that must exist


SUITE = (
    Bench(name="sindy", full={}, quick={}),  # 31 events x 100 windows, pysindy on 100 of them
    Bench(name="identify", full={"n_events": 31}, quick={"n_events": 3}),
    Bench(name="derivative", full={}, quick={"noise_kinds": ("white",), "n_events": 2}),  # full: about 5 min
    Bench(name="turbulence", full={}, quick={"repeats": 1}),
    Bench(name="felt_wind", full={}, quick={"repeats": 1}),
    Bench(name="varying_speed", full={}, quick={"samples": 20_000}),
    Bench(name="clustering", full={}, quick={"blobs_only": True}),  # quick: no 31-event campaign to make
    Bench(name="campaign"),
    Bench(name="sweep"),
    Bench(name="greybox", full={"argv": []}, needs=("demo/identify", "demo/campaign")),
)


def _load(name: str):
    path = HERE / f"bench_{name}.py"
    spec = importlib.util.spec_from_file_location(path.stem, path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def run_one(bench: Bench, kwargs: dict) -> dict:
    """Figures of one benchmark, or ``{"skipped": why}`` / ``{"error": what}``; ``wall_s`` beside them."""
    missing = [p for p in bench.needs if not (ROOT / p).exists()]
    if missing:
        return {"skipped": f"needs {', '.join(missing)} (run `make demo` first)", "wall_s": 0.0}
    argv, sys.argv = sys.argv, [str(HERE / f"bench_{bench.name}.py")]
    t0 = time.perf_counter()
    try:
        figures = _load(bench.name).main(**kwargs)
        out = figures if isinstance(figures, dict) else {"figures": figures}
    except ModuleNotFoundError as exc:
        out = {"skipped": f"reference package missing: {exc}"}
    except (Exception, SystemExit) as exc:  # a script's argparse exits: report it and go on
        traceback.print_exc()
        out = {"error": f"{type(exc).__name__}: {exc}"}
    finally:
        sys.argv = argv
    out["wall_s"] = time.perf_counter() - t0
    return out


def _get(results: dict, *keys):
    for key in keys:
        if not isinstance(results, dict) or key not in results:
            return None
        results = results[key]
    return results


def speed_rows(results: dict) -> list[tuple[str, str, str, str, str]]:
    """(benchmark, workload, vivbench, reference, ratio) of every speed comparison that ran."""
    rows = []
    for label, fig in (("synthetic sparse-model windows", _get(results, "sindy")),
                       ("windows of a campaign of the default bridge", _get(results, "identify", "engine_vs_pysindy"))):
        if fig and "speedup_vs_sindy_loop" in fig:
            rows.append(("window SINDy engine vs pysindy `SINDy` loop",
                         f"{label}: {fig['n_events']} events, {fig['n_windows']} windows "
                         f"({fig['n_reference_windows']} for pysindy)",
                         f"{fig['ours_ms_per_window']:.3g} ms/window",
                         f"{fig['pysindy_sindy_ms_per_window']:.3g} ms/window",
                         f"{fig['speedup_vs_sindy_loop']:.3g}x"))
    derivative = _get(results, "derivative")
    if isinstance(derivative, dict):
        flat = dict(flatten(derivative))
        ours = [v for k, v in flat.items() if k.endswith(".time_ours_s")]
        ref = [v for k, v in flat.items() if k.endswith(".time_ref_s")]
        if ours and ref and len(ours) == len(ref):
            total_ours, total_ref = sum(ours), sum(ref)
            rows.append(("TV derivative vs pynumdiff `iterative_velocity` (tuned settings)", f"{len(ours)} cases",
                         f"{total_ours:.3g} s",
                         f"{total_ref:.3g} s", f"{total_ref / total_ours:.3g}x"))
    turbulence = _get(results, "turbulence")
    if isinstance(turbulence, dict) and "speedup" in turbulence:
        rows.append(("turbulence field vs pyconturb `gen_turb`",
                     f"{turbulence['n_points']} points x 3 components, {turbulence['n_samples']} samples",
                     f"{turbulence['time_ours_s']:.3g} s", f"{turbulence['time_pyconturb_s']:.3g} s",
                     f"{turbulence['speedup']:.3g}x"))
    for part in ("coef", "order"):
        fig = _get(results, "clustering", "campaign", part)
        if fig and "ratio_ours_over_pydpc" in fig:
            rows.append((f"density peaks vs pydpc ({part} features)", "the default campaign's window models",
                         f"{fig['t_ours_gaussian_s']:.3g} s", f"{fig['t_pydpc_s']:.3g} s",
                         f"{1.0 / fig['ratio_ours_over_pydpc']:.3g}x"))
    fig = _get(results, "clustering", "blobs")
    if fig and "ratio_ours_over_pydpc" in fig:
        rows.append(("density peaks vs pydpc (synthetic blobs)", f"{fig['n_points']} points in {fig['dim']} dimensions",
                     f"{fig['t_ours_gaussian_s']:.3g} s", f"{fig['t_pydpc_s']:.3g} s",
                     f"{1.0 / fig['ratio_ours_over_pydpc']:.3g}x"))
    return rows


def results_page(results: dict, *, quick: bool, command: str) -> str:
    """The Markdown results page of a run."""
    meta = results["_run"]
    lines = [f"# Benchmark results{' (quick)' if quick else ''}", "", written_by(command, meta), "",
             "The machine may be shared with other work while the suite runs: the wall times say what one run took, "
             "the ratios (vivbench and its reference timed side by side, in the same run) are the figures to compare.",
             ""]
    rows = speed_rows(results)
    lines += ["## Speed against the reference packages", ""]
    if rows:
        lines += ["Ratio: reference time over vivbench's (above 1: vivbench is faster).", "",
                  "| comparison | workload | vivbench | reference | ratio |", "|---|---|---|---|---|"]
        lines += [f"| {' | '.join(r)} |" for r in rows]
    else:
        lines.append("No speed comparison ran.")
    lines += ["", "## Benchmarks", "", "| benchmark | what | status | wall time (s) |", "|---|---|---|---|"]
    for name, fig in results.items():
        if name.startswith("_"):
            continue
        status = "skipped: " + fig["skipped"] if "skipped" in fig else ("error: " + fig["error"] if "error" in fig
                                                                         else "ran")
        what = first_line(HERE / f"bench_{name}.py")
        lines.append(f"| `{name}` | {what} | {status.replace('|', '/')} | {fig['wall_s']:.0f} |")
    for name, fig in results.items():
        if name.startswith("_") or "skipped" in fig or "error" in fig:
            continue
        lines += ["", f"### `{name}`", ""] + figures_table(fig)
    lines += ["", "## Accuracy studies (separate commands)", "",
              "Not run by `make bench`: each is its own command, `python benchmarks/run_study.py NAME [ARGS ...]`, "
              "which writes the page `docs/results/studies/NAME.md` (`python benchmarks/run_study.py NAME --help` says "
              "what each takes; most need a campaign and its identification results, for example `make demo`'s).", "",
              "| study | what |", "|---|---|"]
    lines += [f"| `{name}` | {first_line(path)} |" for name, path in STUDIES.items()]
    return "\n".join(lines) + "\n"


def main(argv: list[str]) -> int:
    quick = "--quick" in argv
    only = {a for a in argv if not a.startswith("--")}
    unknown = only - {b.name for b in SUITE}
    if unknown:
        print(f"run_all: unknown benchmarks {sorted(unknown)}; the suite: {', '.join(b.name for b in SUITE)}",
              file=sys.stderr)
        return 2
    t0 = time.perf_counter()
    results: dict = {}
    for bench in SUITE:
        kwargs = bench.quick if quick else bench.full
        if kwargs is None or (only and bench.name not in only):
            continue
        print(f"\n=== {bench.name} ===", flush=True)
        results[bench.name] = run_one(bench, kwargs)
        print(f"--- {bench.name}: {results[bench.name]['wall_s']:.0f} s", flush=True)
    results["_run"] = {**run_metadata(time.perf_counter() - t0), "quick": quick}
    suffix = "_quick" if quick else ""
    out = HERE / "out"
    out.mkdir(exist_ok=True)
    (out / f"results{suffix}.json").write_text(json.dumps(results, indent=2, default=float) + "\n")
    command = "make bench-quick" if quick else "make bench"
    if only:
        command = f"python benchmarks/run_all.py {' '.join(argv)}"
    page = HERE / f"results{suffix}.md"
    page.write_text(results_page(results, quick=quick, command=command), encoding="utf-8")
    print(f"\nwrote {out / f'results{suffix}.json'} and {page}")
    return 1 if any("error" in v for k, v in results.items() if not k.startswith("_")) else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
