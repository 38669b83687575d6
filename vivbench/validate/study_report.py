"""Summary and results page of a study over the generator family (:mod:`vivbench.validate.study`).

Per method, the distribution over the study's campaigns (draws) of each score: the number of
draws with a finite value, the median, the 10th and 90th percentiles (linear interpolation),
and the worst campaign with its draw number (the largest error; the smallest share of right
flags, coverage or accuracy). Beside it, the share of campaigns that keep the verdict's promise
(at least :data:`PROMISE_SHARE` of the flagged window-equations right, on draws with at least
:data:`PROMISE_MIN_FLAGS` flags) and the self-excited flags on forced-only draws. Everything
is given for all draws and split by whether the drawn bridge's aerodynamics depend on yaw.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

__all__ = ["LABEL_COLUMNS", "PROMISE_SHARE", "PROMISE_MIN_FLAGS", "SUMMARY_SCORES", "study_summary", "study_markdown"]

#: Draw labels written in every row of ``study.csv`` (see :func:`vivbench.synth.family.draw_bridge`).
LABEL_COLUMNS = ("forced_only", "yaw_effect", "yaw_course", "eiv", "bell", "e_mix", "n_sections", "frequency_hz",
                 "depth_m", "damping_ratio", "lock_in_m_s", "point_intensity", "point_timescale_s", "change",
                 "step_event", "step_damping_factor")
#: A yaw effect "matters" on a campaign when the truth's factor on Y1 ranges by at least this much over the
#: campaign's measured yaws (5th-95th percentile; :func:`vivbench.validate.study.yaw_factor_range`): a reporting cut.
YAW_MATTERS = 0.2
#: Where the yaw does not matter, the chosen model's curves count as good as its yaw-free counterpart's when their
#: energy-weighted error is at most this factor times the counterpart's (issue's cut: within 10 %).
YAW_FREE_MARGIN = 1.1
#: The verdict's promise: at least this share of flagged window-equations right ...
PROMISE_SHARE = 0.95
#: ... on every draw with at least this many flagged window-equations.
PROMISE_MIN_FLAGS = 20
#: Scores summarised over draws, each with the direction in which it gets worse.
SUMMARY_SCORES = (("rhs_error_true_AU_energy", "high"), ("rhs_error_true_AU_median_active", "high"),
                  ("curve_error_energy", "high"), ("curve_error_total", "high"), ("curve_error_linear", "high"),
                  ("flagged_right_share", "low"),
                  ("coverage", "low"), ("accuracy_all", "low"))
_SUBSETS = (("all", None), ("yaw_present", True), ("yaw_absent", False))
_LABELS = {"rhs_error_true_AU_energy": "dA/dt error on the true (A, U), energy-weighted",
           "rhs_error_true_AU_median_active": "dA/dt error on the true (A, U), median over active windows",
           "curve_error_energy": "curve error, energy-weighted", "curve_error_total": "curve error (total)", "curve_error_linear": "curve error (linear order)",
           "flagged_right_share": "share of flags right", "coverage": "coverage (share flagged)",
           "accuracy_all": "regime accuracy, all windows"}


_GREYBOX_NOTE = ("- greybox: the grey-box refit given each draw's structural properties (modal mass, deck depth, "
                 "frequency, structural damping before any step, mode shape, tributary lengths; never the "
                 "aerodynamics), warm-started from the varying model, whose regime its flags must also carry. Its "
                 "30 s wind smoothing, penalty grid and verdict settings were chosen on the default campaign, not on "
                 "the family.")
_TRUTH_WIND_NOTE = ("- **Oracle wind (`--wind-source truth`)**: every method was fitted, and its verdict read, on "
                    "records whose wind (and yaw, where the truth stores it) is the truth's own, not the "
                    "anemometers'. No user has this wind: the "
                    "figures bound what the methods reach without errors in the wind; compare them with the "
                    "same draws on the measured wind.")
_TRUTH_AMPLITUDE_NOTE = ("- **Oracle amplitude (`--amplitude-source truth`)**: every method was fitted, and its "
                         "verdict read, on records whose amplitude and dA/dt are the truth's averaged ones, not the "
                         "measured envelopes. No user has them: with the oracle wind as well, the figures are those "
                         "of the methods' model classes alone.")


#: Campaigns with fewer events than this are summarised apart on the page (a reporting split, not a setting).
SMALL_CAMPAIGN_EVENTS = 10


def _number(value) -> float:
    try:
        return float(value)
    except (TypeError, ValueError):
        return math.nan


def _plain(x: float) -> float | None:
    return None if x is None or not math.isfinite(x) else float(x)


def _distribution(rows: Sequence[dict], key: str, worse: str) -> dict[str, Any]:
    values = np.array([_number(r.get(key)) for r in rows])
    ok = np.isfinite(values)
    if not ok.any():
        return {"n": 0, "median": None, "p10": None, "p90": None, "worst": None, "worst_draw": None}
    v = values[ok]
    draws = [r["draw"] for r, good in zip(rows, ok) if good]
    k = int(np.argmax(v) if worse == "high" else np.argmin(v))
    return {"n": int(ok.sum()), "median": float(np.median(v)), "p10": float(np.percentile(v, 10)),
            "p90": float(np.percentile(v, 90)), "worst": float(v[k]), "worst_draw": int(draws[k])}


def _promise(rows: Sequence[dict]) -> dict[str, Any]:
    enough = [r for r in rows if _number(r.get("n_flagged")) >= PROMISE_MIN_FLAGS]
    right = [_number(r.get("flagged_right_share")) for r in enough]
    kept = sum(1 for x in right if x >= PROMISE_SHARE)
    worst = int(np.argmin(right)) if enough else None
    return {"draws_with_enough_flags": len(enough), "draws_kept": kept,
            "share_kept": _plain(kept / len(enough)) if enough else None,
            "worst_flagged_right_share": None if worst is None else _plain(right[worst]),
            "worst_draw": None if worst is None else int(enough[worst]["draw"])}


def _forced(rows: Sequence[dict]) -> dict[str, Any]:
    forced = [r for r in rows if str(r.get("forced_only")) == "True"]
    flags = [_number(r.get("self_excited_flags")) for r in forced]
    return {"draws": len(forced), "self_excited_flags": int(np.nansum(flags)) if forced else 0,
            "draws_with_self_excited_flags": int(sum(1 for f in flags if f > 0))}


def _choices(rows: Sequence[dict]) -> dict[str, Any]:
    """How often a model that chooses from the campaign's evidence took a yaw covariate (``chosen`` "yawN-...")."""
    chosen = [r for r in rows if str(r.get("chosen") or "").startswith("yaw")]
    with_yaw = [r for r in chosen if not str(r["chosen"]).startswith("yaw0")]
    out = {"draws": len(chosen), "yaw_chosen": len(with_yaw)}
    # By the yaw's course: varying between events (the yaw can be told from the time within an event) or the
    # same course in every event (confounded with it; the selection should leave the yaw out and widen the bands).
    for course in ("per_event", "shared"):
        out[f"{course}_draws"] = sum(1 for r in chosen if r.get("yaw_course") == course)
        out[f"{course}_yaw_chosen"] = sum(1 for r in with_yaw if r.get("yaw_course") == course)
    # Where the yaw matters over the campaign's own yaws (the truth's factor on Y1 ranges by YAW_MATTERS or more).
    matters = [r for r in chosen if _number(r.get("yaw_factor_range")) >= YAW_MATTERS]
    out["matters_draws"] = len(matters)
    out["matters_yaw_chosen"] = sum(1 for r in matters if not str(r["chosen"]).startswith("yaw0"))
    # ... and where a yaw model is at least in the confidence set (not significantly worse than the best)
    out["matters_yaw_in_set"] = sum(1 for r in matters if any(
        m.startswith("yaw") and not m.startswith("yaw0") for m in str(r.get("confidence_set") or "").split(";")))
    # Where it does not matter: the chosen model's curves against those of the same options without the yaw.
    minor = [r for r in chosen if _number(r.get("yaw_factor_range")) < YAW_MATTERS]
    out["minor_draws"] = len(minor)
    out["minor_yaw_chosen"] = sum(1 for r in minor if not str(r["chosen"]).startswith("yaw0"))
    pairs = [(_number(r.get("curve_error_energy")), _number(r.get("curve_error_energy_yaw_free"))) for r in minor]
    pairs = [(own, free) for own, free in pairs if math.isfinite(own) and math.isfinite(free)]
    out["minor_curves_compared"] = len(pairs)
    out["minor_curves_within"] = sum(1 for own, free in pairs if own <= YAW_FREE_MARGIN * free)
    return out


