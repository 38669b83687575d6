"""Study: which candidate the held-out evidence should choose, the simplest of the confidence set or another rule.

Run::

    python benchmarks/run_study.py selection_rule --split development --draws 0-29 --out DIR \
        [--max-events N] [--max-duration 30] [--workers 2]

The default campaign model (:func:`vivbench.analysis.varying_selection`, as ``vivbench pool`` fits it)
scores every candidate (yaw degree, penalty choice) by the output error of whole held-out events
and reports the **simplest** member of the confidence set: the candidates whose summed held-out
loss is within one standard error of the best's and whose per-event losses are not above the
best's more consistently than a signed-rank test allows (:func:`vivbench.analysis.confidence_set`).
With few events a single event whose simulation one candidate gets badly wrong dominates both the
sum and its standard error, and the simplest candidate then stays in the set even where it loses
by a factor of several on the total.

Every draw's campaign is generated with the caps and identified once; the default selection is
fitted on the records ``vivbench pool`` fits, and every candidate it scored is refitted to every
event and scored against the truth (the energy-weighted relative dA/dt error on the truth's own
(A, U) and the curve error). The study then asks which candidate each rule picks from the same
held-out losses (only the candidates the default's forward search scored take part):

- ``simplest``: the default (the simplest member of the confidence set);
- ``lowest``: the candidate of the lowest summed held-out loss;
- ``normalised``: the simplest member of the confidence set computed on per-event losses divided by
  that event's mean loss over the scored candidates, so that every event weighs alike in the sum
  and its standard error (scale-free; one event cannot outweigh the others by its energy).

Beside the rules, ``oracle`` is the scored candidate of the lowest error against the truth: what
no rule can exceed with these candidates, and no user can pick. Per rule the page gives the error
of the candidate it picks (median, 90th percentile, worst over the draws), the median paired ratio to the default's, the draws better or worse by more than 10 %,
how often the yaw covariate is picked on the draws where the yaw matters (the truth's factor on Y1
ranges by :data:`vivbench.validate.study_report.YAW_MATTERS` or more over the campaign's yaws) and
where it does not, and on the latter the curve error against the yaw-free candidate of the same
penalty. No rule is a default because of this page: development draws choose, an evaluation run
only reports. The study directory ``--out`` keeps each draw's campaign, identification and scores;
rerunning with the same options continues it.
"""

from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import copy  # noqa: E402
import math  # noqa: E402

import numpy as np  # noqa: E402

#: The rules compared, the default first.
RULES = ("simplest", "lowest", "normalised")
#: Beside the rules: the scored candidate of the lowest error against the truth, which no user can pick.
ORACLE = "oracle"


def rule_choices(losses: np.ndarray, complexity: np.ndarray, scored: np.ndarray) -> dict[str, int]:
    """The candidate each rule picks from the held-out losses.

    Parameters
    ----------
    losses : ndarray, shape (C, E), held-out loss of every candidate on every event (NaN where not scored)
    complexity : ndarray of int, shape (C,)
    scored : ndarray of bool, shape (C,), the candidates with losses

    Returns
    -------
    dict: rule name -> index of the candidate it picks (``simplest`` recomputed from the losses)
    """
    from vivbench.analysis.held_out import confidence_set

    idx = np.flatnonzero(scored)
    L = np.asarray(losses, dtype=float)[idx]
    comp = np.asarray(complexity)[idx]

    def simplest(loss):
        in_set = confidence_set(loss)[0]
        members = np.flatnonzero(in_set)
        total = loss.sum(axis=1)
        return int(idx[min(members, key=lambda m: (comp[m], total[m]))])

    scale = L.mean(axis=0)
    scale = np.where(scale > 0, scale, 1.0)
    return {"simplest": simplest(L), "lowest": int(idx[int(np.argmin(L.sum(axis=1)))]),
            "normalised": simplest(L / scale)}


def _yaw_free_twin(names: list[str], name: str) -> str | None:
    """The yaw-free candidate of the same options as ``name`` (``yaw1-cv`` -> ``yaw0-cv``), or None."""
    if not name.startswith("yaw") or name.startswith("yaw0") or "-" not in name:
        return None
    twin = "yaw0" + name[name.index("-"):]
    return twin if twin in names else None


def _pick(rule: str, name: str, cand: dict) -> dict:
    """The row's fields of ``rule`` picking candidate ``name`` (``cand``: name -> its scores against the truth)."""
    twin = _yaw_free_twin(list(cand), name)
    return {f"chosen_{rule}": name, f"error_{rule}": cand[name]["error"],
            f"curve_error_{rule}": cand[name]["curve_error"], f"yaw_{rule}": int(not name.startswith("yaw0")),
            f"curve_error_yaw_free_{rule}": cand[(twin or name)]["curve_error"]}


