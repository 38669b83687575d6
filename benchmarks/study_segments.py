"""Study: what a campaign model gains when it is refitted on each side of the change its scan locates.

Run::

    python benchmarks/run_study.py segments --split development --draws 0-119 --out DIR \
        [--max-events N] [--max-duration 30] [--workers 2]

The family puts a step of the structural damping ratio (times 1 -+ U(0.3, 0.6), from an event
drawn in 2..n_events on) into a quarter of its draws (:mod:`vivbench.synth.family`). Among
``--draws`` this study keeps the draws with such a step and at least 3 events on each side of it
in the (capped) campaign (:func:`benchmarks.study_change_power.kept_draws`). Each is generated,
identified and fitted with the default campaign model (``varying``, as ``vivbench pool`` fits
it). Where its change scan locates a change, the same model is refitted on the events before the
located event and on the events from it on (what ``vivbench pool --events`` does when a user
pools each side), and, as an oracle no user has, on each side of the true step.

Per draw the page gives the energy-weighted relative dA/dt error on the truth's own (A, U) of the
campaign model fitted to every event and of the two-piece model (each event predicted by the model
of its own side), over all events and over the events after the change (the bridge as it is now);
and the flagged window-equations and the share of them with the true regime (the model fitted to
every event flags nothing once its scan locates a change; each side's model has its own verdict).
``--max-events`` and ``--max-duration`` (minutes; default 30) cap the campaigns. The study
directory ``--out`` is resumable: a rerun reads the finished draws (the page's wall time is then that of
the rest; each row's ``fit_s`` is the fit of the model of every event, in the run that fitted it).
"""

from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import math  # noqa: E402

import numpy as np  # noqa: E402


def _energy(models, records, truths) -> float:
    """Energy-weighted relative dA/dt error on the truths' (A, U), each record predicted by ``models[i]``."""
    from vivbench.validate.metrics import energy_relative_error
    from vivbench.validate.recovery import model_rhs_true_AU, record_yaw_on

    fm, ft = [], []
    for model, rec, truth in zip(models, records, truths):
        _t, f_model, f_true = model_rhs_true_AU(model, truth, event_id=rec.event_id,
                                                yaw=record_yaw_on(rec, truth["time"].values))
        fm.append(f_model.ravel())
        ft.append(f_true.ravel())
    return energy_relative_error(np.concatenate(fm), np.concatenate(ft)) if fm else math.nan


def _pieces(split_at: int, records, truths, windows, truth_regimes, whole) -> dict:
    """The two-piece model split before record ``split_at``: errors and verdicts beside those of ``whole``."""
    from vivbench.validate.methods import fit_method, resolve_method

    from benchmarks._family_args import verdict_counts

    sides = [slice(0, split_at), slice(split_at, None)]
    fitted = [fit_method(resolve_method("varying"), records[s])[0] for s in sides]
    per_record = [fitted[0]] * split_at + [fitted[1]] * (len(records) - split_at)
    after = sides[1]
    flagged = right = 0
    for model, s in zip(fitted, sides):
        f, r, _cov = verdict_counts(model, records[s], truth_regimes[s], windows[s])
        flagged += f
        right += r
    return {"error_all": _energy(per_record, records, truths),
            "error_after": _energy([fitted[1]] * (len(records) - split_at), records[after], truths[after]),
            "whole_error_after": _energy([whole] * (len(records) - split_at), records[after], truths[after]),
            "flagged": flagged, "flagged_right_share": right / flagged if flagged else math.nan}