def _within(choices: dict) -> str:
    """"k of n" draws whose curves are within the margin of the yaw-free model's; "n/a" when none was compared."""
    n = choices.get("minor_curves_compared", 0)
    return f"{choices.get('minor_curves_within', 0)} of {n}" if n else "n/a"


def _recorded(row: dict, key: str) -> bool:
    """Whether a method recorded ``key`` for the draw (an evidence column left empty by methods without one)."""
    return str(row.get(key, "")).strip() not in ("", "nan")


def _shown(row: dict) -> bool:
    """The null test let the verdict flag (``dynamics_shown`` 1)."""
    return bool(int(_number(row["dynamics_shown"])))


def _changed(row: dict) -> bool:
    """The chosen model's change scan located a change (``stationary`` 0), which withholds every flag."""
    return _recorded(row, "stationary") and not int(_number(row["stationary"]))


def _withheld(rows: Sequence[dict]) -> dict[str, Any]:
    """Draws on which the campaign's held-out evidence did not show its dynamics (``dynamics_shown`` 0):
    the null model predicted held-out events as well, and no window was flagged; and the draws whose
    dynamics were shown but whose chosen model's change scan located a change."""
    tested = [r for r in rows if _recorded(r, "dynamics_shown")]
    withheld = [r for r in tested if not _shown(r)]
    return {"draws": len(tested), "withheld": len(withheld),
            "withheld_for_change": sum(1 for r in tested if _shown(r) and _changed(r)),
            "forced_only_withheld": sum(1 for r in withheld if str(r.get("forced_only")) == "True"),
            "forced_only": sum(1 for r in tested if str(r.get("forced_only")) == "True")}


