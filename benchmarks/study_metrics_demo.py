"""Study: median-over-windows against energy-weighted errors, and the binned baseline, on a finished campaign.

Run (from the repository root, after ``make demo`` or on any synthetic campaign with its identification)::

    python benchmarks/study_metrics_demo.py --campaign demo/campaign --results demo/identify \\
        [--methods binned,pooled,varying] [--out benchmarks/out/study_metrics_demo]

Each method (a spec of :func:`vivbench.validate.resolve_method`) is fitted on
the identification's records, dA/dt recomputed by the campaign model's
derivative (:data:`vivbench.analysis.CAMPAIGN_DERIVATIVE`, as ``vivbench pool``
does), and scored by :func:`vivbench.validate.score_fitted` on the
identification's windows. The table gives, per method, the dA/dt error on the
true (A, U) as the median over active windows and energy-weighted over every
sample, the coefficient curves' errors (a_k1 and dA/dt over the self-excited
samples of the reference section, and energy-weighted over every sample
against the truth's curves, all inside the data's wind range), coverage,
accuracy of flagged windows and the fit time. One more column scores the
curves' dA/dt against the truth's dA/dt itself (energy-weighted, every sample):
it also charges the curves with what no curve of one wind can carry (sections
at different winds, the yaw); the truth's own curves' figure by that measure is
printed under the table as its floor. Writes ``<out>.md`` (the table) and
``<out>.json`` (every score).
"""

from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import json  # noqa: E402
import math  # noqa: E402
import sys  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

from vivbench.analysis.pool import curve_wind_grid  # noqa: E402
from vivbench.models import data_wind_range  # noqa: E402
from vivbench.validate.campaign import event_truth_curves  # noqa: E402
from vivbench.validate.metrics import curve_energy_error  # noqa: E402
from vivbench.validate.methods import fit_method, resolve_method, score_fitted, scoring_inputs  # noqa: E402

#: (score key, column heading) of the table.
COLUMNS = (
    ("rhs_error_true_AU_median_active", "dA/dt error, median over active windows"),
    ("rhs_error_true_AU_energy", "dA/dt error, energy-weighted"),
    ("curve_error_linear", "a_k1 curve error"),
    ("curve_error_total", "curve dA/dt error, self-excited samples"),
    ("curve_error_energy", "curve dA/dt error, energy-weighted"),
    ("curve_error_energy_vs_dadt", "same against the truth's dA/dt"),
    ("coverage", "coverage"),
    ("accuracy_identifiable", "accuracy flagged"),
    ("fit_time_s", "fit (s)"),
)


def _fmt(x) -> str:
    return "-" if x is None or (isinstance(x, float) and not math.isfinite(x)) else f"{x:.3f}"


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--campaign", type=Path, required=True, help="directory of the events (<event_id>.nc, with /truth)")
    ap.add_argument("--results", type=Path, required=True, help="directory of their <event_id>.identify.nc")
    ap.add_argument("--methods", default="binned,pooled,varying", help="comma-separated method specs")
    ap.add_argument("--out", type=Path, default=Path("benchmarks/out/study_metrics_demo"),
                    help="output stem: <out>.md and <out>.json")
    args = ap.parse_args(argv)
    results = sorted(args.results.glob("*.identify.nc"))
    events = [args.campaign / (p.name.removesuffix(".identify.nc") + ".nc") for p in results]
    if not results:
        raise SystemExit(f"{args.results}: no <event_id>.identify.nc")
    records, truths, windows = scoring_inputs(events, results)
    U = np.concatenate([tr["U"].values for tr in truths])
    A = np.concatenate([tr["A"].values for tr in truths])
    dA = np.concatenate([np.asarray(tr["r"].values, dtype=float).sum(axis=-1) for tr in truths])
    wind_range = data_wind_range(records)
    grid = curve_wind_grid(np.concatenate([r.U.ravel() for r in records]))

    def vs_dadt(curves, wind) -> float:
        return curve_energy_error(curves, wind, U, A, dA, wind_range)

    truth_curves = event_truth_curves(truths[0])
    floor = math.nan if truth_curves is None else vs_dadt(*truth_curves)
    scores = {}
    for spec in [m.strip() for m in args.methods.split(",") if m.strip()]:
        fitted, seconds = fit_method(resolve_method(spec), records)
        scores[spec] = score_fitted(fitted, records, truths, windows=windows, fit_time_s=seconds, simulate=False)
        has_curves = callable(getattr(fitted, "curves", None))
        scores[spec]["curve_error_energy_vs_dadt"] = (vs_dadt(fitted.curves(grid)["curves"].values, grid)
                                                      if has_curves else math.nan)
        print(f"{spec}: " + ", ".join(f"{k} {_fmt(scores[spec][k])}" for k, _h in COLUMNS), file=sys.stderr)
    lines = [f"Campaign {args.campaign} ({len(records)} events), identification {args.results}; dA/dt by the "
             "campaign derivative; errors on the true (A, U), curves only inside the data's wind range.", "",
             "| method | " + " | ".join(h for _k, h in COLUMNS) + " |",
             "|---|" + "---|" * len(COLUMNS)]
    lines += [f"| {spec} | " + " | ".join(_fmt(s[k]) for k, _h in COLUMNS) + " |" for spec, s in scores.items()]
    lines += ["", f"The truth's own curves against its dA/dt, energy-weighted by the same measure: {_fmt(floor)}."]
    scores["truth_curves_vs_dadt"] = floor
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.with_suffix(".md").write_text("\n".join(lines) + "\n")
    args.out.with_suffix(".json").write_text(json.dumps(scores, indent=2, default=float) + "\n")
    print("\n".join(lines))
    print(f"wrote {args.out.with_suffix('.md')} and {args.out.with_suffix('.json')}", file=sys.stderr)
    return scores


if __name__ == "__main__":
    main()
