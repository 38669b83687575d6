"""Study: limit regimes in events too short to show how a change ends, over development draws of the family.

Run::

    python benchmarks/run_study.py short_events --split development --draws 0-59 --out DIR \
        [--max-events 6] [--max-duration 20] [--workers 1]

An event that lasts a few envelope time constants shows an amplitude's growth or decay but not
how it ends, and the split of that change between the orders of A, which decides the limit
regimes 3 and 4, is then not identified (docs/model_selection.md). The selection of ``vivbench
pool`` reads the envelope's time constant from the campaign's chosen model and flags no limit
regime in an event shorter than ``min_time_constants`` of them (the stated prior
``vivbench.analysis.LIMIT_TIME_CONSTANTS``).

Every draw's campaign is generated with the caps (six events of at most 20 minutes by default:
small campaigns, where events are short against the time constant of a low, lightly damped mode),
identified, and its selection fitted once; the restriction acts on the verdict only, so each value
of ``min_time_constants`` (none, 3, 5, 8) is scored on the same fit against the truth's regimes.
Per value, over the draws: the draws with at least 20 flagged window-equations, how many keep the
verdict's promise (at least 95 % of the flags right), the worst share right, the flags in all and
the median coverage. Per draw: the time constant read from the campaign against the structure's
1/(2 pi f zeta), which the campaign's own estimate must not need.

Development draws only: the prior may be chosen on them. The study directory ``--out`` keeps each
draw's campaign, identification and scores; rerunning it with the same options continues it.
"""

from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import math  # noqa: E402

import numpy as np  # noqa: E402

from vivbench.validate.study_report import PROMISE_MIN_FLAGS  # noqa: E402

#: The values of ``min_time_constants`` scored (None: no restriction).
VALUES = (None, 3.0, 5.0, 8.0)


def _label(value) -> str:
    return "none" if value is None else f"{value:g}"


def score_draw(task: dict) -> dict:
    """One draw: generate (capped), identify, fit the selection once, score the verdict at every value."""
    from vivbench.analysis.selection import varying_selection
    from vivbench.regimes.truth import truth_window_regimes
    from vivbench.synth.family import draw_bridge

    from benchmarks._family_args import capped_draw, store_row, stored_row, verdict_counts

    done = stored_row(task)
    if done is not None:
        return done
    records, truths, windows = capped_draw(task)
    sel = varying_selection(seed=0, workers=1).fit(records)
    labels = draw_bridge(task["split"], task["draw"]).labels
    row = {"draw": task["draw"], "n_events": len(records), "chosen": sel.chosen_,
           "time_constant_s": sel.time_constant_s_,
           "structural_time_constant_s": 1.0 / (2 * math.pi * labels["frequency_hz"] * labels["damping_ratio"]),
           "event_duration_median_s": float(np.median(sel.event_duration_s_)),
           "short_events": len(sel.short_events())}
    truth_regimes = [truth_window_regimes(t, s, e, tau=sel.tau).astype(int) for t, (s, e) in zip(truths, windows)]
    for value in VALUES:
        sel.min_time_constants = value
        flagged, right, coverage = verdict_counts(sel, records, truth_regimes, windows)
        row[f"flags_{_label(value)}"] = flagged
        row[f"right_{_label(value)}"] = right
        row[f"coverage_{_label(value)}"] = coverage
    return store_row(task, row)


def summarise(rows: list[dict]) -> list[dict]:
    """One row per value of ``min_time_constants``: the promise and the flags over the draws."""
    from benchmarks._family_args import promise_figures

    return [{"min_time_constants": _label(value), "draws": len(rows), **promise_figures(rows, _label(value))}
            for value in VALUES]


def findings(summary: list[dict], rows: list[dict]) -> list[str]:
    """Sentences generated from the figures."""
    said = []
    for s in summary:
        said.append(f"min_time_constants {s['min_time_constants']}: the promise kept on {s['promise_kept']} of "
                    f"{s['draws_with_enough_flags']} draws with at least {PROMISE_MIN_FLAGS} flags (worst "
                    f"{s['worst_share_right']:.3f} right); {s['flags']} flags, {s['flags_right']} right.")
    ratio = np.array([r["time_constant_s"] / r["structural_time_constant_s"] for r in rows], dtype=float)
    known = ratio[np.isfinite(ratio)]
    if known.size:
        said.append(f"The time constant read from the campaign is {np.median(known):.2f} times the structure's "
                    f"1/(2 pi f zeta) at the median over {known.size} draws (5th to 95th percentile "
                    f"{np.percentile(known, 5):.2f} to {np.percentile(known, 95):.2f}; aerodynamic damping shortens "
                    f"it); it is not identified on {int(ratio.size - known.size)} draws, whose chosen model flags no "
                    "regime-1 window.")
    return said


def main(argv=None) -> dict:
    from _family_args import family_parser, run_draws

    args = family_parser(__doc__.splitlines()[0], max_events=6, max_duration=20.0).parse_args(argv)
    draws, rows, failed = run_draws("study_short_events", "score_draw", args)
    summary = summarise(rows)
    return {"findings": findings(summary, rows), "split": args.split, "draws": draws,
            "max_events": args.max_events, "max_duration_min": args.max_duration,
            "failed_draws": failed, "summary": summary, "rows": rows}


if __name__ == "__main__":
    main()
