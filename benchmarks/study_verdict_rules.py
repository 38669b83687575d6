"""Study: the selection's two verdict rules, the signed-rank test and the test of dynamics by wind, over development draws.

Run::

    python benchmarks/run_study.py verdict_rules --split development --draws 60-159 --out DIR \
        [--max-events 6] [--max-duration 20] [--workers 1]

The confidence set of ``vivbench pool``'s held-out selection drops a candidate that a one-sided
signed-rank test finds worse than the best (``rank_level``, the stated prior
``vivbench.analysis.RANK_LEVEL``) beside the one-standard-error rule, and a window is flagged only
where its wind lies in a bin in which the chosen model beats the quasi-steady map (``wind_bins``:
off by default, ``vivbench.analysis.WIND_BINS`` bins when ``vivbench pool --wind-bins`` asks for
it). Both are priors of the verdict; this study measures what each does, on the same campaigns:

- ``stated``: both as stated (the signed-rank test, no test by wind);
- ``one_se_only``: ``rank_level=None`` (the one-standard-error rule alone);
- ``wind_bins``: the test by wind in ``WIND_BINS`` bins;
- ``wind_bins_3``: the test by wind in three bins.

A draw directory whose scores lack a variant (written when the variants differed) gets that
variant's scores and keeps the others.

Every draw's campaign is generated with the caps (six events of at most 20 minutes by default),
identified once, and each variant's selection fitted on the same records and scored against the
truth: the flagged window-equations, how many carry the truth's regime, the coverage and the
energy-weighted dA/dt error on the truth's own (A, U). Per variant, over the draws: the draws with
at least 20 flags, how many keep the verdict's promise (at least 95 % of the flags right), the worst
share right, the flags in all and right, the median coverage and the error's median and 90th
percentile; and the draws whose promise a variant breaks where the stated rules keep it, or the
reverse.

Development draws only: the priors may be chosen on them. The study directory ``--out`` keeps each
draw's campaign, identification and scores; rerunning it with the same options continues it.
"""

from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import json  # noqa: E402
import math  # noqa: E402

import numpy as np  # noqa: E402

from vivbench.analysis import WIND_BINS  # noqa: E402

#: Variant name -> the selection's parameters it changes (none: as stated).
VARIANTS = {
    "stated": {},
    "one_se_only": {"rank_level": None},
    "wind_bins": {"wind_bins": WIND_BINS},
    "wind_bins_3": {"wind_bins": 3},
}
#: The prefixes of a variant's scores in a row (``flags_stated``, ...).
_SCORES = ("chosen_", "flags_", "right_", "coverage_", "error_")

#: Fewest flags for a draw to test the promise, and the promise itself.
MIN_FLAGS, PROMISE = 20, 0.95


def score_draw(task: dict) -> dict:
    """One draw: generate (capped), identify, fit every variant's selection and score it against the truth."""
    from vivbench.analysis.selection import varying_selection
    from vivbench.regimes.truth import truth_window_regimes
    from vivbench.validate.methods import SelectedVerdictModel, score_fitted

    from benchmarks._family_args import capped_draw, store_row, stored_variants, verdict_counts

    row, missing = stored_variants(task, VARIANTS)
    if not missing:
        return row
    row = row or {}
    # the scores of variants no longer studied are dropped
    row = {k: v for k, v in row.items() if not k.startswith(_SCORES) or k.split("_", 1)[1] in VARIANTS}
    records, truths, windows = capped_draw(task)
    row.update(draw=task["draw"], n_events=len(records))
    truth_regimes = None
    for name in missing:
        params = VARIANTS[name]
        sel = varying_selection(seed=0, workers=1, **params).fit(records)
        if truth_regimes is None:
            truth_regimes = [truth_window_regimes(t, s, e, tau=sel.tau).astype(int)
                             for t, (s, e) in zip(truths, windows)]
        flagged, right, coverage = verdict_counts(sel, records, truth_regimes, windows)
        scores = score_fitted(SelectedVerdictModel(sel), records, truths, windows=windows, simulate=False)
        row.update({f"chosen_{name}": sel.chosen_, f"flags_{name}": flagged, f"right_{name}": right,
                    f"coverage_{name}": coverage,
                    f"error_{name}": float(scores["rhs_error_true_AU_energy"])})
    return store_row(task, row)


def _kept(row: dict, name: str):
    """True/False: the draw keeps the promise under the variant; None: fewer than MIN_FLAGS flags."""
    flags = row[f"flags_{name}"]
    return None if flags < MIN_FLAGS else row[f"right_{name}"] / flags >= PROMISE


def summarise(rows: list[dict]) -> list[dict]:
    """One row per variant: the promise, the flags and the error over the draws."""
    out = []
    for name, params in VARIANTS.items():
        tested = [r for r in rows if _kept(r, name) is not None]
        shares = [r[f"right_{name}"] / r[f"flags_{name}"] for r in tested]
        cov = np.array([r[f"coverage_{name}"] for r in rows], dtype=float)
        err = np.array([r[f"error_{name}"] for r in rows], dtype=float)
        err = err[np.isfinite(err)]
        out.append({"variant": name, "changes": json.dumps(params) if params else "as stated", "draws": len(rows),
                    "draws_with_enough_flags": len(tested), "promise_kept": int(sum(s >= PROMISE for s in shares)),
                    "worst_share_right": min(shares, default=math.nan),
                    "flags": int(sum(r[f"flags_{name}"] for r in rows)),
                    "flags_right": int(sum(r[f"right_{name}"] for r in rows)),
                    "coverage_median": float(np.nanmedian(cov)) if np.isfinite(cov).any() else math.nan,
                    "error_median": float(np.median(err)) if err.size else math.nan,
                    "error_p90": float(np.percentile(err, 90)) if err.size else math.nan,
                    "broken_where_stated_keeps": [r["draw"] for r in rows
                                                  if _kept(r, name) is False and _kept(r, "stated") is not False],
                    "kept_where_stated_breaks": [r["draw"] for r in rows
                                                 if _kept(r, name) is not False and _kept(r, "stated") is False]})
    return out


def findings(summary: list[dict]) -> list[str]:
    """Sentences generated from the figures."""
    said = []
    for s in summary:
        said.append(f"{s['variant']} ({s['changes']}): the promise kept on {s['promise_kept']} of "
                    f"{s['draws_with_enough_flags']} draws with at least {MIN_FLAGS} flags (worst "
                    f"{s['worst_share_right']:.3f} right); {s['flags']} flags, {s['flags_right']} right; median "
                    f"coverage {s['coverage_median']:.3f}; energy-weighted dA/dt error median {s['error_median']:.3f}, "
                    f"90th percentile {s['error_p90']:.3f}.")
        if s["variant"] != "stated":
            said.append(f"{s['variant']} breaks the promise where the stated rules keep it (or flag too little to "
                        f"test) on draws {s['broken_where_stated_keeps'] or 'none'}, and keeps it (or flags too "
                        f"little) where they break it on draws {s['kept_where_stated_breaks'] or 'none'}.")
    return said


def main(argv=None) -> dict:
    from _family_args import family_parser, run_draws

    args = family_parser(__doc__.splitlines()[0], max_events=6, max_duration=20.0).parse_args(argv)
    draws, rows, failed = run_draws("study_verdict_rules", "score_draw", args)
    summary = summarise(rows)
    return {"findings": findings(summary), "split": args.split, "draws": draws,
            "max_events": args.max_events, "max_duration_min": args.max_duration,
            "failed_draws": failed, "summary": summary, "rows": rows}


if __name__ == "__main__":
    main()
