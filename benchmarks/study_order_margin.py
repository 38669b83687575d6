"""Study: the margin of the confidence set of order subsets (``order_set_margin``), over development draws of the family.

Run::

    python benchmarks/run_study.py order_margin --split development --draws 0-29 --out DIR \
        [--max-events N] [--max-duration 30] [--workers 2]

The window verdict of the varying model flags a window only when every order subset in its
confidence set (the models without some of the orders 0, 2, 3 whose leave-one-event-out error is
not significantly above the best subset's) gives the window's regime. Over many events a subset
that is worse by a fraction of a per cent on every event is significantly worse, so the set can
shrink to one model even where the split of the dynamics between the orders is not identified
(a forced response read by a model of A alone). ``order_set_margin`` keeps in the set every subset
within that relative excess of the best (``vivbench.models.ORDER_SET_MARGIN``, a stated prior).

Every draw's campaign is generated with the caps, identified, and the selection of ``vivbench
pool`` fitted once; the margin acts on the verdict only, so for each value (0: the test alone,
0.2 %, 0.5 %, 1 %, 2 %) the confidence sets of every model of the selection (the chosen, the other
members of its set, its perturbed-wind refits) are recomputed from their per-event held-out errors
(:func:`vivbench.regression.confidence_set`) and the verdict scored against the truth's regimes.
Per value, over the draws: the draws with at least 20 flagged window-equations, how many keep the
verdict's promise (at least 95 % of the flags right), the worst share right, the flags in all and
right, the self-excited flags (model regime 2, 3 or 4) on forced-only draws and the median coverage.

Development draws only: the prior is chosen on them. The study directory ``--out`` keeps each
draw's campaign, identification and scores; rerunning with the same options continues it.
"""

from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import math  # noqa: E402

import numpy as np  # noqa: E402

from vivbench.validate.study_report import PROMISE_MIN_FLAGS  # noqa: E402

#: The margins scored.
VALUES = (0.0, 0.002, 0.005, 0.01, 0.02)


def _label(value: float) -> str:
    return f"{value:g}"


def _selection_models(selection) -> list:
    """Every fitted varying model whose order-subset set enters the selection's verdict."""
    out = [selection.model_, *getattr(selection, "set_models_", []), *getattr(selection, "perturbed_models_", [])]
    return [m for m in out if getattr(m, "subset_loeo_event_", None) is not None]


def set_margin(selection, margin: float) -> None:
    """Recompute the confidence sets of order subsets of every model of ``selection`` with ``margin``, in place."""
    from vivbench.regression.model_set import confidence_set

    for m in _selection_models(selection):
        for k in range(m.subset_loeo_event_.shape[1]):
            loss = m.subset_loeo_event_[:, k, :]
            has = np.isfinite(loss).all(axis=0)
            if has.any():
                m.subset_plausible_[:, k] = confidence_set(loss[:, has], m.model_set_level, m.model_set_test,
                                                           margin=margin)


def score_draw(task: dict) -> dict:
    """One draw: generate (capped), identify, fit the selection once, score its verdict at every margin."""
    from vivbench.regimes.truth import truth_window_regimes
    from vivbench.synth.family import draw_bridge
    from vivbench.validate.methods import fit_method, resolve_method

    from benchmarks._family_args import capped_draw, store_row, stored_row

    done = stored_row(task)
    if done is not None:
        return done
    records, truths, windows = capped_draw(task)
    fitted, seconds = fit_method(resolve_method("varying"), records)
    labels = draw_bridge(task["split"], task["draw"]).labels
    row = {"draw": task["draw"], "n_events": len(records), "forced_only": bool(labels["forced_only"]),
           "chosen": fitted.model.chosen_, "fit_s": seconds}
    truth = [truth_window_regimes(t, s, e, tau=fitted.model.tau).astype(int) for t, (s, e) in zip(truths, windows)]
    for value in VALUES:
        set_margin(fitted.model, value)
        flagged = right = scored = excited = 0
        for rec, tru, (s, e) in zip(records, truth, windows):
            flag = fitted.identifiable(rec, s, e)
            regime = fitted.window_regimes(rec, s, e)
            flagged += int(flag.sum())
            right += int((flag & (regime == tru)).sum())
            excited += int((flag & (regime >= 2)).sum())
            scored += int(((regime > 0) & (tru > 0)).sum())
        k = _label(value)
        row.update({f"flags_{k}": flagged, f"right_{k}": right, f"self_excited_{k}": excited,
                    f"coverage_{k}": flagged / scored if scored else math.nan})
    return store_row(task, row)


def summarise(rows: list[dict]) -> list[dict]:
    """One row per margin: the promise, the flags and the forced-only draws' self-excited flags over the draws."""
    from benchmarks._family_args import promise_figures

    forced = [r for r in rows if r["forced_only"]]
    return [{"order_set_margin": _label(value), "draws": len(rows), **promise_figures(rows, _label(value)),
             "forced_only_draws": len(forced),
             "forced_only_self_excited_flags": int(sum(r[f"self_excited_{_label(value)}"] for r in forced))}
            for value in VALUES]


def findings(summary: list[dict]) -> list[str]:
    """Sentences generated from the figures."""
    return [f"order_set_margin {s['order_set_margin']}: the promise kept on {s['promise_kept']} of "
            f"{s['draws_with_enough_flags']} draws with at least {PROMISE_MIN_FLAGS} flags (worst "
            f"{s['worst_share_right']:.3f} right); {s['flags']} flags, {s['flags_right']} right; "
            f"{s['forced_only_self_excited_flags']} self-excited flags on {s['forced_only_draws']} forced-only draws; "
            f"median coverage {s['coverage_median']:.3f}."
            for s in summary]


def main(argv=None) -> dict:
    from _family_args import family_study

    return family_study("study_order_margin", __doc__.splitlines()[0], argv, summarise, findings, max_duration=30.0)


if __name__ == "__main__":
    main()