def segment_draw(task: dict) -> dict:
    """One draw: generate (capped), identify, fit ``varying`` on every event, and on each side of the located
    and of the true change."""
    from vivbench.regimes.truth import truth_window_regimes
    from vivbench.synth.family import draw_bridge
    from vivbench.validate.methods import fit_method, resolve_method

    from benchmarks._family_args import capped_draw, store_row, stored_row, verdict_counts

    done = stored_row(task)
    if done is not None:
        return done
    records, truths, windows = capped_draw(task)
    truth_regimes = [truth_window_regimes(t, s, e).astype(int) for t, (s, e) in zip(truths, windows)]
    whole, fit_s = fit_method(resolve_method("varying"), records)
    labels = draw_bridge(task["split"], task["draw"]).labels
    step = labels["step_event"] - 1  # the first event after the step, 0-based
    change = whole.change_
    ids = [r.event_id for r in records]
    located = ids.index(change["event"]) if change["detected"] and change["event"] in ids else -1
    flagged, right, _cov = verdict_counts(whole, records, truth_regimes, windows)
    row = {"draw": task["draw"], "n_events": len(records), "step_index": step,
           "step_factor": labels["step_damping_factor"], "eiv": labels["eiv"], "n_sections": labels["n_sections"],
           "yaw_effect": labels["yaw_effect"], "p_value": float(change["p_value"]), "located_index": located,
           "whole_error_all": _energy([whole] * len(records), records, truths), "whole_flagged": flagged,
           "whole_flagged_right_share": right / flagged if flagged else math.nan, "fit_s": fit_s}
    for name, split_at in (("located", located), ("true", step)):
        part = _pieces(split_at, records, truths, windows, truth_regimes, whole) if split_at > 0 else {}
        for key in ("error_all", "error_after", "whole_error_after", "flagged", "flagged_right_share"):
            row[f"{name}_{key}"] = part.get(key, math.nan)
    return store_row(task, row)


def summarise(rows: list[dict]) -> list[dict]:
    """Errors over the draws whose scan located the change, for the model fitted to every event and the
    two-piece models; and over every draw with a step for the oracle split."""
    from _family_args import spread

    located = [r for r in rows if r["located_index"] > 0]
    out = [{"model": "every event", "draws": "located", **spread(r["whole_error_all"] for r in located),
            "after_median": spread(r["located_whole_error_after"] for r in located)["median"]},
           {"model": "two pieces at the located change", "draws": "located",
            **spread(r["located_error_all"] for r in located),
            "after_median": spread(r["located_error_after"] for r in located)["median"]},
           {"model": "every event", "draws": "all with a step", **spread(r["whole_error_all"] for r in rows),
            "after_median": spread(r["true_whole_error_after"] for r in rows)["median"]},
           {"model": "two pieces at the true step (oracle)", "draws": "all with a step",
            **spread(r["true_error_all"] for r in rows),
            "after_median": spread(r["true_error_after"] for r in rows)["median"]}]
    return out


def findings(rows: list[dict], summary: list[dict]) -> list[str]:
    """Sentences generated from the figures."""
    located = [r for r in rows if r["located_index"] > 0]
    within = [r for r in located if abs(r["located_index"] - r["step_index"]) <= 1]
    lower = [r for r in located if r["located_error_all"] < r["whole_error_all"]]
    flags = [r for r in located if r["located_flagged"] >= 20]
    kept = [r for r in flags if r["located_flagged_right_share"] >= 0.95]
    s = {(x["model"], x["draws"]): x for x in summary}
    whole, two = s[("every event", "located")], s[("two pieces at the located change", "located")]
    out = [f"{len(rows)} draws with a step the capped campaign holds with 3 events on each side; the scan located a "
           f"change on {len(located)} ({len(within)} within one event of the step)."]
    if located:
        out.append(f"On those {len(located)}: energy-weighted dA/dt error of the model fitted to every event median "
                   f"{whole['median']:.3f} (90th percentile {whole['p90']:.3f}, worst {whole['worst']:.3f}); of the "
                   f"two-piece model {two['median']:.3f} ({two['p90']:.3f}, {two['worst']:.3f}); lower on "
                   f"{len(lower)} of {len(located)}. After the change alone: median {whole['after_median']:.3f} "
                   f"against {two['after_median']:.3f}.")
        out.append(f"The two pieces' verdicts: {len(flags)} draws with at least 20 flags, the promise (95 % right) "
                   f"kept on {len(kept)}; the model fitted to every event flags nothing once a change is located.")
    return out


def main(argv=None) -> dict:
    from _family_args import family_parser, run_draws

    from benchmarks.study_change_power import kept_draws

    parser = family_parser(__doc__.splitlines()[0], max_duration=30.0)
    args = parser.parse_args(argv)
    from vivbench.validate.study import parse_draws

    steps, _none = kept_draws(args.split, parse_draws(args.draws), args.max_events)
    if not steps:
        parser.error(f"no draw of {args.draws} has a step with 3 events on each side")
    args.draws = ",".join(map(str, steps))
    draws, rows, failed = run_draws("study_segments", "segment_draw", args)
    summary = summarise(rows)
    return {"findings": findings(rows, summary), "split": args.split, "draws": draws,
            "max_events": args.max_events, "max_duration_min": args.max_duration, "failed_draws": failed,
            "summary": summary, "rows": rows}


if __name__ == "__main__":
    main()
