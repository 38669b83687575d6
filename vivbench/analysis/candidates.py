"""A selection's candidates (:class:`Candidate`) and their adaptation to the records before the held-out choice.

Two adaptations, both from the records alone:

- :func:`without_yaw`: the candidates that need no wind yaw, for records that carry none
  (and :func:`yaw_free_counterpart`, one candidate's yaw-free version, to compare with it);
- :func:`settle_candidates`: the settings that the simplest candidate settles once on every event
  (its ``settle(records)``, e.g. the varying model's wind smoothing chosen by its own cross-validation,
  :func:`vivbench.models.varying_fit.settle_smoothing`) given to every model of the selection that has
  them, so that the held-out fits compare the candidates on one input and the costly choice is made
  once instead of in every fold of every candidate.
"""

from __future__ import annotations

import copy
import dataclasses
from dataclasses import dataclass
from typing import Any, Sequence

from vivbench.core.errors import InputError

__all__ = ["Candidate", "settle_candidates", "without_yaw", "yaw_free_counterpart"]


@dataclass(frozen=True, kw_only=True)
class Candidate:
    """One candidate campaign model of a selection.

    Attributes
    ----------
    name : str
        Short label, e.g. ``"yaw0-cv"``; unique within a selection.
    model : object
        An unfitted model of the protocol (``fit(records)`` returning the fitted model,
        ``simulate`` for the output error or ``predict`` for the derivative criterion,
        ``order_contributions``); fitted on copies, never in place.
    complexity : int
        Rank of simplicity (0 the simplest); the selection reports the simplest member of
        the confidence set.
    options : dict
        The option values this candidate stands for (recorded with the choice).
    """

    name: str
    model: Any
    complexity: int = 0
    options: dict | None = None

    def __post_init__(self) -> None:
        if not isinstance(self.name, str) or not self.name:
            raise InputError(f"a candidate's name must be a non-empty string; got {self.name!r}")
        if not callable(getattr(self.model, "fit", None)):
            raise InputError(f"candidate {self.name!r}: its model has no fit(records) method")
        if int(self.complexity) != self.complexity or self.complexity < 0:
            raise InputError(f"candidate {self.name!r}: complexity must be an integer >= 0; got {self.complexity!r}")


def without_yaw(selection):
    """The selection's candidates that need no yaw (``yaw_degree`` 0), for records that carry none.

    Raises InputError when none is left.
    """
    kept = [c for c in selection.candidates if not getattr(c.model, "yaw_degree", 0)]
    if not kept:
        raise InputError("every candidate model needs the wind's yaw, which the records do not carry")
    out = copy.copy(selection)
    out.candidates = tuple(kept)
    return out


def yaw_free_counterpart(candidates: Sequence[Candidate], name: str) -> Candidate | None:
    """The candidate of the same options as candidate ``name`` but without the yaw covariate.

    Parameters
    ----------
    candidates : sequence of Candidate (a selection's)
    name : str, one of their names

    Returns
    -------
    Candidate whose ``options`` are those of ``name`` with ``yaw_degree`` 0, or None when ``name`` takes no
    yaw (its ``yaw_degree`` is 0 or absent) or no such candidate is among ``candidates``.
    Raises InputError when ``name`` is not a candidate's.
    """
    by_name = {c.name: c for c in candidates}
    if name not in by_name:
        raise InputError(f"no candidate is named {name!r}; the names are {', '.join(map(repr, by_name))}")
    options = dict(by_name[name].options or {})
    if not options.get("yaw_degree"):
        return None
    wanted = {**options, "yaw_degree": 0}
    return next((c for c in candidates if dict(c.options or {}) == wanted), None)


def settle_candidates(candidates: Sequence, null_model, records) -> tuple[tuple, Any, dict]:
    """The candidates and null model with the settings the simplest candidate settles on ``records``.

    Parameters
    ----------
    candidates : sequence of Candidate (the first of the lowest complexity is the simplest)
    null_model : an unfitted model or None
    records : sequence of Record, every event

    Returns
    -------
    candidates : tuple of Candidate, each model given the settled parameters it has (``get_params``)
    null_model : the same for the null model (None stays None)
    evidence : dict, the simplest candidate's evidence for its settlement (JSON-ready; {} without one)
    """
    simplest = min(candidates, key=lambda c: c.complexity)
    settle = getattr(simplest.model, "settle", None)
    params, evidence = settle(records) if callable(settle) else ({}, {})
    if not params:
        return tuple(candidates), null_model, dict(evidence)

    def given(model):
        own = model.get_params() if callable(getattr(model, "get_params", None)) else {}
        mine = {k: v for k, v in params.items() if k in own}
        return type(model)(**{**own, **mine}) if mine else model

    settled = tuple(dataclasses.replace(c, model=given(c.model)) for c in candidates)
    return settled, (None if null_model is None else given(null_model)), dict(evidence)
