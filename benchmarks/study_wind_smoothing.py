"""Study: the wind's smoothing as a stated prior (30 s) or chosen per campaign from the campaign's own events.

Run::

    python benchmarks/run_study.py wind_smoothing --split development --draws 0-29 --out DIR \
        [--max-events N] [--max-duration 30] [--grid 30,90] [--cv-grid 10,30,60] \
        [--variants stated,chosen,cv] [--workers 2]

The deck of a bridge feels either a tributary average of the turbulent wind, which a point
anemometer records in part, or a smooth wind while each anemometer sees its own point turbulence
(5-12 % intensity, 5-60 s time scales in the generator family). The varying campaign model smooths
the measured mean wind with a Gaussian of 30 s (a stated prior); fitted on the wind the truth's
dynamics sees, its error falls most on the draws of the second kind
(docs/results/studies/truth_wind), where a 30 s smoothing leaves much of the point turbulence in the
model's input. Which smoothing a campaign needs depends on which kind it is, and a field user cannot
tell that from the bridge's drawings, so here the smoothing is chosen per campaign from the
campaign's own held-out events: ``wind_smoothing_s`` becomes an option of the selection
(:func:`vivbench.analysis.varying_selection`) beside the yaw degree and the penalty, each candidate
scored by the output error of held-out events simulated under their measured wind. A smoothing adds
no complexity: among the confidence set's models of one structure, the lowest held-out loss decides.
The output error of an envelope barely sees the wind's fast changes, which the envelope's time
constant (minutes) filters out, while dA/dt responds to them at once: the third variant (``cv``)
chooses the smoothing among ``--cv-grid`` once per campaign by the simplest candidate's cross-validated
dA/dt error over folds of events (``wind_smoothing_grid``, :mod:`vivbench.analysis.candidates`) and
gives it to every model, keeping the 30 s prior unless another smoothing's error is lower by more than
one standard error of the paired differences over at least 5 folds
(:func:`vivbench.models.varying_fit.smoothing_choice`).

Every draw's campaign is generated with the caps and identified once; the selection with the prior alone
(``stated``: 30 s), the selection with the smoothing among its options (``chosen``: ``--grid``) and
the selection whose models choose it by their cross-validation (``cv``: ``--cv-grid``, as
``vivbench pool --wind-smoothing-grid``) are fitted on the same records (those ``vivbench pool`` fits)
and scored against the truth: the
energy-weighted relative dA/dt error on the truth's own (A, U), the curve error, the flagged
window-equations and how many carry the truth's regime, the self-excited flags on forced-only draws,
the model chosen and the fit's wall time. The summary gives per variant the median, 90th percentile
and worst error over the draws, the median of the paired ratio chosen / stated, the draws where the
chosen smoothing is worse by more than 10 %, the errors by the draws' kind of wind error, and the
verdict's promise (at least 95 % of at least 20 flags right).

Development draws choose the prior; an evaluation run only reports. The study directory ``--out``
keeps each draw's campaign, identification and scores; rerunning with the same options continues it.
"""

from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import math  # noqa: E402

import numpy as np  # noqa: E402

#: The variants: the stated prior, the smoothing among the selection's options (held-out output error), and
#: the smoothing chosen by each candidate's cross-validated dA/dt error with the prior kept unless beaten.
VARIANTS = ("stated", "chosen", "cv")


def _smoothing_of(candidate: str) -> float | None:
    """The wind smoothing (s) in a selection candidate's name ("yaw0-cv-smooth90" -> 90.0), None without one."""
    import re

    found = re.search(r"smooth(\d+(?:\.\d+)?)", candidate)
    return float(found.group(1)) if found else None


def _options(grid: tuple[float, ...]) -> dict:
    from vivbench.analysis.selection import VARYING_OPTIONS

    return {**VARYING_OPTIONS, "wind_smoothing_s": tuple(grid)}


def score_draw(task: dict) -> dict:
    """One draw: generate (capped) and identify once; fit and score both variants on pool's records."""
    from vivbench.validate.methods import CampaignMethod

    from benchmarks._family_args import draw_inputs, fit_and_score, labelled_row, store_row, stored_row

    done = stored_row(task)
    if done is not None:
        return done
    labels, row = labelled_row(task)
    row.update(forced_only=bool(labels["forced_only"]),
               point_timescale_s=float(labels["point_timescale_s"] or math.nan))
    records, truths, windows = draw_inputs(task)
    row["n_events"] = len(records)
    methods = {"stated": CampaignMethod("varying"),  # the prior alone
               "chosen": CampaignMethod("varying", options=_options(tuple(task["grid"]))),
               "cv": CampaignMethod("varying", wind_smoothing_grid=tuple(task["cv_grid"]))}
    for name in task["variants"]:
        method = methods[name]
        s = fit_and_score(method, records, truths, windows)
        # on a forced-only draw the truth has regime 1 only: every wrong flag is self-excited
        s["self_excited"] = s["flags"] - s["right"] if row["forced_only"] else 0
        row.update({f"{k}_{name}": v for k, v in s.items()})
    return store_row(task, row)