def _changes(rows: Sequence[dict]) -> dict[str, Any]:
    """The change scan's alarms on draws without a change, and its detections of the damping steps.

    A step is located when the first event after the scan's split is within one event of the first
    event with the step (``step_event``, counted from 1).
    """
    scanned = [r for r in rows if math.isfinite(_number(r.get("change_p_value")))]
    none = [r for r in scanned if r.get("change") == "none"]
    steps = [r for r in scanned if r.get("change") not in (None, "", "none")]
    found = [r for r in steps if int(_number(r.get("change_detected")) or 0)]
    located = [r for r in found
               if abs(int(_number(r.get("change_index"))) - (int(_number(r.get("step_event"))) - 1)) <= 1]
    return {"draws_without_change": len(none),
            "false_alarms": sum(1 for r in none if int(_number(r.get("change_detected")) or 0)),
            "draws_with_step": len(steps), "detected": len(found), "located_within_one_event": len(located)}


def _block(rows: Sequence[dict]) -> dict[str, Any]:
    return {"n_draws": len(rows), "method_errors": sum(1 for r in rows if r.get("error")),
            "scores": {key: _distribution(rows, key, worse) for key, worse in SUMMARY_SCORES},
            "promise": _promise(rows), "forced_only": _forced(rows), "choices": _choices(rows),
            "changes": _changes(rows), "withheld": _withheld(rows),
            "by_size": {label: {"n_draws": len(sub),
                                "energy_error_median": _distribution(sub, "rhs_error_true_AU_energy", "high")["median"],
                                "promise": _promise(sub)}
                        for label, sub in _by_size(rows)},
            "by_evidence": {label: {"n_draws": len(sub),
                                    "energy_error": _distribution(sub, "rhs_error_true_AU_energy", "high")}
                            for label, sub in _by_evidence(rows)}}


def _by_evidence(rows: Sequence[dict]) -> list[tuple[str, list[dict]]]:
    """The rows whose own held-out evidence let the verdict flag (dynamics shown, no change located) and the
    rows where it withheld the regimes; empty for a method that records no such evidence."""
    tested = [r for r in rows if _recorded(r, "dynamics_shown")]
    if not tested:
        return []
    allowed = [_shown(r) and not _changed(r) for r in tested]
    return [("dynamics shown, one model for the campaign", [r for r, a in zip(tested, allowed) if a]),
            ("regimes withheld", [r for r, a in zip(tested, allowed) if not a])]


