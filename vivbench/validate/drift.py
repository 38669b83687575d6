"""The campaign model's change flags scored against the truth's recorded slow changes (docs/concepts.md (no inverse crime)).

The generator records, per event, the parameters its slow changes set: the
step of damping or mass and the retrofit of the deck aerodynamics (from a
given event on) and the daily damping drift. A step or a retrofit makes the
events from it on *changed* relative to the campaign's first event; the daily
drift runs on continuously and is not a change of any one event, so it is not
scored. The flags of ``vivbench pool`` (``event_after_change``, ``event_change_flag``,
``event_offset_flag``, ``event_misfit_flag``) are then counted as hits on
changed events and false alarms on unchanged ones, and the located change
(``model_change_event``, ``change_event``) is compared with the first changed
event.
"""

from __future__ import annotations

import json

import numpy as np

__all__ = ["FLAG_VARIABLES", "event_structural_state", "score_change_flags"]

#: The regimes file's per-event flags that are scored, with their meaning.
FLAG_VARIABLES = {
    "event_after_change": "from the change the model change scan located (campaign-level test)",
    "event_change_flag": "after the located change, held-out offset departs from the before-events' (per event)",
    "event_offset_flag": "linear offset departs from the other events' of its stratum (change-agnostic)",
    "event_misfit_flag": "held-out misfit is a robust outlier (change-agnostic)",
}


def event_structural_state(truth) -> np.ndarray | None:
    """The event's step-changed parameters, shape (6,): damping step factor, mass factor, aero factors (4,).

    Parameters
    ----------
    truth : xarray.Dataset, an event's ``/truth``

    Returns
    -------
    ndarray or None
        The median over the event of the recorded ``mass_factor`` and
        ``aero_factor`` and the configured damping step factor (1 when the
        configuration is not readable); None when the truth records no slow
        changes (then nothing changed).
    """
    if "aero_factor" not in truth.data_vars or "mass_factor" not in truth.data_vars:
        return None
    step = 1.0
    try:
        meta = json.loads(truth.attrs["config_json"])
        changes = meta["generator"].get("changes", {})
        number = int(meta.get("event", {}).get("number", 0))
        if changes.get("step_event") and number >= int(changes["step_event"]):
            step = float(changes.get("step_damping_factor", 1.0))
    except (KeyError, TypeError, ValueError):
        pass
    aero = np.nanmedian(np.asarray(truth["aero_factor"].values, dtype=float), axis=0)
    return np.concatenate([[step, float(np.nanmedian(truth["mass_factor"].values))], aero])


def score_change_flags(pooled, states: dict) -> dict | None:
    """Hits and false alarms of the regimes file's change flags against the truth's steps and retrofits.

    Parameters
    ----------
    pooled : xarray.Dataset, a ``campaign.regimes.nc``
    states : dict event_id -> :func:`event_structural_state` (None: no recorded changes), events in time order

    Returns
    -------
    dict or None
        None when the regimes file has no per-event flags. Otherwise
        ``changed_events`` (truth), ``first_changed`` (or None), per flag
        variable present ``{flag: {"flagged", "hits", "false_alarms",
        "n_changed", "n_unchanged", "hit_rate", "false_alarm_rate"}}`` under
        ``flags``, and ``located`` {"model_change_event", "change_event"}
        each with ``"correct"``: the detected change is the first changed
        event, or no change was detected and the truth has none.
    """
    present = [k for k in FLAG_VARIABLES if k in pooled.data_vars]
    if not present:
        return None
    ids = [str(e) for e in pooled["event"].values]
    known = [e for e in ids if e in states]
    ref = next((states[e] for e in known if states[e] is not None), None)
    changed = {e: bool(ref is not None and states[e] is not None and not np.allclose(states[e], ref, rtol=1e-6))
               for e in known}
    first = next((e for e in known if changed[e]), None)
    out = {"changed_events": [e for e in known if changed[e]], "first_changed": first, "flags": {}, "located": {}}
    for key in present:
        flag = dict(zip(ids, pooled[key].values.astype(bool)))
        flagged = [e for e in known if flag[e]]
        hits = [e for e in flagged if changed[e]]
        n_ch = sum(changed.values())
        n_un = len(known) - n_ch
        out["flags"][key] = {"meaning": FLAG_VARIABLES[key], "flagged": flagged, "hits": len(hits),
                             "false_alarms": len(flagged) - len(hits), "n_changed": n_ch, "n_unchanged": n_un,
                             "hit_rate": len(hits) / n_ch if n_ch else float("nan"),
                             "false_alarm_rate": (len(flagged) - len(hits)) / n_un if n_un else float("nan")}
    for attr, detected in (("model_change_event", "model_change_detected"), ("change_event", "change_detected")):
        if attr in pooled.attrs:
            event = str(pooled.attrs[attr]) if int(pooled.attrs.get(detected, 0)) else ""
            out["located"][attr] = {"event": event or None, "correct": (event or None) == first}
    return out
