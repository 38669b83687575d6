"""The model protocol (docs/methods.md): one interface for everything that turns data into dynamics.

A *method* has ``fit(records)`` and returns a *fitted model*; a fitted model
gives at least ``order_contributions(record)``, the contributions r_0..r_3 of
the powers of A to dA/dt (n_samples, n_sections, 4). It may also give
``predict(record)`` (dA/dt), ``simulate(record, t0, t1, A0)``,
``curves(wind)`` (campaign-level models only, docs/concepts.md (coefficient curves)), ``save``/``load``
(NetCDF) and pysindy-like ``equations()``. Regimes, forecasts, validation and
the report use only these names, so a user's model works wherever a built-in
one does.

A campaign model may also give the optional methods below; code outside the
models asks for them only through the helper of the same concern, which
supplies the default, so no caller branches on a model's class or fitted
attributes:

================================  ==================================  =====================================
method                            helper                              default
================================  ==================================  =====================================
``window_verdicts(record, s, e)`` :func:`vivbench.regimes.model_verdicts`  the regime rule on the order
                                                                      contributions, nothing identifiable
``campaign_summary()``            :func:`model_summary`               the class's name and import path
``terms_per_equation()``          :func:`model_size`                  ``[]`` (no size to report)
``for_records(records)``          :func:`model_for_records`           the model itself
``event_change_inputs(records)``  :func:`model_change_inputs`         None (no model change scan)
``measured_wind(record)``         :func:`transforms_wind`             the caller's wind smoothing
``curves(wind)``                  :func:`model_curves`                None (no curves)
``report_description(regimes)``   :func:`model_description`           the class's name and its coverage
``chosen_model()``                :func:`chosen_model`                the model itself (not a wrapper)
``evidence()``                    :func:`model_evidence`              None (no held-out evidence)
``settings_text()``               :func:`model_settings_text`         the class's name and its size per equation
================================  ==================================  =====================================

The protocols are :func:`typing.runtime_checkable`: ``isinstance(m, FittedModel)``
checks that the methods exist (not their signatures). :class:`ModelBase`
gives scikit-learn's conventions (``get_params``/``set_params`` from the
keyword-only parameters of ``__init__``, a ``__repr__`` with the parameters
that differ from their defaults) and ``print()`` on top of ``equations()``.
The helpers below (:func:`as_record`, :func:`coef_order_contributions`,
:func:`format_equations`, :func:`simulate_windows`) are shared by the built-in
models and available to users' models.
"""

from __future__ import annotations

import dataclasses
import inspect
import json
from collections.abc import Sequence
from typing import Protocol, runtime_checkable

import numpy as np
import xarray as xr

from vivbench.core.record import Record
from vivbench.core.terms import evaluate_library, section_exponents
from vivbench.models.simulate import Simulation, nmse, simulate_identified

__all__ = [
    "Method", "FittedModel", "Predictor", "Simulator", "CampaignLevel", "Persistent", "HasEquations",
    "ModelBase", "NotFittedError", "as_record", "fit_records", "coef_order_contributions", "format_equations",
    "section_names", "simulate_windows", "model_summary", "model_size", "model_for_records", "model_change_inputs",
    "recorded_change_scan", "simulate_many", "transforms_wind", "model_curves", "model_class_path", "model_description", "chosen_model",
    "model_evidence", "model_settings_text", "IDENTIFIABLE_LONG_NAME",
]


@runtime_checkable
class Method(Protocol):
    """Anything that fits records: ``fit(records) -> FittedModel``."""

    def fit(self, records: Sequence[Record]): ...


@runtime_checkable
class FittedModel(Protocol):
    """A fitted model: the order contributions are the one required output.

    ``order_contributions(record)`` returns r_i, shape (n_samples, n_sections, 4)
    in m/s, with sum over i equal to the model's dA/dt (NaN where the record
    has no sample).
    """

    def order_contributions(self, record: Record) -> np.ndarray: ...


@runtime_checkable
class Predictor(Protocol):
    """Optional: ``predict(record)`` -> dA/dt, shape (n_samples, n_sections), m/s."""

    def predict(self, record: Record) -> np.ndarray: ...


@runtime_checkable
class Simulator(Protocol):
    """Optional: ``simulate(record, t0, t1, A0)`` integrates the model with the record's wind."""

    def simulate(self, record: Record, t0: float, t1: float, A0=None): ...


