"""Assertion helpers for users' tests of their own methods (docs/methods.md).

A *method* is any object with ``fit(records) -> fitted`` whose fitted model has
``order_contributions(record) -> (n_samples, n_sections, 4)`` in m/s (the
model protocol, :mod:`vivbench.models.protocol`); it may also have
``identifiable(record, window_start, window_end) -> bool (n_windows,
n_sections)``. The helpers turn events (from :func:`vivbench.testing.events`
or read from files) into records, fit the method and compare what it says
with the events' truth, with the same scores ``vivbench validate`` reports.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import xarray as xr

from vivbench.analysis.identify import IdentifyConfig, identify_event
from vivbench.core.errors import InputError
from vivbench.core.record import Record
from vivbench.core.regime import DEFAULT_TAU
from vivbench.io.event import validate_event
from vivbench.io.result import result_record
from vivbench.regimes.model import model_window_regimes
from vivbench.regimes.truth import truth_window_regimes
from vivbench.validate.recovery import model_window_rhs_errors_true_AU, truth_record

__all__ = ["RECORD_SOURCES", "event_records", "assert_valid_event", "assert_recovers"]

#: Where :func:`event_records` takes a record from.
RECORD_SOURCES = ("truth", "measured")


def _as_events(events) -> list[xr.DataTree]:
    if isinstance(events, xr.DataTree):
        return [events]
    out = list(events)
    if not all(isinstance(e, xr.DataTree) for e in out):
        raise TypeError("expected an event (xarray.DataTree) or a sequence of events")
    return out


def event_records(events, *, source: str = "truth", config: IdentifyConfig | None = None) -> list[Record]:
    """Records of the model protocol made from events.

    Parameters
    ----------
    events : xarray.DataTree or sequence of them
        Events in the layout of docs/formats.md.
    source : {"truth", "measured"}
        ``truth``: the averaged truth's own time, A, U and exact dA/dt (the sum
        of ``/truth/r`` over the orders): noise-free, no preprocessing, for a
        method's regression alone (needs ``/truth``). ``measured``: what
        ``vivbench identify`` makes of the sensor records (wind and
        acceleration to U and A on a 4 Hz grid, dA/dt by its TV derivative;
        NaN outside the trusted segments): the whole chain's input, as
        ``vivbench compare`` gives it to methods.
    config : IdentifyConfig, optional
        Settings of the ``measured`` preprocessing (default: the chain's).

    Returns
    -------
    list of Record
        One per event, with the event's ``event_id``.
    """
    if source not in RECORD_SOURCES:
        raise InputError(f"source must be one of {list(RECORD_SOURCES)}; got {source!r}")
    out = []
    for ev in _as_events(events):
        eid = str(ev.attrs["event_id"])
        if source == "truth":
            if "truth" not in ev.children:
                raise InputError(f"event {eid!r} has no /truth group: use source='measured'")
            out.append(truth_record(ev["truth"].to_dataset(), eid))
        else:
            out.append(result_record(identify_event(ev, config)))
    return out


def assert_valid_event(event: xr.DataTree) -> None:
    """Assert that an in-memory event follows the format of docs/formats.md (AssertionError naming the breach)."""
    try:
        validate_event(event, name=f"event {event.attrs.get('event_id', '?')!r}")
    except InputError as exc:
        raise AssertionError(str(exc)) from None


class _Predicting:
    """A fitted model seen through ``predict``: the sum of its order contributions."""

    def __init__(self, fitted):
        self.fitted = fitted

    def predict(self, record: Record) -> np.ndarray:
        r = np.asarray(self.fitted.order_contributions(record), dtype=float)
        if r.shape != record.A.shape + (4,):
            raise AssertionError(f"order_contributions returned shape {r.shape}; the protocol needs "
                                 f"{record.A.shape + (4,)} (n_samples, n_sections, 4)")
        return r.sum(axis=-1)


def _windows(t: np.ndarray, window: float, step: float) -> tuple[np.ndarray, np.ndarray]:
    start = np.arange(t[0], t[-1] - window + 1e-9, step)
    return start, start + window


def _pseudo_truth(record: Record) -> xr.Dataset:
    """A record as a /truth-like dataset whose dA/dt is the record's (no order split is known)."""
    r = np.zeros(record.A.shape + (4,))
    r[..., 0] = record.dA
    return xr.Dataset({"A": (("time", "section"), record.A), "U": (("time", "section"), record.U),
                       "r": (("time", "section", "order"), r)}, coords={"time": record.t})


def assert_recovers(method, event_or_records, *, source: str = "truth", rhs_tolerance: float | None = 0.1,
                    regime_accuracy: float | None = 0.9, window: float = 50.0, step: float = 25.0,
                    tau: float | None = None, active_share: float = 0.1, identifiable_only: bool = True,
                    config: IdentifyConfig | None = None):
    """Assert that a method recovers the truth: its dA/dt and its regimes match within tolerances.

    The method is fitted on the records of all events together (one campaign),
    then each event is scored on its truth's own time, A and U, as ``vivbench
    validate`` scores models (``rhs_error_true_AU``):

    - dA/dt: per window and section, rms(model - truth) / rms(truth) on
      windows where the truth has dynamics (RMS of the true dA/dt at least
      ``active_share`` of the event's); the median over those windows must
      not exceed ``rhs_tolerance``;
    - regimes (docs/concepts.md (regimes), threshold ``tau``): the model's regime of each
      window from its order contributions against the truth's; the share of
      agreeing windows must reach ``regime_accuracy``. If the fitted model
      has ``identifiable`` and ``identifiable_only`` is true, only the windows
      it flags are scored (a method may decline to answer; what it claims
      must be right); with none flagged the check passes, and the message of
      any other failure says so.

    Parameters
    ----------
    method : object with ``fit(records)``
    event_or_records : xarray.DataTree, sequence of DataTree, or sequence of Record
        Events with their ``/truth`` (e.g. from :func:`vivbench.testing.events`
        or :func:`vivbench.testing.campaigns`). Records alone carry no order
        split: then only dA/dt is checked, against each record's ``dA``.
    source : {"truth", "measured"}
        Records the method is fitted on (:func:`event_records`).
    rhs_tolerance : float or None
        Largest median relative dA/dt error; None: not checked.
    regime_accuracy : float or None
        Smallest share of scored windows with the true regime; None: not checked.
    window, step : float, s
        Scoring windows.
    tau : float, optional
        Regime threshold; default the truth's own (``/truth`` attribute ``tau``) or 0.2.
    active_share : float
    identifiable_only : bool
    config : IdentifyConfig, optional
        Preprocessing of ``source="measured"``.

    Returns
    -------
    fitted
        The fitted model, for further checks.

    Raises
    ------
    AssertionError
        The first line says which check failed on how many events; one line
        per event follows with its figures.
    """
    items = [event_or_records] if isinstance(event_or_records, (xr.DataTree, Record)) else list(event_or_records)
    if not items:
        raise InputError("assert_recovers needs at least one event or record")
    if all(isinstance(x, Record) for x in items):
        records, truths = items, [(r.event_id, _pseudo_truth(r), False) for r in items]
    elif all(isinstance(x, xr.DataTree) for x in items):
        records = event_records(items, source=source, config=config)
        truths = []
        for ev in items:
            if "truth" not in ev.children:
                raise InputError(f"event {ev.attrs.get('event_id')!r} has no /truth group: nothing to recover")
            truths.append((str(ev.attrs["event_id"]), ev["truth"].to_dataset(), True))
    else:
        raise TypeError("event_or_records must be events (xarray.DataTree) or records (vivbench Record), not a mix")
    fitted = method.fit(records)
    if not hasattr(fitted, "order_contributions"):
        raise AssertionError(f"{type(method).__name__}.fit returned {type(fitted).__name__}, which has no "
                             "order_contributions(record) (the model protocol, docs/methods.md)")
    predictor = _Predicting(fitted)
    failures, lines = [], []
    for eid, truth, has_orders in truths:
        t = truth["time"].values
        start, end = _windows(t, window, step)
        if start.size == 0:
            raise InputError(f"event {eid!r} is shorter than one scoring window ({window:g} s)")
        parts = [f"{eid}:"]
        bad = False
        if rhs_tolerance is not None:
            err, active = model_window_rhs_errors_true_AU(predictor, truth, start, end, event_id=eid,
                                                          active_share=active_share)
            scored = err[active & np.isfinite(err)]
            missing = int(np.sum(active & ~np.isfinite(err)))
            med = float(np.median(scored)) if scored.size else float("nan")
            parts.append(f"median dA/dt error {med:.3g} over {scored.size} active window-sections"
                         + (f" ({missing} without a finite prediction)" if missing else "")
                         + f" (tolerance {rhs_tolerance:g})")
            if not med <= rhs_tolerance:
                bad = True
        if regime_accuracy is not None and has_orders:
            thr = tau if tau is not None else float(truth.attrs.get("tau", DEFAULT_TAU))
            record = truth_record(truth, eid)
            true_reg = truth_window_regimes(truth, start, end, tau=thr)
            model_reg = model_window_regimes(fitted, record, start, end, tau=thr)["regime"]
            scored = (true_reg > 0) & (model_reg > 0)
            note = ""
            if identifiable_only and hasattr(fitted, "identifiable"):
                flags = np.asarray(fitted.identifiable(record, start, end), dtype=bool)
                if flags.shape != true_reg.shape:
                    raise AssertionError(f"identifiable returned shape {flags.shape}; the protocol needs "
                                         f"{true_reg.shape} (n_windows, n_sections)")
                note = f", {int(flags.sum())} of {flags.size} flagged identifiable"
                scored &= flags
            n = int(scored.sum())
            acc = float(np.mean(model_reg[scored] == true_reg[scored])) if n else float("nan")
            parts.append(f"regime accuracy {acc:.3g} on {n} windows{note} (required {regime_accuracy:g}); "
                         f"true regimes {np.bincount(true_reg[scored].ravel(), minlength=5)[1:].tolist()}, "
                         f"model's {np.bincount(model_reg[scored].ravel(), minlength=5)[1:].tolist()} (counts of 1..4)")
            if n and not acc >= regime_accuracy:
                bad = True
        lines.append(" ".join(parts))
        if bad:
            failures.append(eid)
    if failures:
        raise AssertionError(f"{type(method).__name__} does not recover the truth on {len(failures)} of "
                             f"{len(truths)} event(s) ({', '.join(failures)}):\n" + "\n".join(lines))
    return fitted
