"""Study: the campaign models fitted on the identification's dA/dt against the campaign derivative's, over family draws.

Run::

    python benchmarks/run_study.py model_derivative --split development --draws 0-29 --out DIR \
        [--max-events N] [--max-duration 30] [--workers 2]

The window regressions of the identification differentiate each envelope with a smoothing total
variation whose weight is set for short windows (``vivbench.preprocess.Derivative()``, stored as the
result's ``dA``); ``vivbench pool`` recomputes dA/dt on every segment with
:data:`vivbench.analysis.CAMPAIGN_DERIVATIVE` (a lighter weight: nearly the unbiased finite
differences), on the argument that a campaign model averages the noise of tens of thousands of
samples but not a smoother's bias. This study measures that prior on draws of the generator family.

Every draw's campaign is generated with the caps and identified once; the records are read twice,
with either dA/dt (nothing else differs), and on each the default campaign model (``varying``: the
selection of ``vivbench pool``) and the binned baseline are fitted and scored against the truth:
the energy-weighted relative dA/dt error on the truth's own (A, U) and the curve error, the flagged
window-equations and how many carry the truth's regime, and the change scan's p-value (with the
draw's true step of damping, if any). The summary gives per derivative the median, 90th percentile
and worst error over the draws, on how many draws it is the lower one, the draws that keep the
verdict's promise (at least 95 % of at least 20 flags right), and the change scan's alarms on the
draws without a step and detections on those with one.

Development draws choose the prior; an evaluation run only reports. The study directory ``--out``
keeps each draw's campaign, identification and scores; rerunning with the same options continues it.
"""

from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import math  # noqa: E402

import numpy as np  # noqa: E402

from vivbench.validate.study_report import PROMISE_MIN_FLAGS, PROMISE_SHARE  # noqa: E402

#: The two derivatives compared: name -> ``derivative`` of :func:`vivbench.validate.scoring_inputs`
#: ("campaign": :data:`vivbench.analysis.CAMPAIGN_DERIVATIVE`, resolved in the worker).
DERIVATIVES = ("identification", "campaign")
#: The methods fitted on each.
METHODS = ("varying", "binned")


def _derivative(name: str):
    from vivbench.analysis import CAMPAIGN_DERIVATIVE

    return {"identification": None, "campaign": CAMPAIGN_DERIVATIVE}[name]


def score_draw(task: dict) -> dict:
    """One draw: generate (capped) and identify once; per derivative, fit and score every method."""
    from vivbench.models.protocol import model_evidence
    from vivbench.synth.family import draw_bridge
    from vivbench.validate.methods import fit_method, resolve_method, score_fitted, scoring_inputs

    from benchmarks._family_args import capped_draw, draw_files, store_row, stored_row

    done = stored_row(task)
    if done is not None:
        return done
    labels = draw_bridge(task["split"], task["draw"]).labels
    row = {"draw": task["draw"], "step_event": int(labels["step_event"]),
           "step_damping_factor": float(labels["step_damping_factor"]), "forced_only": bool(labels["forced_only"])}
    capped_draw(task)  # generated and identified once; the records read again with each derivative
    for deriv in DERIVATIVES:
        records, truths, windows = scoring_inputs(*draw_files(task), derivative=_derivative(deriv))
        row["n_events"] = len(records)
        for name in METHODS:
            fitted, seconds = fit_method(resolve_method(name), records)
            s = score_fitted(fitted, records, truths, windows=windows, simulate=False, fit_time_s=seconds)
            flagged = 0 if math.isnan(s["coverage"]) else int(round(s["coverage"] * s["n_scored"]))
            key = f"{name}_{deriv}"
            row.update({f"{key}_error": s["rhs_error_true_AU_energy"], f"{key}_curve_error": s["curve_error_energy"],
                        f"{key}_flags": flagged, f"{key}_right": s["accuracy_identifiable"],
                        f"{key}_fit_s": seconds})
            ev = model_evidence(fitted)
            if ev is not None:
                change = ev.get("change", {})
                row[f"{key}_chosen"] = str(ev["chosen"])
                row[f"{key}_change_p"] = float(change.get("p_value", math.nan))
                row[f"{key}_change_event"] = str(change.get("event", "")) if change.get("detected") else ""
    return store_row(task, row)


def summarise(rows: list[dict]) -> list[dict]:
    """One row per method and derivative: errors over the draws, draws where it is lower, promise, change scan."""
    from _family_args import spread

    out = []
    for name in METHODS:
        for deriv in DERIVATIVES:
            key, other = f"{name}_{deriv}", f"{name}_{[d for d in DERIVATIVES if d != deriv][0]}"
            err, cerr = spread(r[f"{key}_error"] for r in rows), spread(r[f"{key}_curve_error"] for r in rows)
            both = [r for r in rows if np.isfinite(r[f"{key}_error"]) and np.isfinite(r[f"{other}_error"])]
            entry = {"method": name, "derivative": deriv, "draws": len(rows),
                     "error_median": err["median"], "error_p90": err["p90"], "error_worst": err["worst"],
                     "curve_error_median": cerr["median"], "curve_error_p90": cerr["p90"],
                     "curve_error_worst": cerr["worst"],
                     "lower_error_draws": int(sum(r[f"{key}_error"] < r[f"{other}_error"] for r in both)),
                     "compared_draws": len(both)}
            tested = [r for r in rows if r[f"{key}_flags"] >= PROMISE_MIN_FLAGS]
            shares = [r[f"{key}_right"] for r in tested]
            entry.update(flags=int(sum(r[f"{key}_flags"] for r in rows)), promise_draws=len(tested),
                         promise_kept=int(sum(s >= PROMISE_SHARE for s in shares)),
                         worst_share_right=min(shares, default=math.nan))
            if f"{key}_change_p" in rows[0]:
                calm = [r for r in rows if r["step_event"] == 0]
                step = [r for r in rows if r["step_event"] > 0]
                entry.update(draws_without_step=len(calm),
                             false_alarms=int(sum(r[f"{key}_change_event"] != "" for r in calm)),
                             draws_with_step=len(step),
                             steps_detected=int(sum(r[f"{key}_change_event"] != "" for r in step)))
            out.append(entry)
    return out


def findings(summary: list[dict]) -> list[str]:
    """Sentences generated from the figures."""
    said = []
    for s in summary:
        text = (f"{s['method']} on the {s['derivative']} dA/dt: energy-weighted dA/dt error median "
                f"{s['error_median']:.3f}, p90 {s['error_p90']:.3f}, worst {s['error_worst']:.3f}; curves median "
                f"{s['curve_error_median']:.3f}; the lower error on {s['lower_error_draws']} of {s['compared_draws']} "
                f"draws; {s['flags']} flags, the promise kept on {s['promise_kept']} of {s['promise_draws']} draws "
                f"with at least {PROMISE_MIN_FLAGS} (worst {s['worst_share_right']:.3f} right)")
        if "false_alarms" in s:
            text += (f"; the change scan alarms on {s['false_alarms']} of {s['draws_without_step']} draws without a "
                     f"step and detects {s['steps_detected']} of {s['draws_with_step']} steps")
        said.append(text + ".")
    return said


def main(argv=None) -> dict:
    from _family_args import family_study

    return family_study("study_model_derivative", __doc__.splitlines()[0], argv, summarise, findings,
                        max_duration=30.0)


if __name__ == "__main__":
    main()