@runtime_checkable
class CampaignLevel(Protocol):
    """Optional, campaign-level models only: ``curves(wind)`` (docs/concepts.md (coefficient curves))."""

    def curves(self, wind) -> xr.Dataset: ...


@runtime_checkable
class Persistent(Protocol):
    """Optional: ``save(path)`` and ``load(path)`` (a class method) to and from NetCDF."""

    def save(self, path): ...

    def load(self, path): ...


@runtime_checkable
class HasEquations(Protocol):
    """Optional: pysindy-like ``equations()`` (list of str) and ``print()``."""

    def equations(self, precision: int = 3) -> list[str]: ...


class NotFittedError(ValueError, AttributeError):
    """A fitted model's method was called before ``fit`` (scikit-learn's name)."""


class ModelBase:
    """scikit-learn conventions for models of the protocol.

    Subclasses declare their parameters as keyword-only arguments of
    ``__init__`` and store each as an attribute of the same name; fitted
    attributes end in ``_``. This base derives ``get_params``,
    ``set_params`` and ``__repr__`` from that signature and gives
    ``print()`` on top of the subclass's ``equations()``.
    """

    #: A fitted attribute whose presence means "fitted" (subclasses override).
    _fitted_attribute = "coef_"

    @classmethod
    def _param_names(cls) -> list[str]:
        sig = inspect.signature(cls.__init__)
        return [p.name for p in sig.parameters.values() if p.kind is inspect.Parameter.KEYWORD_ONLY]

    @classmethod
    def _param_defaults(cls) -> dict:
        sig = inspect.signature(cls.__init__)
        return {p.name: p.default for p in sig.parameters.values() if p.kind is inspect.Parameter.KEYWORD_ONLY}

    def get_params(self, deep: bool = True) -> dict:
        """Constructor parameters by name (scikit-learn convention; ``deep`` is accepted and unused)."""
        return {name: getattr(self, name) for name in self._param_names()}

    def set_params(self, **params):
        """Set constructor parameters by name; returns self. Unknown names raise ValueError."""
        allowed = self._param_names()
        for name, value in params.items():
            if name not in allowed:
                raise ValueError(f"unknown parameter {name!r} for {type(self).__name__}; allowed: {', '.join(allowed)}")
            setattr(self, name, value)
        return self

    def __repr__(self) -> str:
        defaults = self._param_defaults()
        shown = []
        for name, value in self.get_params().items():
            default = defaults.get(name, inspect.Parameter.empty)
            try:
                same = bool(np.all(value == default)) and np.shape(value) == np.shape(default)
            except (TypeError, ValueError):
                same = repr(value) == repr(default)
            if not same:
                shown.append(f"{name}={value!r}")
        return f"{type(self).__name__}({', '.join(shown)})"

    @property
    def is_fitted(self) -> bool:
        """Whether ``fit`` has run (or the model was loaded)."""
        return hasattr(self, self._fitted_attribute)

    def _check_fitted(self) -> None:
        if not self.is_fitted:
            raise NotFittedError(f"this {type(self).__name__} is not fitted yet: call fit(records) or load(path) first")

    def _check_record(self, record) -> Record:
        """The record (legacy tuples accepted), checked against the fitted model's number of sections."""
        self._check_fitted()
        record = as_record(record)
        if record.n_sections != self.n_sections_:
            raise ValueError(f"record {record.event_id!r} has {record.n_sections} sections; "
                             f"the model was fitted on {self.n_sections_}")
        return record

    def equations(self, precision: int = 3) -> list[str]:  # pragma: no cover - subclasses implement
        """One string per equation (subclasses implement)."""
        raise NotImplementedError

    def print(self, precision: int = 3, file=None) -> None:
        """Print :meth:`equations`, one per line (pysindy's ``print``)."""
        for line in self.equations(precision=precision):
            print(line, file=file)


def section_names(n_sections: int) -> list[str]:
    """Names of the sections' equations, ``["S1", ..., "S<n>"]``."""
    return [f"S{k + 1}" for k in range(n_sections)]


def as_record(item, index: int = 0) -> Record:
    """A :class:`Record` from a record or a legacy ``(t, A, U, dA)`` tuple (event id ``"record<index>"``)."""
    if isinstance(item, Record):
        return item
    try:
        t, A, U, dA = item
    except (TypeError, ValueError):
        raise TypeError(f"record {index} must be a Record or a (t, A, U, dA) tuple; got {type(item).__name__}") from None
    return Record(event_id=f"record{index}", t=t, A=A, U=U, dA=dA)


