"""Benchmark: false-alarm rate and power of the varying campaign model's change scan (issue 11).

Run::

    python benchmarks/run_study.py change_calibration \\
        --case A:demo/campaign:demo/identify --case drift:DRIFT/campaign:DRIFT/identify:10 \\
        [--subsets 20 --subset-size 12 --permutations 99 --null permutation \\
         --statistic max,standardised --yaw-terms 1,0]

Each ``--case NAME:CAMPAIGN:RESULTS[:CHANGE]`` is a campaign and its identification
results; ``CHANGE`` (1-based event number) is the first event after a true change
(none: a campaign without change). For each case the default varying model of
``vivbench pool`` (yaw covariate when the records carry it, its wind smoothing)
is fitted once to all events, its per-event statistics are computed once
(``event_statistics`` of the measured records through ``measured_wind``) and the
change scan (:func:`vivbench.analysis.changes.statistics_change_scan`) is run on

- the whole campaign, events in time order;
- ``--subsets`` random subsets of ``--subset-size`` events, kept in time order
  (a subset of a campaign without change is a campaign without change; for a
  campaign with one, only subsets with at least ``min_events`` events on each
  side of it are drawn).

The model's basis and penalty come from all events, which does not depend on
their order, so a subset's scan stays a test of "no ordered change". Subsets of
one campaign share events and are not independent: the false-alarm rate is
given with the number of campaigns as well as of scans.

Reported per case: the p-values, the share of scans with p < 0.05 (false alarms
without a change, power with one), the share of detections that locate the
change within one event, and the events flagged as not predicted (misfit flags).
Nothing is asserted; the table is printed and written as JSON (``--json``), and
``run_study.py`` writes it as the page ``docs/results/studies/change_calibration.md``.
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

from vivbench.analysis import CAMPAIGN_DERIVATIVE, records_from_results  # noqa: E402
from vivbench.analysis.changes import CHANGE_LEVEL, statistics_change_scan  # noqa: E402
from vivbench.models import VaryingCoefficientSINDy  # noqa: E402

OUT = Path(__file__).resolve().parent / "out"


def _subset_stats(stats: list[dict], idx: np.ndarray) -> list[dict]:
    return [{**st, "G": st["G"][idx], "b": st["b"][idx], "yy": st["yy"][idx], "n": st["n"][idx]} for st in stats]


def _scan_rows(stats, ids, change, *, n_subsets, size, n_permutations, min_events, null, seed, statistic="max",
               yaw_terms=True) -> dict:
    E = len(ids)
    opts = {"null": null, "statistic": statistic, "yaw_terms": yaw_terms}
    full = statistics_change_scan(stats, n_permutations=n_permutations, seed=seed, min_events=min_events, **opts)
    out = {"full": {"p_value": full["p_value"], "detected": bool(full["detected"]),
                    "change_event": ids[full["change_index"]] if full["change_index"] >= 0 else None,
                    "misfit_flagged": [ids[i] for i in np.flatnonzero(full["misfit_flag"])]}}
    rng = np.random.default_rng(12345)  # the same subsets for every null
    rows = []
    tries = 0
    while len(rows) < n_subsets and tries < 100 * n_subsets and size <= E:
        tries += 1
        idx = np.sort(rng.choice(E, size=size, replace=False))
        before = int(np.sum(idx < change - 1)) if change is not None else None
        if change is not None and not (min_events <= before <= size - min_events):
            continue
        sc = statistics_change_scan(_subset_stats(stats, idx), n_permutations=n_permutations, seed=len(rows),
                                    min_events=min_events, **opts)
        # located: the split found is within one subset event of the true one (``before`` events before it)
        located = None if change is None or sc["change_index"] < 0 else bool(abs(sc["change_index"] - before) <= 1)
        rows.append({"events": [ids[i] for i in idx], "p_value": sc["p_value"], "detected": bool(sc["detected"]),
                     "located": located, "n_misfit_flagged": int(np.sum(sc["misfit_flag"]))})
    p = np.array([r["p_value"] for r in rows])
    out["subsets"] = rows
    out["n_subsets"] = len(rows)
    out["rate_p_lt_level"] = float(np.mean(p < CHANGE_LEVEL)) if p.size else float("nan")
    out["p_quartiles"] = np.percentile(p, [25, 50, 75]).tolist() if p.size else []
    if change is not None:
        det = [r for r in rows if r["detected"]]
        out["located_share_of_detected"] = float(np.mean([r["located"] for r in det])) if det else float("nan")
    return out


def _variants(nulls, statistics, yaw_terms) -> list[str]:
    """Keys ``null|statistic|yaw`` (or ``noyaw``) of every combination of the scan's options."""
    return [f"{n}|{s}|{'yaw' if y else 'noyaw'}" for n in nulls for s in statistics for y in yaw_terms]