def _by_size(rows: Sequence[dict]) -> list[tuple[str, list[dict]]]:
    """The rows of small campaigns (fewer than :data:`SMALL_CAMPAIGN_EVENTS` events) and of the others."""
    small = [r for r in rows if _number(r.get("n_events")) < SMALL_CAMPAIGN_EVENTS]
    large = [r for r in rows if _number(r.get("n_events")) >= SMALL_CAMPAIGN_EVENTS]
    return [(f"fewer than {SMALL_CAMPAIGN_EVENTS} events", small), (f"{SMALL_CAMPAIGN_EVENTS} events or more", large)]


def _versus(rows: Sequence[dict], methods: Sequence[str], key: str = "rhs_error_true_AU_energy") -> dict[str, Any]:
    """For every ordered pair of methods, on how many draws (with both scores) the first's error is the lower."""
    by = {(int(r["draw"]), r["method"]): _number(r.get(key)) for r in rows}
    draws = sorted({int(r["draw"]) for r in rows})
    out: dict[str, Any] = {}
    for a in methods:
        for b in methods:
            if a == b:
                continue
            both = [d for d in draws if math.isfinite(by.get((d, a), math.nan)) and math.isfinite(by.get((d, b), math.nan))]
            better = sum(1 for d in both if by[(d, a)] < by[(d, b)])
            out[f"{a} vs {b}"] = {"draws": len(both), "lower": better,
                                  "share_lower": _plain(better / len(both)) if both else None}
    return out


def study_summary(config: dict[str, Any], rows: Sequence[dict], *, failed: Sequence[int] = ()) -> dict[str, Any]:
    """The summary of a study (``summary.json``), from its table rows.

    Parameters
    ----------
    config : the study's :meth:`~vivbench.validate.study.StudyConfig.to_dict`
    rows : ``study.csv``'s rows as dicts (one per draw and method)
    failed : draws whose task failed in this run (not scored)

    Returns
    -------
    dict, JSON-ready (no NaN: missing values are None)
    """
    out: dict[str, Any] = {
        "study": config, "capped": config.get("max_events") is not None or config.get("max_duration_s") is not None,
        "promise": {"share": PROMISE_SHARE, "min_flags": PROMISE_MIN_FLAGS},
        "draws_scored": sorted({int(r["draw"]) for r in rows}), "draws_failed": [int(d) for d in failed],
        "methods": {},
    }
    for name in config["methods"]:
        mine = [r for r in rows if r["method"] == name]
        out["methods"][name] = {
            subset: _block([r for r in mine if want is None or (r.get("yaw_effect") != "absent") == want])
            for subset, want in _SUBSETS}
    out["versus"] = _versus(rows, config["methods"])
    return out


def _ranges(draws: Sequence[int]) -> str:
    if not draws:
        return "none"
    parts, start, prev = [], draws[0], draws[0]
    for d in list(draws[1:]) + [None]:
        if d is not None and d == prev + 1:
            prev = d
            continue
        parts.append(str(start) if start == prev else f"{start}-{prev}")
        if d is not None:
            start = prev = d
    return ", ".join(parts)


def _subset(subset: str, block: dict) -> str:
    return f"{subset.replace('_', ' ')} ({block['n_draws']})"


def _fmt(x, digits: int = 3) -> str:
    return "–" if x is None else f"{x:.{digits}f}"