def fit_records(records, *, need_dA: bool = True, why: str = "needed to fit") -> list[Record]:
    """The records a model is fitted on, checked: at least one, all with one number of sections (and dA).

    Parameters
    ----------
    records : sequence of Record (or legacy ``(t, A, U, dA)`` tuples, :func:`as_record`)
    need_dA : bool
        Refuse a record without dA.
    why : str
        Said in that refusal, after "has no dA".

    Returns
    -------
    list of Record

    Raises
    ------
    ValueError
        No record; a record with another number of sections than the first; a record without dA
        (with ``need_dA``).
    """
    records = [as_record(r, k) for k, r in enumerate(records)]
    if not records:
        raise ValueError("no records to fit")
    S = records[0].n_sections
    for rec in records:
        if rec.n_sections != S:
            raise ValueError(f"record {rec.event_id!r} has {rec.n_sections} sections, the first record {S}")
        if need_dA and rec.dA is None:
            raise ValueError(f"record {rec.event_id!r} has no dA ({why})")
    return records


def coef_order_contributions(A: np.ndarray, U: np.ndarray, coef: np.ndarray) -> np.ndarray:
    """Order contributions of a model on the physical library.

    Parameters
    ----------
    A, U : ndarray, shape (n, S), m and m/s
    coef : ndarray, shape (S, 23 S) or (n, S, 23 S)
        Coefficients on :func:`vivbench.core.terms.evaluate_library` (one model,
        or one per sample); dA/dt in m/s.

    Returns
    -------
    r : ndarray, shape (n, S, 4), m/s
        r[:, k, i] = sum over the order-i columns of Theta * coef; NaN where A
        or U is not finite or the coefficients are NaN.
    """
    theta = evaluate_library(A, U)
    coef = np.asarray(coef, dtype=float)
    S = A.shape[1]
    if coef.shape[-2:] != (S, 23 * S) or coef.ndim not in (2, 3):
        raise ValueError(f"coef must have shape ({S}, {23 * S}) or (n, {S}, {23 * S}); got {coef.shape}")
    orders = np.tile(section_exponents()[:, 0], S)
    r = np.empty(A.shape + (4,))
    for i in range(4):  # four orders, each one matrix product over all samples
        cols = orders == i
        if coef.ndim == 2:
            r[..., i] = theta[:, cols] @ coef[:, cols].T
        else:
            r[..., i] = np.einsum("nc,nkc->nk", theta[:, cols], coef[:, :, cols])
    return r


def _number(x: float, precision: int) -> str:
    mant, _, exp = f"{x:.{max(precision - 1, 0)}e}".partition("e")
    e = int(exp)
    return mant if e == 0 else f"{mant}e{e}"


def format_equations(coef: np.ndarray, feature_names: Sequence[str], lhs: Sequence[str],
                     precision: int = 3) -> list[str]:
    """pysindy-like equation strings, e.g. ``"dA1/dt = 1.20e-3 A1 - 4.00e-2 A1 U1^2"``.

    Parameters
    ----------
    coef : ndarray, shape (S, p), physical coefficients
    feature_names : sequence of str, length p
    lhs : sequence of str, length S (e.g. ``"dA1/dt"``)
    precision : int
        Significant digits of each coefficient.

    Returns
    -------
    list of str
        Terms with a zero coefficient are omitted; an all-zero equation reads
        ``"... = 0"``, one without a model (NaN) ``"... = nan"``.
    """
    coef = np.asarray(coef, dtype=float)
    out = []
    for name, row in zip(lhs, coef):
        if not np.all(np.isfinite(row)):
            out.append(f"{name} = nan")
            continue
        parts = []
        for c, feat in zip(row, feature_names):
            if c == 0:
                continue
            num = _number(abs(c), precision)
            if not parts:
                parts.append(("-" if c < 0 else "") + f"{num} {feat}")
            else:
                parts.append(("- " if c < 0 else "+ ") + f"{num} {feat}")
        out.append(f"{name} = " + (" ".join(parts) if parts else "0"))
    return out


