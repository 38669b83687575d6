"""Window SINDy as a model of the protocol (docs/methods.md): per-event window models over records.

:class:`vivbench.models.window.EventWindowSINDy` fits one record (the paper's
time-varying SINDy); :class:`WindowSINDy` fits it to every record of a
campaign and keeps each event's windows. Evaluated on a record, the model at a
time is that of the event's fitted window whose centre is nearest (ties: the
earlier window), the rule of :func:`vivbench.models.simulate.window_in_force`,
so predictions, order contributions and simulations agree with the
identification's simulation. Window models are not campaign-level: they have
no ``curves`` (a window's coefficients hold only along the data it saw).
"""

from __future__ import annotations

import dataclasses
import json
from collections.abc import Sequence

import numpy as np
import xarray as xr

import vivbench
from vivbench.core.record import Record
from vivbench.core.terms import evaluate_library, feature_names
from vivbench.io.window_model import read_window_model, write_window_model
from vivbench.models.protocol import (
    ModelBase,
    as_record,
    coef_order_contributions,
    format_equations,
    section_names,
    simulate_windows,
)
from vivbench.models.simulate import Simulation
from vivbench.models.window import EventWindowSINDy
from vivbench.regression.optimizers import OptimizerOptions

__all__ = ["WindowSINDy", "nearest_window"]


def nearest_window(window_start: np.ndarray, window_end: np.ndarray, fitted: np.ndarray, t) -> np.ndarray:
    """Index of the fitted window whose centre is nearest to each time (ties: the earlier window).

    The array form of :func:`vivbench.models.simulate.window_in_force`.

    Parameters
    ----------
    window_start, window_end : ndarray, shape (W,), s
    fitted : ndarray of bool, shape (W,)
        Windows with a model; at least one.
    t : array_like, s

    Returns
    -------
    ndarray of int, shape of ``t``
    """
    idx = np.flatnonzero(fitted)
    if idx.size == 0:
        raise ValueError("no window has a fitted model")
    centre = 0.5 * (np.asarray(window_start, dtype=float)[idx] + np.asarray(window_end, dtype=float)[idx])
    order = np.argsort(centre, kind="stable")
    c = centre[order]
    t = np.asarray(t, dtype=float)
    tt = t.ravel()
    if c.size == 1:
        pick = np.zeros(tt.size, dtype=int)
    else:
        pos = np.clip(np.searchsorted(c, tt), 1, c.size - 1)
        pick = np.where(np.abs(tt - c[pos - 1]) <= np.abs(c[pos] - tt), pos - 1, pos)
    return idx[order[pick]].reshape(t.shape)