def score_draw(task: dict) -> dict:
    """One draw: the default selection, every scored candidate refitted and scored, the rules' picks."""
    from vivbench.validate.methods import CampaignMethod, score_fitted
    from vivbench.validate.study import yaw_factor_range

    from benchmarks._family_args import draw_inputs, labelled_row, store_row, stored_row

    done = stored_row(task)
    if done is not None:
        return done
    labels, row = labelled_row(task)
    records, truths, windows = draw_inputs(task)
    row.update(n_events=len(records), yaw_effect=str(labels["yaw_effect"]),
               yaw_factor_range=float(yaw_factor_range(records, truths)))
    selection = CampaignMethod("varying").fit(records).model
    names = list(selection.names_)
    scored = np.asarray(selection.scored_, dtype=bool)
    complexity = np.array([c.complexity for c in selection.candidates])
    cand = {}
    for i in np.flatnonzero(scored):
        model = copy.deepcopy(selection.candidates[i].model).fit(records)
        s = score_fitted(model, records, truths, windows=windows, simulate=False)
        cand[names[i]] = {"error": float(s["rhs_error_true_AU_energy"]),
                          "curve_error": float(s["curve_error_energy"]),
                          "held_out_loss": float(np.sum(selection.losses_[i]))}
    picks = rule_choices(selection.losses_, complexity, scored)
    row.update(default=str(selection.chosen_), candidates=cand,
               simplest_is_default=int(names[picks["simplest"]] == selection.chosen_))
    for rule, i in picks.items():
        row.update(_pick(rule, names[i], cand))
    return store_row(task, row)


def _with_oracle(row: dict) -> dict:
    """The row with the oracle's pick (the scored candidate of the lowest error against the truth) beside the
    rules'."""
    cand = row["candidates"]
    name = min(cand, key=lambda k: (cand[k]["error"] if math.isfinite(cand[k]["error"]) else math.inf, k))
    return {**row, **_pick(ORACLE, name, cand)}


def summarise(rows: list[dict]) -> list[dict]:
    """One row per rule and group of draws (all, yaw matters, yaw does not matter): errors, pairing, yaw picked."""
    from _family_args import paired, spread

    from vivbench.validate.study_report import YAW_MATTERS

    rows = [_with_oracle(r) for r in rows]
    groups = [("all", rows),
              ("yaw matters", [r for r in rows if r["yaw_factor_range"] >= YAW_MATTERS]),
              ("yaw does not matter", [r for r in rows if not r["yaw_factor_range"] >= YAW_MATTERS])]
    out = []
    for group, sub in groups:
        for rule in (*RULES, ORACLE):
            err = spread(r[f"error_{rule}"] for r in sub)
            cerr = spread(r[f"curve_error_{rule}"] for r in sub)
            pair = paired(sub, f"error_{rule}", "error_simplest")
            # curves within 10 % of the yaw-free candidate's (where it has curves)
            near = [r for r in sub if math.isfinite(r[f"curve_error_{rule}"])
                    and math.isfinite(r[f"curve_error_yaw_free_{rule}"])]
            within = sum(1 for r in near if r[f"curve_error_{rule}"] <= 1.1 * r[f"curve_error_yaw_free_{rule}"])
            out.append({"rule": rule, "draws_of": group, "draws": len(sub), "error_median": err["median"],
                        "error_p90": err["p90"], "error_worst": err["worst"], "curve_error_median": cerr["median"],
                        "curve_error_p90": cerr["p90"], "ratio_to_simplest_median": pair["ratio_median"],
                        "better_by_10pct": pair["better_by_10pct"], "worse_by_10pct": pair["worse_by_10pct"],
                        "yaw_picked": int(sum(r[f"yaw_{rule}"] for r in sub)),
                        "curves_within_10pct_of_yaw_free": within, "curves_compared": len(near)})
            if rule == "simplest":
                # the rule recomputed from the stored losses picks what the selection itself chose
                out[-1]["same_as_selection"] = int(sum(r.get("simplest_is_default", 0) for r in sub))
    return out


def findings(summary: list[dict]) -> list[str]:
    """Sentences generated from the figures."""
    said = []
    for s in summary:
        text = (f"{s['rule']}, {s['draws_of']} ({s['draws']} draws): energy-weighted dA/dt error median "
                f"{s['error_median']:.3f}, p90 {s['error_p90']:.3f}, worst {s['error_worst']:.3f}; curves median "
                f"{s['curve_error_median']:.3f}; the yaw picked on {s['yaw_picked']}")
        if s["rule"] == "simplest":
            text += f"; the selection's own choice on {s['same_as_selection']} of {s['draws']}"
        else:
            text += (f"; paired with the default: median ratio {s['ratio_to_simplest_median']:.2f}, better by more "
                     f"than 10 % on {s['better_by_10pct']} draws and worse on {s['worse_by_10pct']}")
        if s["draws_of"] == "yaw does not matter":
            text += (f"; curves within 10 % of the yaw-free candidate's on {s['curves_within_10pct_of_yaw_free']} "
                     f"of {s['curves_compared']}")
        said.append(text + ".")
    return said


def main(argv=None) -> dict:
    from _family_args import family_study

    return family_study("study_selection_rule", __doc__.splitlines()[0], argv, summarise, findings, max_duration=30.0)


if __name__ == "__main__":
    main()
