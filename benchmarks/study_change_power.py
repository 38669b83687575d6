"""Study: the change scan's statistics on draws of the generator family, with and without a step of damping.

Run::

    python benchmarks/run_study.py change_power --split development --draws 0-119 --out DIR \
        [--without-change 30] [--max-events N] [--max-duration 30] [--permutations 99] [--workers 2]

The family puts a step of the structural damping ratio (times 1 -+ U(0.3, 0.6), from an event
drawn in 2..n_events on) into a quarter of its draws (:mod:`vivbench.synth.family`). Among
``--draws`` this study keeps the draws with such a step and at least ``min_events`` (3) events on
each side of it in the (capped) campaign, where a scan can see it, and the first
``--without-change`` draws without any change (all of them by default). Each is generated,
identified, and fitted with the default campaign model (``varying``, as ``vivbench pool``
fits it); its change scan
(:func:`vivbench.analysis.changes.statistics_change_scan`, the stratified null, ``--permutations``
orderings) is run with every statistic of :data:`vivbench.analysis.changes.CHANGE_STATISTICS`:

- ``max``, the default: the largest relative drop of the penalised RSS when every coefficient
  curve is refitted on each side of a split;
- ``standardised``: the same drop, each split on its own null scale;
- ``offset``: the drop when the events after the split get one shift of the linear coefficient
  per equation, the form of a step of damping (:mod:`vivbench.analysis.change_offset`).

Per statistic the page gives the draws with a step, how many it detects (p < 0.05) and how many
of those it locates within one event of the step, and its alarms on the draws without a change
(the aims: 80 % detected and located, at most 5 % false alarms); per draw the p-values,
the located event and the scans' wall times. ``--max-events`` and ``--max-duration`` (minutes;
default 30) cap the campaigns. The study directory ``--out`` is resumable: a rerun reads the
finished draws (the page's wall time is then that of the rest) and its scan times are theirs.
"""

from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import math  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402

#: Fewest events on each side of a split (the scans' default).
MIN_EVENTS = 3


def kept_draws(split: str, draws, max_events) -> tuple[list[int], list[int]]:
    """The draws with a step the capped campaign holds with ``MIN_EVENTS`` events on each side, and those
    without any change (nothing simulated)."""
    from vivbench.synth.family import draw_bridge

    steps, none = [], []
    for d in draws:
        labels = draw_bridge(split, d).labels
        n = labels["n_events"] if max_events is None else min(labels["n_events"], max_events)
        if labels["change"] == "none":
            none.append(d)
        elif labels["change"] == "damping_step" and MIN_EVENTS <= labels["step_event"] - 1 <= n - MIN_EVENTS:
            steps.append(d)
    return steps, none


def scan_draw(task: dict) -> dict:
    """One draw: generate (capped), identify, fit ``varying`` once, scan with every statistic."""
    from vivbench.analysis.changes import CHANGE_STATISTICS, statistics_change_scan
    from vivbench.models.model_input import measured_input
    from vivbench.models.protocol import model_change_inputs
    from vivbench.synth.family import draw_bridge
    from vivbench.validate.methods import fit_method, resolve_method

    from benchmarks._family_args import capped_draw, store_row, stored_row

    done = stored_row(task)
    if done is not None:
        return done
    records, _truths, _windows = capped_draw(task)
    fitted, fit_s = fit_method(resolve_method("varying"), records)
    inputs = model_change_inputs(fitted, [measured_input(fitted, r) for r in records])
    labels = draw_bridge(task["split"], task["draw"]).labels
    step = labels["step_event"] - 1 if labels["change"] == "damping_step" else -1  # first changed event, 0-based
    row = {"draw": task["draw"], "n_events": len(records), "step_index": step,
           "step_factor": labels["step_damping_factor"], "eiv": labels["eiv"], "forced_only": labels["forced_only"],
           "fit_s": fit_s}
    for stat in CHANGE_STATISTICS:
        t0 = time.perf_counter()
        scan = statistics_change_scan(inputs["statistics"], seed=int(getattr(fitted, "seed", 0)),
                                      n_permutations=task["permutations"], statistic=stat)
        row[f"p_{stat}"] = float(scan["p_value"])
        row[f"index_{stat}"] = int(scan["change_index"])
        row[f"scan_s_{stat}"] = time.perf_counter() - t0
    return store_row(task, row)


def summarise(rows: list[dict]) -> list[dict]:
    """Per statistic: steps detected and located within one event, false alarms without a change."""
    from vivbench.analysis.changes import CHANGE_LEVEL, CHANGE_STATISTICS

    out = []
    steps = [r for r in rows if r["step_index"] >= 0]
    none = [r for r in rows if r["step_index"] < 0]
    for stat in CHANGE_STATISTICS:
        hit = [r for r in steps if r[f"p_{stat}"] < CHANGE_LEVEL]
        located = [r for r in hit if abs(r[f"index_{stat}"] - r["step_index"]) <= 1]
        scanned = [r for r in none if math.isfinite(r[f"p_{stat}"])]
        alarms = [r for r in scanned if r[f"p_{stat}"] < CHANGE_LEVEL]
        out.append({"statistic": stat, "draws_with_step": len(steps), "detected": len(hit),
                    "located_within_one_event": len(located), "draws_without_change": len(scanned),
                    "false_alarms": len(alarms), "alarm_draws": [r["draw"] for r in alarms],
                    "scan_s_median": float(np.median([r[f"scan_s_{stat}"] for r in rows])) if rows else math.nan})
    return out


def findings(summary: list[dict]) -> list[str]:
    """Sentences generated from the figures."""
    return [f"{s['statistic']}: {s['detected']} of {s['draws_with_step']} steps detected, "
            f"{s['located_within_one_event']} located within one event; alarms on {s['false_alarms']} of "
            f"{s['draws_without_change']} draws without a change"
            + (f" ({', '.join(map(str, s['alarm_draws']))})" if s["alarm_draws"] else "")
            + f"; median scan {s['scan_s_median']:.3f} s." for s in summary]


def main(argv=None) -> dict:
    from _family_args import family_parser, run_draws

    parser = family_parser(__doc__.splitlines()[0], max_duration=30.0)
    parser.add_argument("--permutations", type=int, default=99, help="orderings of the null (default 99)")
    parser.add_argument("--without-change", type=int, default=None, metavar="N",
                        help="keep only the first N draws without a change (default: all)")
    args = parser.parse_args(argv)
    from vivbench.validate.study import parse_draws

    steps, none = kept_draws(args.split, parse_draws(args.draws), args.max_events)
    if not steps and not none:
        parser.error(f"no draw of {args.draws} has a step the scan can see or no change at all")
    none = none[:args.without_change]
    args.draws = ",".join(map(str, sorted(steps + none)))
    draws, rows, failed = run_draws("study_change_power", "scan_draw", args, permutations=args.permutations)
    summary = summarise(rows)
    return {"findings": findings(summary), "split": args.split, "draws": draws, "draws_with_step": steps,
            "max_events": args.max_events, "max_duration_min": args.max_duration, "permutations": args.permutations,
            "failed_draws": failed, "summary": summary, "rows": rows}


if __name__ == "__main__":
    main()
