"""The held-out evidence of a model selection as text: what ``vivbench pool`` prints."""

from __future__ import annotations

import math

__all__ = ["evidence_text"]


def evidence_text(ev: dict, *, note: str = "", short_threshold: float = float("nan")) -> str:
    """Lines of text for :meth:`vivbench.analysis.ModelSelection.evidence` ``ev``.

    Parameters
    ----------
    ev : dict, the evidence
    note : str, why no held-out choice was made ("" when it was): then the text is the note alone
    short_threshold : float, the envelope time constants an event must last for its limit regimes
    """
    if note:
        return note
    best = min((c["held_out_loss"] for c in ev["candidates"] if c["scored"]), default=float("nan"))
    unit = "m^2" if ev["criterion"] == "output" else "m^2/s^2"
    lines = [f"held-out {('output' if ev['criterion'] == 'output' else 'dA/dt')} error over "
             f"{len(ev['events'])} events in {ev['n_folds']} folds (sum of squares, {unit}):"]
    for c in ev["candidates"]:
        if not c["scored"]:
            lines.append(f"  {c['name']:<22} not scored: no simpler candidate needed its terms")
            continue
        rel = c["held_out_loss"] / best if best > 0 else float("nan")
        mark = "chosen" if c["name"] == ev["chosen"] else ("in the confidence set" if c["in_set"] else "")
        rank = "" if not math.isfinite(c["p_rank"]) else f", signed-rank p {c['p_rank']:.2g}"
        lines.append(f"  {c['name']:<22} {c['held_out_loss']:.4g} ({rel:.3f} x best; +{c['excess']:.3g} "
                     f"+- {c['se']:.3g}{rank}) {mark}".rstrip())
    lines += _smoothing_lines(ev.get("wind_smoothing"))
    null = ev["null"]
    if null is not None:
        rel = null["held_out_loss"] / best if best > 0 else float("nan")
        lines.append(f"  {'null: ' + null['name']:<22} {null['held_out_loss']:.4g} ({rel:.3f} x best; "
                     f"+{null['excess']:.3g} +- {null['se']:.3g})")
        lines.append("  the dynamic models predict held-out events significantly better than the null model: "
                     "regimes may be flagged" if ev["dynamics_shown"] else
                     "  the null model predicts held-out events as well as the dynamic models: the dynamics, "
                     "and so the regimes, are not identified from this campaign; no window is flagged")
        local = ev.get("dynamics_by_wind")
        if local is not None and ev["dynamics_shown"]:
            e = local["wind_edges"]
            spans = [(f"{e[b]:.1f}-{e[b + 1]:.1f}", ok) for b, ok in enumerate(local["shown"])]
            missing = [x for x, ok in spans if not ok]
            lines.append("  by wind (m/s): the chosen model beats the null model significantly in "
                         + (", ".join(x for x, ok in spans if ok) or "no bin")
                         + ("" if not missing else "; not in " + ", ".join(missing)
                            + ": no window is flagged at those winds"))
    change = ev["change"]
    if change["tested"]:
        lines.append(f"  the chosen model's change scan locates a change from {change['event']} on "
                     f"(p = {change['p_value']:.3g}): one model does not hold for the whole campaign; "
                     "no window is flagged" if change["detected"] else
                     f"  the chosen model's change scan locates no change (p = {change['p_value']:.3g})")
    short, tc = ev["short_events"], ev["time_constant_s"]
    verdict = "are not flagged" if ev["min_time_constants"] is not None else "may be misread"
    if short and ev["dynamics_shown"] and ev["stationary"]:  # otherwise no window is flagged anyway
        lines.append(f"  {len(short)} of {len(ev['events'])} events are shorter than {short_threshold:g} "
                     f"envelope time constants ({tc:.0f} s): they show an amplitude's change but not how it "
                     f"ends, and their limit regimes (3, 4) {verdict}" if math.isfinite(tc) else
                     "  the envelope's time constant is not identified (the chosen model flags no regime-1 "
                     f"window), so no event is known to show how an amplitude's change ends: limit regimes "
                     f"(3, 4) {verdict}")
    return "\n".join(lines)


def _smoothing_lines(sm: dict | None) -> list[str]:
    """The wind smoothing the records settled and its cross-validated evidence (``evidence()["wind_smoothing"]``;
    None: not settled from the records, the models' own)."""
    if not sm or len(sm["candidates_s"]) < 2:
        return [] if not sm else [f"  wind smoothing {sm['chosen_s']:g} s (given or the prior; not chosen here)"]
    errors = ", ".join(f"{c:g} s {e:.4g}" for c, e in zip(sm["candidates_s"], sm["cv_error"]))
    how = ("the prior, not beaten by more than one standard error" if sm["chosen_s"] == sm["prior_s"] else
           f"below the {sm['prior_s']:g} s prior's by more than one standard error")
    return [f"  wind smoothing {sm['chosen_s']:g} s for every model, chosen by the simplest candidate's "
            f"cross-validated dA/dt error over folds of events ({errors}; per sample, standardised): {how}"]