class WindowSINDy(ModelBase):
    """Time-varying SINDy over a campaign's records: one :class:`EventWindowSINDy` fit per event.

    Parameters
    ----------
    window, step, thresholds, alpha, max_iter, scaling, unbias, allow_empty, residual_floor,
    refit_rcond, solver, chunk_size, keep_path, raw_cond, optimizer, optimizer_options, random_state
        Those of :class:`vivbench.models.window.EventWindowSINDy`, with the same
        defaults (``keep_path=True`` keeps each event's threshold path in
        ``estimators_``; pass False to save memory on long campaigns).

    Attributes
    ----------
    event_ids_ : list of str
        Events fitted, in the order of the records.
    estimators_ : dict of str to EventWindowSINDy
        The fitted per-event estimators (not restored by :meth:`load`).
    coef_ : ndarray, shape (W, S, 23 S)
        Physical coefficients of every window of every event (dA/dt in m/s); NaN
        where no model was fitted.
    window_start_, window_end_ : ndarray, shape (W,), s
    window_event_ : ndarray of int, shape (W,)
        Index into ``event_ids_`` of each window.
    threshold_, n_terms_, rss_, aicc_ : ndarray, shape (W, S)
    n_sections_ : int
    feature_names_ : list of str
    """

    # The same parameters as the single-record estimator, so the two cannot drift apart.
    __init__ = EventWindowSINDy.__init__

    def estimator(self) -> EventWindowSINDy:
        """A fresh single-record estimator with these parameters."""
        return EventWindowSINDy(**self.get_params())

    def fit(self, records: Sequence[Record | tuple]) -> "WindowSINDy":
        """Fit window SINDy to every record.

        Parameters
        ----------
        records : sequence of Record (or legacy (t, A, U, dA) tuples)
            One per event, all with the same number of sections and distinct event ids.

        Returns
        -------
        self
        """
        records = [as_record(r, k) for k, r in enumerate(records)]
        if not records:
            raise ValueError("no records to fit")
        ids = [r.event_id for r in records]
        dup = sorted({e for e in ids if ids.count(e) > 1})
        if dup:
            raise ValueError(f"event ids must be distinct; repeated: {', '.join(dup)}")
        S = records[0].n_sections
        estimators = {}
        for rec in records:
            if rec.n_sections != S:
                raise ValueError(f"record {rec.event_id!r} has {rec.n_sections} sections, the first record {S}")
            if rec.dA is None:
                raise ValueError(f"record {rec.event_id!r} has no dA: window SINDy is fitted to dA/dt")
            try:
                estimators[rec.event_id] = self.estimator().fit(rec.t, rec.A, rec.U, rec.dA)
            except ValueError as exc:
                raise ValueError(f"record {rec.event_id!r}: {exc}") from None
        est = list(estimators.values())
        self.estimators_ = estimators
        self.event_ids_ = ids
        self.coef_ = np.concatenate([e.coef_ for e in est])
        self.window_start_ = np.concatenate([e.window_start_ for e in est])
        self.window_end_ = np.concatenate([e.window_end_ for e in est])
        self.window_event_ = np.concatenate([np.full(e.coef_.shape[0], k) for k, e in enumerate(est)])
        self.threshold_ = np.concatenate([e.threshold_ for e in est])
        self.n_terms_ = np.concatenate([e.n_terms_ for e in est])
        self.rss_ = np.concatenate([e.rss_ for e in est])
        self.aicc_ = np.concatenate([e.aicc_ for e in est])
        self.n_sections_ = S
        self.feature_names_ = est[0].feature_names_
        return self

    # -- the model protocol -------------------------------------------------------------------------

    def _windows_of(self, record) -> tuple[Record, np.ndarray]:
        """The record and the indices of its event's windows."""
        self._check_fitted()
        record = as_record(record)
        if record.n_sections != self.n_sections_:
            raise ValueError(f"record {record.event_id!r} has {record.n_sections} sections; "
                             f"the model was fitted on {self.n_sections_}")
        if record.event_id not in self.event_ids_:
            raise KeyError(f"event {record.event_id!r} was not fitted; window models hold only the events they saw "
                           f"({', '.join(self.event_ids_[:5])}{', ...' if len(self.event_ids_) > 5 else ''})")
        return record, np.flatnonzero(self.window_event_ == self.event_ids_.index(record.event_id))

    def coef_at(self, record: Record) -> np.ndarray:
        """Coefficients in force at each sample of the record, shape (n_samples, S, 23 S).

        NaN everywhere if the event has no fitted window.
        """
        record, w = self._windows_of(record)
        coef = self.coef_[w]
        fitted = np.all(np.isfinite(coef), axis=(1, 2))
        if not fitted.any():
            return np.full((record.n_samples,) + coef.shape[1:], np.nan)
        return coef[nearest_window(self.window_start_[w], self.window_end_[w], fitted, record.t)]

    def order_contributions(self, record: Record) -> np.ndarray:
        """Order contributions r_0..r_3 with the window in force at each sample.

        Returns
        -------
        r : ndarray, shape (n_samples, n_sections, 4), m/s
        """
        record = as_record(record)
        return coef_order_contributions(record.A, record.U, self.coef_at(record))

    def predict(self, record: Record) -> np.ndarray:
        """dA/dt with the window in force at each sample, shape (n_samples, n_sections), m/s."""
        record = as_record(record)
        coef = self.coef_at(record)
        return np.einsum("nc,nkc->nk", evaluate_library(record.A, record.U), coef)

    def simulate(self, record: Record, t0: float | None = None, t1: float | None = None, A0=None,
                 **kwargs) -> Simulation:
        """Integrate the time-varying model (:func:`vivbench.models.simulate.simulate_identified`'s rule).

        Parameters
        ----------
        record : Record of a fitted event
        t0, t1 : float, s, optional
            Default: the first fitted window's start to the last one's end.
        A0 : array_like, shape (S,), m, optional
            Default: the record's A at t0.
        **kwargs
            ``u_interp``, ``bound_factor``, ``negative_tolerance``, ``clip``.
        """
        record, w = self._windows_of(record)
        return simulate_windows(record, self.coef_[w], self.window_start_[w], self.window_end_[w],
                                t0=t0, t1=t1, A0=A0, **kwargs)

    def equations(self, precision: int = 3, *, event_id: str | None = None) -> list[str]:
        """Equations of every window, each prefixed by ``[event start-end s]``.

        Parameters
        ----------
        precision : int
            Significant digits.
        event_id : str, optional
            Only this event's windows.
        """
        self._check_fitted()
        lhs = [f"dA{k + 1}/dt" for k in range(self.n_sections_)]
        out = []
        for w in range(self.coef_.shape[0]):
            ev = self.event_ids_[self.window_event_[w]]
            if event_id is not None and ev != event_id:
                continue
            head = f"[{ev} {self.window_start_[w]:g}-{self.window_end_[w]:g} s] "
            out += [head + line for line in format_equations(self.coef_[w], self.feature_names_, lhs, precision)]
        return out

    def _params_json(self) -> str:
        params = self.get_params()
        if params["thresholds"] is not None:
            params["thresholds"] = [float(x) for x in np.ravel(params["thresholds"])]
        if params["optimizer_options"] is not None:
            params["optimizer_options"] = dataclasses.asdict(params["optimizer_options"])
        return json.dumps(params, sort_keys=True)

    def to_dataset(self) -> xr.Dataset:
        """The fitted model as the Dataset of a window-model file (``vivbench.io.window_model``)."""
        self._check_fitted()
        we = ("window", "equation")
        data = {
            "coef": (("window", "equation", "feature"), self.coef_, {"units": "m/s per unit of the feature"}),
            "window_start": (("window",), self.window_start_, {"units": "s"}),
            "window_end": (("window",), self.window_end_, {"units": "s"}),
            "window_event": (("window",), self.window_event_.astype(np.int32)),
            "threshold": (we, self.threshold_), "n_terms": (we, self.n_terms_.astype(np.int32)),
            "rss": (we, self.rss_, {"units": "m2 s-2"}), "aicc": (we, self.aicc_),
        }
        coords = {"event": np.array(self.event_ids_, dtype=str), "equation": section_names(self.n_sections_),
                  "feature": self.feature_names_}
        attrs = {"model": type(self).__name__, "params_json": self._params_json(),
                 "vivbench_version": vivbench.__version__}
        return xr.Dataset(data, coords=coords, attrs=attrs)

    def save(self, path):
        """Write the window coefficients as a NetCDF window-model file; returns the path."""
        return write_window_model(self.to_dataset(), path)

    @classmethod
    def from_result(cls, ds: xr.Dataset, windows=None) -> "WindowSINDy":
        """The window models of one identification result as a fitted model of the protocol.

        Parameters
        ----------
        ds : xarray.Dataset
            An identification result (``<event_id>.identify.nc``, read by
            :func:`vivbench.io.result.read_result`) with ``coef`` (window,
            equation, feature) in physical units (dA/dt in m/s),
            ``window_start``, ``window_end`` (window) in s and the attribute
            ``event_id``; ``threshold``, ``n_terms``, ``rss`` and ``aicc``
            (window, equation) are copied when present (NaN or 0 otherwise).
        windows : array_like of int, optional
            Only these windows (indices along ``window``, in the given order).
            ``from_result(ds, windows=[w]).predict(record)`` is window w's own
            model at every sample of the record, whatever the neighbouring windows.

        Returns
        -------
        WindowSINDy
            Fitted with the default parameters (the result's identification
            settings are in its ``identify_config_json``, not restored here) and
            an empty ``estimators_``: it predicts, gives order contributions,
            simulates, prints equations and saves.

        Raises
        ------
        InputError
            One line naming the result's file when a variable or the event id is missing.
        """
        from vivbench.core.errors import InputError

        source = ds.encoding.get("source", "result")
        missing = [n for n in ("coef", "window_start", "window_end") if n not in ds.data_vars]
        if missing or "event_id" not in ds.attrs:
            what = ", ".join(missing + ([] if "event_id" in ds.attrs else ["the event_id attribute"]))
            raise InputError(f"{source}: not an identification result with window models: missing {what}")
        n_w = int(ds.sizes["window"])
        w = np.arange(n_w) if windows is None else np.atleast_1d(np.asarray(windows, dtype=int))
        if w.size == 0 or np.any((w < 0) | (w >= n_w)):
            raise InputError(f"{source}: windows must be indices in 0..{n_w - 1}; got {w.tolist()}")
        coef = np.asarray(ds["coef"].values, dtype=float)[w]
        shape = coef.shape[:2]

        def per_window(name, fill):
            return np.asarray(ds[name].values)[w] if name in ds.data_vars else np.full(shape, fill)

        model = cls()
        model.estimators_ = {}
        model.event_ids_ = [str(ds.attrs["event_id"])]
        model.coef_ = coef
        model.window_start_ = np.asarray(ds["window_start"].values, dtype=float)[w]
        model.window_end_ = np.asarray(ds["window_end"].values, dtype=float)[w]
        model.window_event_ = np.zeros(w.size, dtype=int)
        model.threshold_ = per_window("threshold", np.nan).astype(float)
        model.n_terms_ = per_window("n_terms", 0).astype(int)
        model.rss_ = per_window("rss", np.nan).astype(float)
        model.aicc_ = per_window("aicc", np.nan).astype(float)
        model.n_sections_ = int(coef.shape[1])
        model.feature_names_ = ([str(f) for f in ds["feature"].values] if "feature" in ds.coords
                                else feature_names(model.n_sections_))
        return model

    @classmethod
    def load(cls, path) -> "WindowSINDy":
        """A fitted model from a window-model file (``estimators_`` is empty: only coefficients are stored)."""
        ds = read_window_model(path)
        params = json.loads(ds.attrs["params_json"])
        if params.get("optimizer_options") is not None:
            params["optimizer_options"] = OptimizerOptions(**params["optimizer_options"])
        if params.get("thresholds") is not None:
            params["thresholds"] = tuple(params["thresholds"])
        model = cls(**params)
        model.estimators_ = {}
        model.event_ids_ = [str(e) for e in ds["event"].values]
        model.coef_ = ds["coef"].values
        model.window_start_ = ds["window_start"].values
        model.window_end_ = ds["window_end"].values
        model.window_event_ = ds["window_event"].values.astype(int)
        model.threshold_ = ds["threshold"].values
        model.n_terms_ = ds["n_terms"].values.astype(int)
        model.rss_ = ds["rss"].values
        model.aicc_ = ds["aicc"].values
        model.n_sections_ = int(ds.sizes["equation"])
        model.feature_names_ = [str(f) for f in ds["feature"].values]
        return model