def summarise(rows: list[dict], variants=VARIANTS) -> list[dict]:
    """One row per variant and kind of wind error (all draws first): errors, pairing with ``stated``, promise."""
    from _family_args import by_wind_error, paired, promise_figures, spread

    from vivbench.models import VaryingCoefficientSINDy

    stated_s = VaryingCoefficientSINDy().wind_smoothing_s  # the stated prior's smoothing, s
    out = []
    for kind, sub in by_wind_error(rows):
        for name in variants:
            err = spread(r[f"error_{name}"] for r in sub)
            cerr = spread(r[f"curve_error_{name}"] for r in sub)
            pair = paired(sub, f"error_{name}", "error_stated")
            entry = {"variant": name, "draws_of": kind, "draws": len(sub), "error_median": err["median"],
                     "error_p90": err["p90"], "error_worst": err["worst"], "curve_error_median": cerr["median"],
                     "curve_error_p90": cerr["p90"],
                     "ratio_to_stated_median": pair["ratio_median"], "worse_by_10pct": pair["worse_by_10pct"],
                     "better_by_10pct": pair["better_by_10pct"],
                     "fit_s_median": float(np.median([r[f"fit_s_{name}"] for r in sub])) if sub else math.nan}
            if kind == "all":
                entry.update(promise_figures(sub, name))
                forced = [r for r in sub if r["forced_only"]]
                entry["forced_only_self_excited_flags"] = int(sum(r[f"self_excited_{name}"] for r in forced))
                # the candidates' names carry their smoothing ("smooth90") where it is an option; the fitted
                # model's own smoothing otherwise (rows written before it was recorded have none)
                chosen = [_smoothing_of(r[f"chosen_{name}"]) if name == "chosen" else r.get(f"smoothing_{name}")
                          for r in sub]
                entry["longer_smoothing_chosen"] = sum(1 for x in chosen if x is not None and x > stated_s)
                entry["shorter_smoothing_chosen"] = sum(1 for x in chosen if x is not None and x < stated_s)
                if name == "cv":  # where the shorter smoothing was chosen: by the kind of errors in the wind
                    entry["shorter_on_tributary"] = sum(1 for x, r in zip(chosen, sub)
                                                        if x is not None and x < stated_s and r["eiv"] == "tributary")
            out.append(entry)
    return out


def findings(summary: list[dict]) -> list[str]:
    """Sentences generated from the figures."""
    said = []
    for s in summary:
        text = (f"{s['variant']}, {s['draws_of']} draws ({s['draws']}): energy-weighted dA/dt error median "
                f"{s['error_median']:.3f}, p90 {s['error_p90']:.3f}, worst {s['error_worst']:.3f}; curves median "
                f"{s['curve_error_median']:.3f}")
        if s["variant"] != "stated":
            text += (f"; paired with the stated prior: median ratio {s['ratio_to_stated_median']:.2f}, better by more "
                     f"than 10 % on {s['better_by_10pct']} draws and worse on {s['worse_by_10pct']}")
        if s["draws_of"] == "all":
            text += (f"; {s['flags']} flags, the promise kept on {s['promise_kept']} of {s['draws_with_enough_flags']}"
                     f" draws with enough flags (worst {s['worst_share_right']:.3f} right); "
                     f"{s['forced_only_self_excited_flags']} self-excited flags on forced-only draws; a longer "
                     f"smoothing than the prior's chosen on {s['longer_smoothing_chosen']}, a shorter on "
                     f"{s['shorter_smoothing_chosen']}"
                     + (f" ({s['shorter_on_tributary']} of them where the deck feels the tributary turbulence)"
                        if "shorter_on_tributary" in s else "") + f"; median fit {s['fit_s_median']:.0f} s")
        said.append(text + ".")
    return said


def main(argv=None) -> dict:
    from _family_args import family_parser, run_draws

    parser = family_parser(__doc__.splitlines()[0], max_duration=30.0)
    parser.add_argument("--grid", default="30,90", help="candidate smoothings of the selection (chosen), s, "
                        "comma-separated (default 30,90)")
    parser.add_argument("--cv-grid", default="10,30,60", help="candidate smoothings of each model's "
                        "cross-validation (cv), s, comma-separated (default 10,30,60)")
    parser.add_argument("--variants", default=",".join(VARIANTS), help="variants to run, comma-separated "
                        f"(default {','.join(VARIANTS)}; stated is always run)")
    args = parser.parse_args(argv)
    grids = {}
    for flag, text in (("--grid", args.grid), ("--cv-grid", args.cv_grid)):
        try:
            grids[flag] = tuple(float(x) for x in text.split(","))
        except ValueError:
            grids[flag] = ()
        if not grids[flag] or any(not (math.isfinite(g) and g >= 0) for g in grids[flag]):
            parser.error(f"{flag} must be seconds >= 0, comma-separated; got {text!r}")
    variants = ["stated"] + [v for v in args.variants.split(",") if v and v != "stated"]
    if any(v not in VARIANTS for v in variants):
        parser.error(f"--variants must be among {', '.join(VARIANTS)}; got {args.variants!r}")
    grid = grids["--grid"]
    draws, rows, failed = run_draws("study_wind_smoothing", "score_draw", args, grid=list(grid),
                                    cv_grid=list(grids["--cv-grid"]), variants=variants)
    summary = summarise(rows, variants) if rows else []
    return {"findings": findings(summary), "split": args.split, "draws": draws, "grid_s": list(grid),
            "cv_grid_s": list(grids["--cv-grid"]), "variants": variants,
            "max_events": args.max_events, "max_duration_min": args.max_duration, "failed_draws": failed,
            "summary": summary, "rows": rows}


if __name__ == "__main__":
    main()
