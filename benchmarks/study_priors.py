"""Study: how much the varying campaign model's stated priors matter, over development draws of the family.

Run::

    python benchmarks/run_study.py priors --split development --draws 0-15 --out DIR \
        [--max-events 10] [--max-duration 30] [--workers 1]

The campaign model that ``vivbench pool`` fits chooses its options from the campaign's held-out
events (docs/model_selection.md); a few constants stay fixed as stated priors. Each is varied
here one at a time, halved and doubled where it is a scale, on the same campaigns:

- ``wind_smoothing_s`` (30 s): the time scale of the Gaussian smoothing of the measured mean wind
  (15 s and 60 s), or chosen per campaign: within each candidate's fit from 15, 30 and 60 s by the
  cross-validated dA/dt error over events (``smoothing_cv``, ``wind_smoothing_grid``), or among the
  selection's candidates by their held-out output error beside the yaw degree and the penalty
  (``smoothing_chosen``);
- ``perturbation_timescale_s`` (60 s): the time scale of the wind error estimate and of the
  wind-perturbed refits a flag must survive (30 s and 120 s);
- ``wind_weights`` (``modal``): the sections' weights in the mean wind (``equal`` instead);
- ``wind_input`` (``mean``): the curves of the sections' weighted mean wind, or chosen among the
  selection's candidates beside the yaw degree and the penalty from the mean wind and the tied sum
  of every section's own wind (``"sum"``: one curve shape weighted by the sections' weights, the
  truth's form where the deck feels a wind that differs along the span) by their held-out output
  error (``input_chosen``), or the tied sum on every campaign (``input_sum``).

``--variants`` (comma-separated names) runs only some variants beside the stated priors.

Every draw's campaign is generated and identified once, and each variant is fitted and scored against
the truth by :func:`vivbench.validate.run_study`, so the variants differ only by the prior. Per variant,
over the draws: the energy-weighted relative dA/dt error on the truth's own (A, U) (median, 90th
percentile, worst), the draws with at least 20 flagged window-equations and how many of them keep
the verdict's promise (at least 95 % of the flags right), the median coverage, and paired against the
stated value: the median ratio of the energy-weighted error and the share of draws within 10 % of it.

Development draws only: the priors may be chosen on them, and the evaluation draws stay for
reporting. ``--max-events`` and ``--max-duration`` (minutes) cap the campaigns, which makes the
study affordable and the campaigns smaller than the family's (the page says so). The study
directory ``--out`` is resumable: rerunning it with the same options continues it.
"""

from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import csv  # noqa: E402
import math  # noqa: E402

import numpy as np  # noqa: E402

from vivbench.validate.methods import CampaignMethod  # noqa: E402
from vivbench.validate.study import StudyConfig, parse_draws, run_study  # noqa: E402

#: Variant name -> the prior it changes and its value (the stated values: ``vivbench.analysis.VARYING_PRIORS``
#: and ``ModelSelection``'s perturbation time scale).
VARIANTS = {
    "smoothing_15s": ("wind_smoothing_s", 15.0),
    "smoothing_60s": ("wind_smoothing_s", 60.0),
    "perturbation_30s": ("perturbation_timescale_s", 30.0),
    "perturbation_120s": ("perturbation_timescale_s", 120.0),
    "weights_equal": ("wind_weights", "equal"),
    "smoothing_chosen": ("options", {"yaw_degree": (0, 1, 2), "penalty_choice": ("cv", "least"),
                                     "wind_smoothing_s": (15.0, 30.0, 60.0)}),
    "smoothing_cv": ("wind_smoothing_grid", (15.0, 30.0, 60.0)),
    "input_chosen": ("options", {"yaw_degree": (0, 1, 2), "penalty_choice": ("cv", "least"),
                                 "wind_input": ("mean", "sum")}),
    "input_sum": ("wind_input", "sum"),
}
#: Study method names of the variants: this prefix and the variant's name.
METHOD_PREFIX = "benchmarks.study_priors:"
#: Fewest flags for a draw to test the promise, and the promise itself.
MIN_FLAGS, PROMISE = 20, 0.95


def _factory(name: str):
    key, value = VARIANTS[name]

    def make():
        return CampaignMethod("varying", **{key: value})

    make.__name__ = name
    make.__doc__ = f"The ``varying`` study method with {key} = {value!r} (the other priors as stated)."
    return make


for _name in VARIANTS:
    globals()[_name] = _factory(_name)


def _num(text: str) -> float:
    try:
        return float(text)
    except ValueError:
        return float("nan")