def study_markdown(summary: dict[str, Any]) -> str:
    """The results page ``study.md`` of a study summary."""
    cfg = summary["study"]
    split = cfg["split"]
    lines = [f"# Study over the generator family: {split} draws", ""]
    if summary["capped"]:
        cap = []
        if cfg.get("max_events") is not None:
            cap.append(f"at most {cfg['max_events']} events")
        if cfg.get("max_duration_s") is not None:
            cap.append(f"events at most {cfg['max_duration_s'] / 60:g} min long")
        lines += [f"**Capped campaigns: {' and '.join(cap)} per draw (`--max-events`, `--max-duration`). These "
                  "campaigns are smaller than the family's draws: the figures below are not the family's.**", ""]
    role = ("evaluation draws: reported only, never used to choose anything" if split == "evaluation" else
            "development draws: any choice may be made on them, so their figures are not quoted as results")
    lines += [f"- Split: {split} ({role}).",
              f"- Draws requested: {_ranges(cfg['draws'])}; scored: {_ranges(summary['draws_scored'])}; "
              f"failed in this run: {_ranges(summary['draws_failed'])}.",
              f"- Methods: {', '.join(cfg['methods'])}.",
              *([f"- Anemometers at {', '.join(f'{x:g}' for x in cfg['anemometer_span'])} of the span length, "
                 f"the wind at each section taken from them by the {cfg['wind_rule']} rule (`--anemometers`); the "
                 "deck feels its own section's wind."] if cfg.get("anemometer_span") is not None else []),
              *([_TRUTH_WIND_NOTE] if cfg.get("wind_source") == "truth" else []),
              *([_TRUTH_AMPLITUDE_NOTE] if cfg.get("amplitude_source") == "truth" else []),
              *([_GREYBOX_NOTE] if "greybox" in cfg["methods"] else []),
              "- Errors are relative: the energy-weighted one is sqrt(sum of squared errors / sum of squared true "
              "dA/dt) over every sample of a campaign, on the truth's own (A, U).",
              f"- The verdict's promise: at least {PROMISE_SHARE:.0%} of the flagged window-equations carry the true "
              f"regime, on every draw with at least {PROMISE_MIN_FLAGS} flags.", ""]
    lines += ["## Scores over campaigns", "",
              "Median, 90th percentile (10th for shares, where low is bad) and worst campaign over the draws; "
              "n: draws with a value.", "",
              "| method | draws | score | n | median | p90 / p10 | worst (draw) |", "|---|---|---|---|---|---|---|"]
    for name, blocks in summary["methods"].items():
        for subset, block in blocks.items():
            for key, worse in SUMMARY_SCORES:
                d = block["scores"][key]
                tail = d["p90"] if worse == "high" else d["p10"]
                worst = "–" if d["worst"] is None else f"{d['worst']:.3f} ({d['worst_draw']})"
                lines.append(f"| {name} | {_subset(subset, block)} | {_LABELS[key]} | {d['n']} | "
                             f"{_fmt(d['median'])} | {_fmt(tail)} | {worst} |")
    lines += ["", "## The verdict's promise", "",
              "| method | draws | draws with enough flags | promise kept | share kept | worst share right (draw) |",
              "|---|---|---|---|---|---|"]
    for name, blocks in summary["methods"].items():
        for subset, block in blocks.items():
            p = block["promise"]
            worst = "–" if p["worst_draw"] is None else f"{p['worst_flagged_right_share']:.3f} ({p['worst_draw']})"
            lines.append(f"| {name} | {_subset(subset, block)} | {p['draws_with_enough_flags']} | "
                         f"{p['draws_kept']} | {_fmt(p['share_kept'])} | {worst} |")
    lines += ["", "## Forced-only draws", "",
              "Self-excited flags: flagged window-equations whose model regime is 2, 3 or 4 on a bridge whose "
              "aerodynamic negative damping never exceeds its structural damping.", "",
              "| method | draws | forced-only draws | self-excited flags | draws with any |", "|---|---|---|---|---|"]
    for name, blocks in summary["methods"].items():
        for subset, block in blocks.items():
            f = block["forced_only"]
            lines.append(f"| {name} | {_subset(subset, block)} | {f['draws']} | {f['self_excited_flags']} | "
                         f"{f['draws_with_self_excited_flags']} |")
    lines += ["", "## Regimes withheld for want of evidence", "",
              "Withheld: draws on which the dynamic models did not predict held-out events significantly better "
              "than the quasi-steady map A = g(U) (or the campaign had too few events to tell). Withheld for a "
              "change: draws whose dynamics were shown but whose chosen model's change scan located a change (one "
              "model does not hold for the whole campaign). No window is flagged on either.",
              "", "| method | draws | draws tested | withheld | forced-only draws | forced-only withheld | "
              "withheld for a change |",
              "|---|---|---|---|---|---|---|"]
    for name, blocks in summary["methods"].items():
        for subset, block in blocks.items():
            w = block.get("withheld", {})
            if w.get("draws"):
                lines.append(f"| {name} | {_subset(subset, block)} | {w['draws']} | {w['withheld']} | "
                             f"{w['forced_only']} | {w['forced_only_withheld']} | {w.get('withheld_for_change', 0)} |")
    lines += ["", "## By campaign size", "",
              "| method | campaigns | draws | energy-weighted dA/dt error, median | draws with enough flags | "
              "promise kept |", "|---|---|---|---|---|---|"]
    for name, blocks in summary["methods"].items():
        for label, b in blocks["all"].get("by_size", {}).items():
            lines.append(f"| {name} | {label} | {b['n_draws']} | {_fmt(b['energy_error_median'])} | "
                         f"{b['promise']['draws_with_enough_flags']} | {b['promise']['draws_kept']} |")
    lines += ["", "## By the campaign's own evidence", "",
              "The energy-weighted dA/dt error on the true (A, U) on the draws whose held-out evidence let the "
              "verdict flag windows (the dynamics beat the quasi-steady map and the change scan located no change) "
              "and on the draws where it withheld the regimes: what a user can expect from what the campaign itself "
              "shows, with no truth.", "",
              "| method | campaigns | draws | median | p90 | worst (draw) |", "|---|---|---|---|---|---|"]
    for name, blocks in summary["methods"].items():
        for label, b in blocks["all"].get("by_evidence", {}).items():
            e = b["energy_error"]
            worst = "–" if e["worst"] is None else f"{e['worst']:.3f} ({e['worst_draw']})"
            lines.append(f"| {name} | {label} | {b['n_draws']} | {_fmt(e['median'])} | {_fmt(e['p90'])} | {worst} |")
    lines += ["", "## Against each other", "",
              "Draws on which the first method's energy-weighted dA/dt error on the true (A, U) is below the "
              "second's.", "", "| methods | draws with both | first lower | share |", "|---|---|---|---|"]
    for pair, v in summary.get("versus", {}).items():
        lines.append(f"| {pair} | {v['draws']} | {v['lower']} | {_fmt(v['share_lower'])} |")
    lines += ["", "## Covariates chosen from the campaign's evidence", "",
              "Draws on which a method that chooses its options from held-out events took a yaw covariate, in all "
              "and by the yaw's course: varying between events (per event), or the same course in every event "
              "(shared), where the yaw is confounded with the time within an event and cannot be told from it; "
              f"and on the draws where the yaw matters: the truth's factor on Y1 ranges by {YAW_MATTERS:g} or more "
              "over the campaign's measured yaws (5th to 95th percentile); there also the draws whose confidence "
              "set holds a yaw model (the evidence does not exclude it); on the draws where it does not matter, "
              "those whose chosen model's energy-weighted curve error is within "
              f"{round(100 * (YAW_FREE_MARGIN - 1)):d} % of that of the same options without the yaw, fitted "
              "to every event (of the draws with both curves).", "",
              "| method | draws | draws with a choice | yaw chosen | per-event course: draws, yaw chosen "
              "| shared course: draws, yaw chosen | yaw matters: draws, yaw chosen, yaw in the set "
              "| yaw does not matter: draws, yaw chosen, curves within the margin of the yaw-free model's |",
              "|---|---|---|---|---|---|---|---|"]
    for name, blocks in summary["methods"].items():
        for subset, block in blocks.items():
            c = block["choices"]
            if c["draws"]:
                lines.append(f"| {name} | {_subset(subset, block)} | {c['draws']} | {c['yaw_chosen']} "
                             f"| {c.get('per_event_draws', 0)}, {c.get('per_event_yaw_chosen', 0)} "
                             f"| {c.get('shared_draws', 0)}, {c.get('shared_yaw_chosen', 0)} "
                             f"| {c.get('matters_draws', 0)}, {c.get('matters_yaw_chosen', 0)}, "
                             f"{c.get('matters_yaw_in_set', 0)} "
                             f"| {c.get('minor_draws', 0)}, {c.get('minor_yaw_chosen', 0)}, {_within(c)} |")
    lines += ["", "## Changes the wind does not carry", "",
              "The model's change scan (refits before and after every split of the events, permutation p-value "
              "below 0.05): alarms on draws without a change, and damping steps detected and located within one "
              "event.", "",
              "| method | draws without change | false alarms | draws with a step | detected | located |",
              "|---|---|---|---|---|---|"]
    for name, blocks in summary["methods"].items():
        ch = blocks["all"]["changes"]
        if ch["draws_without_change"] or ch["draws_with_step"]:
            lines.append(f"| {name} | {ch['draws_without_change']} | {ch['false_alarms']} | {ch['draws_with_step']} | "
                         f"{ch['detected']} | {ch['located_within_one_event']} |")
    errors = {name: blocks["all"]["method_errors"] for name, blocks in summary["methods"].items()}
    if any(errors.values()):
        lines += ["", "Method failures (see the `error` column of study.csv): "
                  + ", ".join(f"{k}: {v}" for k, v in errors.items() if v) + "."]
    return "\n".join(lines) + "\n"