def simulate_windows(record: Record, coef: np.ndarray, window_start, window_end, *, t0: float | None = None,
                     t1: float | None = None, A0=None, **kwargs) -> Simulation:
    """Integrate piecewise-constant models over a record with :func:`vivbench.models.simulate.simulate_identified`.

    Parameters
    ----------
    record : Record
    coef : ndarray, shape (W, S, 23 S)
        Physical coefficients of each window (W = 1 with one window spanning
        the record for a time-invariant model).
    window_start, window_end : ndarray, shape (W,), s
        The window in force at a time is the fitted window with the nearest centre.
    t0, t1 : float, s, optional
        Span (snapped to the record's samples); default the windows' span.
    A0 : array_like, shape (S,), m, optional
        Initial amplitudes; default the record's A at t0.
    **kwargs
        ``u_interp``, ``bound_factor``, ``negative_tolerance``, ``clip`` of
        :func:`~vivbench.models.simulate.simulate_identified`.

    Returns
    -------
    Simulation
        With S columns; ``A_meas`` is the record's A (not ``A0``).

    """
    coef = np.asarray(coef, dtype=float)
    S = record.n_sections
    t = record.t
    A = np.array(record.A, dtype=float)
    U = np.array(record.U, dtype=float)
    start = np.asarray(window_start, dtype=float)
    end = np.asarray(window_end, dtype=float)
    fitted = np.all(np.isfinite(coef), axis=(1, 2))
    t0 = float(start[fitted].min()) if t0 is None and fitted.any() else t0
    t1 = float(min(end[fitted].max(), t[-1])) if t1 is None and fitted.any() else t1
    if A0 is not None:
        A0 = np.asarray(A0, dtype=float)
        if A0.shape != (S,):
            raise ValueError(f"A0 must have shape ({S},) (one amplitude per section, m); got {A0.shape}")
        i0 = int(np.argmin(np.abs(t - float(t0)))) if t0 is not None else 0
        A[i0, :S] = A0
    ds = xr.Dataset(
        {"A": (("time", "equation"), A), "U": (("time", "equation"), U),
         "coef": (("window", "equation", "feature"), coef),
         "window_start": (("window",), start), "window_end": (("window",), end)},
        coords={"time": t, "equation": section_names(S)},
    )
    sim = simulate_identified(ds, t0=t0, t1=t1, **kwargs)
    i0 = int(np.searchsorted(t, sim.t[0]))
    A_meas = record.A[i0:i0 + sim.t.size]
    return dataclasses.replace(sim, A_meas=A_meas, nmse=nmse(sim.A_sim, A_meas))


#: The ``identifiable`` variable's long name for a model without its own (``campaign_summary``'s ``verdicts``).
IDENTIFIABLE_LONG_NAME = "the model's own verdict (window_verdicts) and the amplitude above the noise floor"


def model_class_path(model) -> str:
    """``"module:QualifiedName"`` of the model's class: how a file names a model's class for loading it again."""
    cls = type(model)
    return f"{cls.__module__}:{cls.__qualname__}"


def model_summary(model) -> dict:
    """What a fitted campaign model writes into ``campaign.regimes.nc`` besides the windows' regimes.

    Parameters
    ----------
    model : fitted campaign model
        Its ``campaign_summary()`` when it has one, else the default below.

    Returns
    -------
    dict
        ``variables`` (name -> (dims, values, attrs)) over the dimensions
        ``equation`` and those of ``coords``; ``coords`` (name -> values);
        ``attrs`` (file attributes, e.g. ``model``, ``model_config_json``,
        ``note``); ``verdicts`` (name -> long name) of the per-window
        verdict outputs written as int8 flags (at least ``identifiable``).
        The default: no variable, the attributes ``model`` (the class name),
        ``model_class`` (:func:`model_class_path`, which
        :func:`vivbench.analysis.load_campaign_model` imports to load the
        model's file) and ``model_config_json`` (``get_params()`` as JSON, or
        ``{}``).
    """
    own = getattr(model, "campaign_summary", None)
    if callable(own):
        return own()
    params = model.get_params() if callable(getattr(model, "get_params", None)) else {}
    return {"variables": {}, "coords": {},
            "attrs": {"model": type(model).__name__, "model_class": model_class_path(model),
                      "model_config_json": json.dumps(params, sort_keys=True, default=str)},
            "verdicts": {"identifiable": IDENTIFIABLE_LONG_NAME}}


def model_size(model) -> list[int]:
    """Terms (or basis functions) per equation: ``model.terms_per_equation()``, or ``[]`` without it."""
    own = getattr(model, "terms_per_equation", None)
    return [int(k) for k in own()] if callable(own) else []


def model_for_records(model, records):
    """The model to fit on ``records``: ``model.for_records(records)`` (which may refuse them with an
    InputError, or give a narrower model, e.g. without a covariate the records lack), else the model."""
    own = getattr(model, "for_records", None)
    return own(records) if callable(own) else model