def summarise(rows: list[dict]) -> list[dict]:
    """One row per variant (``stated`` first): the scores' spread over draws and the pairing with ``stated``."""
    by = {}
    for r in rows:
        by.setdefault(r["variant"], {})[r["draw"]] = r
    base = by.get("stated", {})
    out = []
    for name in ["stated", *VARIANTS]:
        got = by.get(name)
        if not got:
            continue
        err = np.array([r["dA_error_energy"] for r in got.values()], dtype=float)
        err = err[np.isfinite(err)]
        tested = [r for r in got.values() if r["n_flagged"] >= MIN_FLAGS]
        kept = [r for r in tested if r["flagged_right_share"] >= PROMISE]
        ratios = np.array([got[d]["dA_error_energy"] / base[d]["dA_error_energy"] for d in got if d in base
                           and base[d]["dA_error_energy"] > 0], dtype=float)
        ratios = ratios[np.isfinite(ratios)]
        cov = np.array([r["coverage"] for r in got.values()], dtype=float)
        out.append({
            "variant": name, "prior": "" if name == "stated" else VARIANTS[name][0],
            "value": "" if name == "stated" else str(VARIANTS[name][1]), "draws": len(got),
            "error_median": float(np.median(err)) if err.size else math.nan,
            "error_p90": float(np.percentile(err, 90)) if err.size else math.nan,
            "error_worst": float(np.max(err)) if err.size else math.nan,
            "draws_with_enough_flags": len(tested), "promise_kept": len(kept),
            "worst_share_right": min((r["flagged_right_share"] for r in tested), default=math.nan),
            "coverage_median": float(np.nanmedian(cov)) if np.isfinite(cov).any() else math.nan,
            "ratio_to_stated_median": float(np.median(ratios)) if ratios.size and name != "stated" else math.nan,
            "within_10pct_of_stated": (float(np.mean(np.abs(ratios - 1.0) <= 0.10))
                                       if ratios.size and name != "stated" else math.nan),
        })
    return out


def findings(summary: list[dict]) -> list[str]:
    """Sentences generated from the summary."""
    said = []
    for s in summary:
        promise = (f"the promise kept on {s['promise_kept']} of {s['draws_with_enough_flags']} draws with at least "
                   f"{MIN_FLAGS} flags")
        if s["variant"] == "stated":
            said.append(f"Stated priors: energy-weighted dA/dt error median {s['error_median']:.3f}, "
                        f"90th percentile {s['error_p90']:.3f}, worst {s['error_worst']:.3f} over {s['draws']} draws; "
                        f"{promise}.")
        else:
            what = {"smoothing_chosen": "the smoothing chosen among the selection's candidates",
                    "smoothing_cv": "the smoothing chosen in each fit by cross-validation",
                    "input_chosen": "the wind input (mean or tied sum) chosen among the selection's candidates",
                    "input_sum": "the tied sum of every section's wind on every campaign"}.get(
                        s["variant"], f"{s['prior']} = {s['value']}")
            said.append(f"{what}: median error {s['error_median']:.3f} (median ratio to the "
                        f"stated prior's {s['ratio_to_stated_median']:.2f}, within 10 % of it on "
                        f"{s['within_10pct_of_stated']:.0%} of the draws); {promise}.")
    return said


def main(argv=None) -> dict:
    from _family_args import family_parser

    parser = family_parser(__doc__.splitlines()[0])
    parser.add_argument("--variants", default=",".join(VARIANTS),
                        help=f"comma-separated variants beside the stated priors (default all: {', '.join(VARIANTS)})")
    args = parser.parse_args(argv)
    chosen = [v.strip() for v in args.variants.split(",") if v.strip()]
    unknown = sorted(set(chosen) - set(VARIANTS))
    if unknown:
        parser.error(f"unknown variants {unknown}; allowed: {', '.join(VARIANTS)}")
    methods = {"varying": "stated", **{METHOD_PREFIX + name: name for name in chosen}}
    config = StudyConfig(split=args.split, draws=parse_draws(args.draws), methods=tuple(methods),
                         max_events=args.max_events,
                         max_duration=None if args.max_duration is None else args.max_duration * 60.0)
    result = run_study(config, args.out, workers=args.workers)
    with open(result.table, encoding="utf-8") as fh:
        table = list(csv.DictReader(fh))
    rows = []
    for row in table:
        n_flagged = int(float(row["n_flagged"])) if row["n_flagged"] not in ("", "nan") else 0
        rows.append({"draw": int(row["draw"]), "variant": methods[row["method"]], "n_sections": int(row["n_sections"]),
                     "eiv": row["eiv"], "yaw_effect": row["yaw_effect"], "n_events": int(row["n_events"]),
                     "chosen": row["chosen"], "n_flagged": n_flagged,
                     "flagged_right_share": _num(row["flagged_right_share"]), "coverage": _num(row["coverage"]),
                     "dA_error_energy": _num(row["rhs_error_true_AU_energy"]),
                     "curve_error_energy": _num(row["curve_error_energy"]), "error": row["error"]})
    summary = summarise([r for r in rows if not r["error"]])
    return {"findings": findings(summary), "split": args.split, "draws": list(config.draws),
            "max_events": args.max_events, "max_duration_min": args.max_duration,
            "failed_draws": sorted(result.failures), "draws_computed": list(result.computed),
            "draws_resumed": list(result.resumed), "summary": summary, "rows": rows}


if __name__ == "__main__":
    main()