def run_case(name: str, camp: Path, results: Path, change: int | None, *, n_subsets: int, size: int,
             n_permutations: int, nulls: list[str], min_events: int = 3, statistics=("max",),
             yaw_terms=(True,)) -> dict:
    t0 = time.perf_counter()
    files = sorted(results.glob("*.identify.nc"))
    recs = records_from_results(files, derivative=CAMPAIGN_DERIVATIVE, campaign=camp)
    model = VaryingCoefficientSINDy(n_bootstrap=0).fit(recs)
    stats = model.event_statistics([model.measured_wind(r) for r in recs])
    ids = [r.event_id for r in recs]
    out = {"events": len(ids), "fit_s": time.perf_counter() - t0}
    for key in _variants(nulls, statistics, yaw_terms):
        null, statistic, yaw = key.split("|")
        out[key] = _scan_rows(stats, ids, change, n_subsets=n_subsets, size=size, n_permutations=n_permutations,
                              min_events=min_events, null=null, seed=model.seed, statistic=statistic,
                              yaw_terms=yaw == "yaw")
    out["total_s"] = time.perf_counter() - t0
    return out


def main(argv=None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--case", action="append", required=True, help="NAME:CAMPAIGN:RESULTS[:CHANGE_EVENT]")
    parser.add_argument("--subsets", type=int, default=20)
    parser.add_argument("--subset-size", type=int, default=12)
    parser.add_argument("--permutations", type=int, default=99)
    parser.add_argument("--null", default="permutation,stratified", help="comma-separated nulls of the scan")
    parser.add_argument("--statistic", default="max", help="comma-separated statistics (max, standardised)")
    parser.add_argument("--yaw-terms", default="1", help="comma-separated 1/0: split refits with/without yaw terms")
    parser.add_argument("--json", type=Path, default=OUT / "change_calibration.json")
    args = parser.parse_args(argv)
    out = {}
    for case in args.case:
        parts = case.split(":")
        if len(parts) not in (3, 4):
            parser.error(f"--case {case!r}: give NAME:CAMPAIGN:RESULTS[:CHANGE_EVENT]")
        change = int(parts[3]) if len(parts) == 4 else None
        res = run_case(parts[0], Path(parts[1]), Path(parts[2]), change, n_subsets=args.subsets,
                       size=args.subset_size, n_permutations=args.permutations, nulls=args.null.split(","),
                       statistics=args.statistic.split(","), yaw_terms=[y == "1" for y in args.yaw_terms.split(",")])
        out[parts[0]] = res
        keys = _variants(args.null.split(","), args.statistic.split(","), [y == "1" for y in args.yaw_terms.split(",")])
        for null in keys:
            summary = {k: v for k, v in res[null].items() if k != "subsets"}
            print(f"{parts[0]} {null}: {json.dumps(summary)}", flush=True)
    print(f"\n{'case':<10} {'null|stat|yaw':<30} {'events':>6} {'full p':>7} {'full event':>10} {'flagged':>16} {'subsets':>7} "
          f"{'p<0.05':>7} {'located':>7}")
    for name, res in out.items():
        for null in keys:
            r = res[null]
            print(f"{name:<10} {null:<30} {res['events']:6d} {r['full']['p_value']:7.3f} "
                  f"{r['full']['change_event']!s:>10} {','.join(r['full']['misfit_flagged']) or '-':>16} "
                  f"{r['n_subsets']:7d} {r['rate_p_lt_level']:7.3f} {r.get('located_share_of_detected', float('nan')):7.3f}")
    args.json.parent.mkdir(parents=True, exist_ok=True)
    args.json.write_text(json.dumps(out, indent=2) + "\n")
    return out


if __name__ == "__main__":
    main()