def model_change_inputs(model, records) -> dict | None:
    """Inputs of the model change scan (:func:`vivbench.analysis.changes.statistics_change_scan`).

    Returns
    -------
    dict or None
        ``model.event_change_inputs(records)``: ``statistics`` (the per-event
        sufficient statistics of its penalised regressions), ``a_ref`` and
        ``y_scale`` (the fit's amplitude and dA/dt scales); None for a model
        without them (no model change scan).
    """
    own = getattr(model, "event_change_inputs", None)
    return own(records) if callable(own) else None


def recorded_change_scan(model) -> dict | None:
    """The change scan a model ran on its own records when it was fitted, or None.

    ``model.recorded_change_scan()`` when the model has it (a
    :class:`vivbench.analysis.ModelSelection` that scanned its chosen model): a dict with
    ``events`` (the event ids scanned, in order), ``seed``, ``inputs``
    (:func:`model_change_inputs` on the records' wind as at fit) and ``scan``
    (:func:`vivbench.analysis.changes.statistics_change_scan` of them at ``seed``).
    """
    own = getattr(model, "recorded_change_scan", None)
    return own() if callable(own) else None


def simulate_many(model, runs: Sequence[tuple]) -> list:
    """Simulations of several spans, ``runs`` a sequence of (record, t0, t1, A0) (A0 None: the record's A at t0).

    ``model.simulate_runs(runs)`` when the model has it (one batched integration, e.g.
    :meth:`vivbench.models.VaryingCoefficientSINDy.simulate_runs`), else ``model.simulate`` of each run.

    Returns
    -------
    list of Simulation, one per run, in order
    """
    own = getattr(model, "simulate_runs", None)
    if callable(own):
        return list(own(list(runs)))
    return [model.simulate(r, t0, t1) if A0 is None else model.simulate(r, t0, t1, A0) for r, t0, t1, A0 in runs]


def transforms_wind(model) -> bool:
    """Whether the model transforms a measured record's wind itself (it has ``measured_wind(record)``)."""
    return callable(getattr(model, "measured_wind", None))


def model_curves(model, wind):
    """The model's coefficient curves on ``wind`` (its ``curves(wind)``), or None when it gives none.

    A model without ``curves``, or whose ``curves`` raises :class:`NotFittedError`
    (e.g. a model rebuilt from a file that holds no curves), gives None.
    """
    own = getattr(model, "curves", None)
    if not callable(own):
        return None
    try:
        return own(wind)
    except NotFittedError:
        return None


def model_description(model, regimes) -> dict:
    """The report's account of a campaign model: ``model.report_description(regimes)`` or the default.

    Parameters
    ----------
    model : fitted campaign model
    regimes : xarray.Dataset, its ``campaign.regimes.nc``

    Returns
    -------
    dict
        ``text``, a Markdown paragraph on the model and its verdict, and
        ``pool_options``, the options of ``vivbench pool`` that fit it
        (default: ``--model module:Class``, the class called without
        arguments as the factory).
    """
    own = getattr(model, "report_description", None)
    if callable(own):
        return own(regimes)
    coverage = float(regimes.attrs.get("coverage", float("nan")))
    text = (f"A campaign model of the protocol, `{type(model).__name__}` (`{model_class_path(model)}`), fitted to "
            "every event. A window's regime and its identifiability verdict are the model's own "
            f"(its `window_verdicts`, or the regime rule on its order contributions); coverage {coverage:.3f}.")
    return {"text": text, "pool_options": f" --model {model_class_path(model)}"}


def chosen_model(fitted):
    """The model a fitted wrapper stands for (a verdict wrapper's model, a selection's chosen one), unwrapped
    through every ``chosen_model()``; a model without that method is its own."""
    own = getattr(fitted, "chosen_model", None)
    return fitted if not callable(own) else chosen_model(own())


def model_evidence(fitted) -> dict | None:
    """The held-out evidence of a model chosen from the campaign's data (``evidence()``, JSON-ready), or None."""
    own = getattr(fitted, "evidence", None)
    return own() if callable(own) else None


def model_settings_text(fitted) -> str:
    """One line on a fitted campaign model's settings for the command line (``settings_text()``), or by default
    its class's name and :func:`model_size` (e.g. ``"PooledSINDy, size per equation 3, 4"``)."""
    own = getattr(fitted, "settings_text", None)
    if callable(own):
        return str(own())
    size = model_size(fitted)
    return type(fitted).__name__ + (f", size per equation {', '.join(map(str, size))}" if size else "")
