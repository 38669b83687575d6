"""Study: which wind the varying model's curves should take, by the kind of error in the wind, over development draws.

Run::

    python benchmarks/run_study.py wind_input --split development --draws 0-29 --out DIR \
        [--max-duration 30] [--variants input_sum,input_chosen] [--workers 2]

The stated prior fits the curves of the sections' weighted mean wind (``wind_input="mean"``). The
truth sums every section's aerodynamic force at that section's own felt wind. Where the felt wind
differs along the span (the family's tributary-averaged felt wind, ``eiv="tributary"``), the tied sum
of every section's measured wind (``wind_input="sum"``: one curve shape, weighted by the sections'
weights) has the truth's form. Where the deck feels one smooth wind and each anemometer adds its own
point turbulence (``eiv="smooth"``), the sum carries every anemometer's error into the curves, which
the mean averages down.

Both are fitted on the same campaigns, as the variants of the priors study (``study_priors``):
``input_sum`` (the tied sum on every campaign) and, where asked, ``input_chosen`` (the mean or the
sum chosen among the selection's candidates by their held-out output error). Every draw's campaign
is generated and identified once; the variants differ only by the wind input.

Over the draws with two sections or more (on one section the two inputs are the same model), per
kind of error in the wind: the energy-weighted relative dA/dt error on the truth's own (A, U) of the
stated prior and of each variant (median, 90th percentile, worst), the draws where the variant is
better or worse than the stated prior by more than 10 %, and the ratio of the variant's fit time to
the stated prior's (the whole selection, as ``vivbench pool`` fits it; wall times of one run on a
shared machine, so only their ratios are compared). The kind of error in the wind is the
generator's label, which no user has: the page says where each input serves, not how a campaign
could tell which it is.

Development draws only. ``--max-events`` and ``--max-duration`` (minutes) cap the campaigns. The
study directory ``--out`` is that of the priors study with the same options and variants, and is
resumable: the page lists the draws this run computed and those it found finished there (their
fit times are those of the run that computed them).
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

import study_priors  # noqa: E402

#: The variants of ``study_priors`` that change the wind input, and the default run.
WIND_VARIANTS = ("input_sum", "input_chosen")
DEFAULT_VARIANTS = "input_sum"
#: Paired ratio beyond which a draw counts as better or worse.
MARGIN = 0.10


def _fit_times(out: Path) -> dict[tuple[int, str], float]:
    """Each (draw, variant)'s fit time (s) from the study's journal; the stated prior is ``"stated"``."""
    from vivbench.validate.journal import load

    names = {"varying": "stated", **{study_priors.METHOD_PREFIX + v: v for v in WIND_VARIANTS}}
    rows, _dropped = load(out / "study.jsonl", n_tasks=2**31, columns=("task_id", "draw", "methods"))
    return {(int(row["draw"]), names[method]): float(scores["fit_time_s"])
            for row in rows.values() for method, scores in row["methods"].items()
            if method in names and scores.get("fit_time_s") is not None}


def _spread(x: np.ndarray) -> dict:
    x = x[np.isfinite(x)]
    if not x.size:
        return {"median": math.nan, "p90": math.nan, "worst": math.nan}
    return {"median": float(np.median(x)), "p90": float(np.percentile(x, 90)), "worst": float(np.max(x))}


def paired_rows(rows: list[dict], variants: list[str], times: dict) -> list[dict]:
    """One row per draw with two sections or more: the stated prior's and each variant's error and fit time."""
    by = {}
    for r in rows:
        by.setdefault(r["draw"], {})[r["variant"]] = r
    out = []
    for draw in sorted(by):
        got = by[draw]
        stated = got.get("stated")
        if stated is None or stated["n_sections"] < 2:
            continue
        row = {"draw": draw, "n_sections": stated["n_sections"], "eiv": stated["eiv"], "n_events": stated["n_events"],
               "stated_error": stated["dA_error_energy"], "stated_chosen": stated["chosen"]}
        for v in variants:
            r = got.get(v)
            err = r["dA_error_energy"] if r else math.nan
            row[f"{v}_error"] = err
            row[f"{v}_chosen"] = r["chosen"] if r else ""
            row[f"{v}_ratio"] = err / stated["dA_error_energy"] if stated["dA_error_energy"] > 0 else math.nan
            t0, t1 = times.get((draw, "stated")), times.get((draw, v))
            row[f"{v}_fit_time_ratio"] = t1 / t0 if t0 and t1 else math.nan
        out.append(row)
    return out


def summarise(paired: list[dict], variants: list[str]) -> list[dict]:
    """Per variant and kind of error in the wind: the spread of the errors and the paired counts."""
    out = []
    for v in variants:
        for eiv in ("tributary", "smooth", "all"):
            g = [r for r in paired if eiv == "all" or r["eiv"] == eiv]
            if not g:
                continue
            ratio = np.array([r[f"{v}_ratio"] for r in g], dtype=float)
            times = np.array([r[f"{v}_fit_time_ratio"] for r in g], dtype=float)
            times = times[np.isfinite(times)]
            s0 = _spread(np.array([r["stated_error"] for r in g], dtype=float))
            s1 = _spread(np.array([r[f"{v}_error"] for r in g], dtype=float))
            out.append({"variant": v, "eiv": eiv, "draws": len(g),
                        **{f"stated_{k}": s0[k] for k in s0}, **{f"variant_{k}": s1[k] for k in s1},
                        "better": int(np.sum(ratio < 1.0 - MARGIN)), "worse": int(np.sum(ratio > 1.0 + MARGIN)),
                        "fit_time_ratio_median": float(np.median(times)) if times.size else math.nan,
                        "fit_time_ratio_max": float(np.max(times)) if times.size else math.nan})
    return out


def _draws(n: int) -> str:
    return f"{n} draw" if n == 1 else f"{n} draws"


def findings(summary: list[dict]) -> list[str]:
    """Sentences generated from the summary."""
    what = {"input_sum": "The tied sum on every campaign",
            "input_chosen": "The wind input chosen by held-out output error"}
    kind = {"tributary": "tributary-averaged felt wind", "smooth": "smooth felt wind, point turbulence at the "
            "anemometers", "all": "every draw with two sections or more"}
    said = []
    for s in summary:
        said.append(f"{what[s['variant']]}, {kind[s['eiv']]} ({s['draws']} draws): energy-weighted dA/dt error "
                    f"median {s['stated_median']:.3f} -> {s['variant_median']:.3f}, 90th percentile "
                    f"{s['stated_p90']:.3f} -> {s['variant_p90']:.3f}, worst {s['stated_worst']:.3f} -> "
                    f"{s['variant_worst']:.3f}; better by more than {MARGIN:.0%} on {_draws(s['better'])}, worse "
                    f"on {s['worse']}; fit time {s['fit_time_ratio_median']:.1f} x the stated prior's (median; "
                    f"at most {s['fit_time_ratio_max']:.1f} x).")
    return said


def main(argv=None) -> dict:
    from _family_args import family_parser

    argv = list(sys.argv[1:] if argv is None else argv)
    parser = family_parser(__doc__.splitlines()[0])
    parser.add_argument("--variants", default=DEFAULT_VARIANTS,
                        help=f"comma-separated variants beside the stated prior, of {', '.join(WIND_VARIANTS)} "
                             f"(default {DEFAULT_VARIANTS})")
    args = parser.parse_args(argv)
    variants = [v.strip() for v in args.variants.split(",") if v.strip()]
    unknown = sorted(set(variants) - set(WIND_VARIANTS))
    if unknown or not variants:
        parser.error(f"unknown variants {unknown}; allowed: {', '.join(WIND_VARIANTS)}")
    if "--variants" not in argv:
        argv += ["--variants", args.variants]
    figures = study_priors.main(argv)
    rows = [r for r in figures["rows"] if not r["error"]]
    paired = paired_rows(rows, variants, _fit_times(args.out))
    summary = summarise(paired, variants)
    return {"findings": findings(summary), "split": figures["split"], "draws": figures["draws"],
            "max_events": figures["max_events"], "max_duration_min": figures["max_duration_min"],
            "failed_draws": figures["failed_draws"], "draws_computed": figures["draws_computed"],
            "draws_resumed": figures["draws_resumed"], "variants": variants, "summary": summary, "rows": paired}


if __name__ == "__main__":
    main()
