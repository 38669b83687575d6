"""Methods as plug-ins (docs/methods.md): resolve a method by name, fit it, score it against the truth.

A *method* is any object with ``fit(records) -> fitted``; the fitted model
gives ``order_contributions(record)`` (n_samples, n_sections, 4) in m/s and
may give ``identifiable(record, window_start, window_end)`` -> bool
(n_windows, n_sections), ``predict(record)``, ``simulate(record, t0, t1)``
and ``curves(wind)``. Records are :class:`vivbench.core.Record` (``event_id``,
``t`` in s, ``A`` in m, ``U`` in m/s, ``dA`` in m/s, (n_samples, n_sections));
:func:`vivbench.analysis.records_from_results` reads them from identification
results.

API (stable; the leaderboard builds on it)::

    resolve_method(spec: str) -> method
        spec: "windows" | "pooled" | "varying" | "pysindy-cp" | "binned" | "package.module:factory"
    fit_method(method, records) -> (fitted, fit_time_s)
    score_fitted(fitted, records, truths, *, windows=None, window=50.0, step=25.0,
                 tau=0.2, active_share=0.1, fit_time_s=nan, simulate=True) -> dict
    score_method(method, records, truths, **same keywords) -> dict   # fit_method, then score_fitted
    default_windows(record, window=50.0, step=25.0) -> (start, end)
    scoring_inputs(event_files, result_files, *, derivative=CAMPAIGN_DERIVATIVE) -> (records, truths, windows)
    simulation_nmse(fitted, records) -> (nmse, covered)

``truths`` are the events' ``/truth`` groups (xarray.Dataset with ``time``,
``A``, ``U``, ``r``, optionally ``coef`` and ``curves``), one per record, in
the records' order. ``windows`` is one ``(window_start, window_end)`` pair of
arrays (s) per record, e.g. the identification result's windows; None gives
:func:`default_windows` (the 50 s / 25 s windows of the chain, over each run of
valid samples). The scores (:data:`SCORE_KEYS`), the same for built-in and
plug-in methods:

- ``coverage``: share of window-equations flagged identifiable (0 for a model
  without ``identifiable``); ``accuracy_identifiable`` (NaN if none flagged),
  ``accuracy_not_identifiable``, ``accuracy_all``: regime accuracy by the rule
  of docs/concepts.md (regimes) applied to the model's order contributions over the window's
  record samples (:func:`vivbench.regimes.model_window_regimes`) against the
  truth's over its own samples (:func:`vivbench.regimes.truth.truth_window_regimes`),
  with :func:`vivbench.validate.regime_scores` (window-equations where both
  have a regime); ``n_scored``; ``truth_majority_share`` and
  ``truth_share_regime1..4`` over the scored window-equations; ``no_model_share``
  (window-equations without a model regime).
- ``rhs_error_true_AU_median`` and ``..._active``: median relative RMS error of
  the model's dA/dt (``predict``, or the sum of the order contributions) on the
  truth's own (A, U) against the truth's dA/dt, per window
  (:func:`vivbench.validate.model_window_rhs_errors_true_AU`);
  ``rhs_error_true_AU_energy``: the same error energy-weighted over every sample
  of every record, sqrt(sum (f_model - f_true)^2 / sum f_true^2)
  (:func:`vivbench.validate.metrics.energy_relative_error`): the median hides
  the large-amplitude phases, this does not;
  ``rhs_median_rel_error`` and ``..._active``: on the record's measured (A, U)
  against the exact coefficient matrix (in-library truths; NaN otherwise).
- ``curve_error_linear``, ``curve_error_total``: the model's ``curves`` against
  the truth's (:func:`vivbench.validate.curve_errors`, reference section; NaN
  without ``curves`` or when the truth's curves differ between events);
  ``curve_error_energy``: the dA/dt the curves give at the truth's (A, U) of
  every sample and equation, sum_i a_ki(U_k) A_k^i, against the same sum with
  the truth's curves, energy-weighted
  (:func:`vivbench.validate.metrics.curve_energy_error`; NaN where the other
  two are). Against the truth's dA/dt itself the curves would also be charged
  with what no curve of one wind carries (sections at different winds, the
  yaw), an error the truth's own curves would score too. All three use the curves only at winds inside each
  equation's fitted data (:func:`vivbench.models.data_wind_range`): the
  extrapolated parts are not scored.
- ``simulation_nmse``: median over records and sections of the NMSE of
  ``simulate`` over each record's longest run of valid samples, over the part
  simulated before the run stopped; ``simulation_covered``: median share of
  the run simulated (NaN without ``simulate``).
- ``fit_time_s``: wall time of ``fit``.

Built-in methods go through the same functions. Two hooks keep the built-in
window SINDy's scores those of the identification chain: a fitted model may
give ``window_regimes(record, window_start, window_end)`` -> int (W, S), its
own regime of each window (window SINDy: the regime of the window's own
model; otherwise the rule on the order contributions, in which overlapping
windows' models mix), and ``identifiable``. The identification's
noise-floor test (``min_snr``) needs the preprocessing's noise level: records
read from identification results carry it (``Record.noise_std``), and the
built-in verdicts apply it (:func:`above_noise_floor`); records without it are
not tested.
"""

from __future__ import annotations

import importlib
import math
import re
import time
from collections.abc import Sequence

import numpy as np

from vivbench.analysis.pool import CAMPAIGN_DERIVATIVE, records_from_results
from vivbench.core.errors import InputError
from vivbench.core.record import Record
from vivbench.core.regime import DEFAULT_TAU
from vivbench.models.model_input import measured_input
from vivbench.preprocess.runs import mask_runs
from vivbench.regimes.model import model_verdicts, model_window_regimes
from vivbench.regimes.truth import truth_window_regimes
from vivbench.validate.metrics import curve_energy_error, curve_errors, curves_rhs, energy_relative_error
from vivbench.validate.recovery import (finite_median, model_window_rhs_errors, model_window_rhs_true_AU,
                                       record_yaw_on, regime_scores)

__all__ = ["BUILTIN_METHODS", "RENAMED_METHODS", "SCORE_KEYS", "resolve_method", "check_method_spec", "fit_method", "score_fitted", "curve_scores",
           "score_method", "scoring_inputs", "default_windows", "simulation_nmse", "above_noise_floor", "WindowMethod",
           "CampaignMethod", "SelectedVerdictModel",
           "FittedWindows", "VerdictModel", "MeasuredWindVerdictModel"]

#: Names of the built-in methods.
BUILTIN_METHODS = ("windows", "pooled", "varying", "pysindy-cp", "binned")

#: Former names of built-in methods, refused with the current name.
RENAMED_METHODS = {"campaign": "pooled"}

#: The keys of :func:`score_fitted`'s dict, in table order.
SCORE_KEYS = ("n_scored", "truth_majority_share", "truth_share_regime1", "truth_share_regime2", "truth_share_regime3",
              "truth_share_regime4", "coverage", "accuracy_all", "accuracy_identifiable", "accuracy_not_identifiable",
              "no_model_share", "rhs_median_rel_error", "rhs_median_rel_error_active", "rhs_error_true_AU_median",
              "rhs_error_true_AU_median_active", "rhs_error_true_AU_energy", "curve_error_linear", "curve_error_total",
              "curve_error_energy", "simulation_nmse", "simulation_covered", "fit_time_s")

_SPEC = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*(\.[A-Za-z_][A-Za-z0-9_]*)*:[A-Za-z_][A-Za-z0-9_]*$")


# -- built-in methods -----------------------------------------------------------------------------------------


class VerdictModel:
    """A fitted campaign-level model with the ``identifiable`` of the protocol from a verdict function.

    Every other attribute (``order_contributions``, ``predict``, ``simulate``, ``curves``, ...) is the
    wrapped model's.
    """

    def __init__(self, model, verdict):
        self.model = model
        self._verdict = verdict

    def __getattr__(self, name):
        if name == "model" or "model" not in self.__dict__:  # unpickling: no wrapped model yet
            raise AttributeError(name)
        return getattr(self.__dict__["model"], name)

    def chosen_model(self):
        """The wrapped model (:func:`vivbench.models.chosen_model`)."""
        return self.model

    def identifiable(self, record: Record, window_start, window_end) -> np.ndarray:
        """Bool (W, S): the model's regime of the window is identifiable (its verdict of docs/concepts.md (regimes)).

        Also needs the window's mean amplitude above the record's noise floor
        (:func:`above_noise_floor`), as ``vivbench pool`` does.
        """
        ok = np.asarray(self._verdict(self.model, record, window_start, window_end)["identifiable"], dtype=bool)
        return ok & above_noise_floor(record, window_start, window_end)


class MeasuredWindVerdictModel(VerdictModel):
    """A :class:`VerdictModel` whose model is evaluated on measured records through :func:`vivbench.models.measured_input`.

    The varying model is fitted on the measured wind smoothed (its ``wind_smoothing_s``): its
    verdict, window regimes and simulations of a measured record use that wind too, as
    ``vivbench pool`` does, while ``predict`` and ``order_contributions`` take a record's wind
    as given (the truth's own wind, for the dA/dt error on the true (A, U)).
    """

    def __init__(self, model, verdict):
        super().__init__(model, verdict)
        self._last = None  # (record, windows, verdict): identifiable and window_regimes ask for the same in turn

    def _measured_verdict(self, record: Record, window_start, window_end) -> dict:
        start = np.atleast_1d(np.asarray(window_start, dtype=float))
        end = np.atleast_1d(np.asarray(window_end, dtype=float))
        key = (start.tobytes(), end.tobytes())
        # The record itself is kept with the verdict (identity, not equality: records compare by identity).
        if self._last is None or self._last[0] is not record or self._last[1] != key:
            self._last = (record, key, self._verdict(self.model, measured_input(self.model, record), start, end))
        return self._last[2]

    def identifiable(self, record: Record, window_start, window_end) -> np.ndarray:
        """Bool (W, S): the verdict on the measured record, and the window above the noise floor."""
        ok = np.asarray(self._measured_verdict(record, window_start, window_end)["identifiable"], dtype=bool)
        return ok & above_noise_floor(record, window_start, window_end)

    def window_regimes(self, record: Record, window_start, window_end) -> np.ndarray:
        """Int (W, S): the model's regime of each window of the measured record (the verdict's point regimes)."""
        return np.asarray(self._measured_verdict(record, window_start, window_end)["regime"], dtype=int)

    def simulate(self, record: Record, *args, **kwargs):
        """The model's ``simulate`` on the measured record's wind as the model was fitted on it."""
        return self.model.simulate(measured_input(self.model, record), *args, **kwargs)


def above_noise_floor(record: Record, window_start, window_end, min_snr: float | None = None) -> np.ndarray:
    """Bool (W, S): the window's mean amplitude is at least ``min_snr`` times the record's noise floor.

    The identification's noise-floor test (:mod:`vivbench.preprocess.noise_floor`): below it A is the
    envelope of noise and no model can give the window's regime. True where the floor is unknown
    (``record.noise_std`` None or NaN) or the window has no valid sample. ``min_snr`` None: the
    identification's default (``IdentifyConfig().min_snr``).
    """
    from vivbench.analysis.identify import IdentifyConfig
    from vivbench.preprocess.noise_floor import window_amplitude_snr

    start = np.atleast_1d(np.asarray(window_start, dtype=float))
    end = np.atleast_1d(np.asarray(window_end, dtype=float))
    if min_snr is None:
        min_snr = IdentifyConfig().min_snr
    if record.noise_std is None or min_snr is None:
        return np.ones((start.size, record.n_sections), dtype=bool)
    snr = window_amplitude_snr(record.t, record.A, start, end, record.noise_std)
    return ~(snr < min_snr)  # NaN (unknown) passes


class CampaignMethod:
    """A built-in campaign model (``PooledSINDy`` or ``VaryingCoefficientSINDy``) as a method with its verdict.

    Parameters
    ----------
    kind : {"pooled", "varying"}
        The method name: ``"pooled"`` (PooledSINDy) or ``"varying"`` (VaryingCoefficientSINDy).
    **params : the model's parameters (defaults: those of ``vivbench pool``)
    """

    def __init__(self, kind: str = "pooled", **params):
        if kind not in ("pooled", "varying"):
            raise ValueError(f"kind must be 'pooled' or 'varying'; got {kind!r}")
        self.kind = kind
        self.params = params

    def __repr__(self) -> str:
        return f"CampaignMethod({self.kind!r}{''.join(f', {k}={v!r}' for k, v in self.params.items())})"

    def fit(self, records: Sequence[Record]) -> VerdictModel:
        from vivbench.analysis.selection import varying_selection, without_yaw
        from vivbench.models.campaign import PooledSINDy

        if self.kind == "pooled":
            return VerdictModel(PooledSINDy(**self.params).fit(records), model_verdicts)
        # The options not given in params are chosen from the records' held-out evidence, as by vivbench pool.
        params = dict(self.params)
        selection_keys = ("n_folds", "criterion", "n_perturbations", "perturbation_timescale_s", "workers", "options",
                          "single_section_share")
        sel_params = {k: params.pop(k) for k in selection_keys if k in params}
        selection = varying_selection(**sel_params, **params)
        if any(r.yaw is None for r in records):
            selection = without_yaw(selection)
        return SelectedVerdictModel(selection.fit(records))


class SelectedVerdictModel(VerdictModel):
    """A fitted :class:`vivbench.analysis.ModelSelection` as a method: its own verdict on measured records.

    The selection evaluates measured records on the wind each of its models was fitted on; ``predict``
    and ``order_contributions`` take a record's wind as given (the truth's own wind).
    """

    def __init__(self, model):
        super().__init__(model, None)

    def identifiable(self, record: Record, window_start, window_end) -> np.ndarray:
        """Bool (W, S): the selection's verdict, and the window above the noise floor."""
        ok = np.asarray(self.model.identifiable(record, window_start, window_end), dtype=bool)
        return ok & above_noise_floor(record, window_start, window_end)

    def window_regimes(self, record: Record, window_start, window_end) -> np.ndarray:
        """Int (W, S): the chosen model's regime of each window of the measured record."""
        return np.asarray(self.model.window_regimes(record, window_start, window_end), dtype=int)

    def simulate(self, record: Record, *args, **kwargs):
        """The chosen model's ``simulate`` on the measured record's wind as it was fitted on it."""
        return self.model.simulate(measured_input(self.model, record), *args, **kwargs)


class FittedWindows:
    """Window SINDy fitted per run of valid samples, with each window's own regime and identifiability verdict.

    Built by :class:`WindowMethod` (``fit``) or :meth:`from_results` (identification results).
    ``model`` is the :class:`vivbench.models.WindowSINDy` of the protocol (order contributions,
    predictions and simulations with the window in force, the one with the nearest centre);
    ``window_regimes`` and ``identifiable`` give, for a scoring window that is one of the fitted
    windows (same start and end within 1e-6 s), that window's own regime and verdict, as the
    identification chain labels it; for other windows, the rule on the order contributions and
    not identifiable.
    """

    def __init__(self, model, regimes: dict, flags: dict, starts: dict):
        self.model = model
        self._regimes, self._flags, self._starts = regimes, flags, starts

    def __getattr__(self, name):
        if name == "model" or "model" not in self.__dict__:  # unpickling: no wrapped model yet
            raise AttributeError(name)
        return getattr(self.__dict__["model"], name)

    def order_contributions(self, record: Record) -> np.ndarray:
        return self.model.order_contributions(record)

    def _match(self, record: Record, window_start, window_end):
        s = np.atleast_1d(np.asarray(window_start, dtype=float))
        e = np.atleast_1d(np.asarray(window_end, dtype=float))
        fs, fe = self._starts.get(record.event_id, (np.empty(0), np.empty(0)))
        if fs.size == 0:
            return np.full(s.size, -1)
        k = np.argmin(np.abs(s[:, None] - fs[None]), axis=1)
        same = (np.abs(fs[k] - s) < 1e-6) & (np.abs(fe[k] - e) < 1e-6)
        return np.where(same, k, -1)

    def window_regimes(self, record: Record, window_start, window_end, tau: float = DEFAULT_TAU) -> np.ndarray:
        k = self._match(record, window_start, window_end)
        rule = model_window_regimes(self.model, record, window_start, window_end, tau=tau)["regime"]
        if record.event_id not in self._regimes:
            return rule
        own = self._regimes[record.event_id]
        return np.where((k >= 0)[:, None], own[np.maximum(k, 0)], rule).astype(np.int8)

    def identifiable(self, record: Record, window_start, window_end) -> np.ndarray:
        k = self._match(record, window_start, window_end)
        if record.event_id not in self._flags:
            return np.zeros((k.size, record.n_sections), dtype=bool)
        return (k >= 0)[:, None] & self._flags[record.event_id][np.maximum(k, 0)]

    @classmethod
    def from_results(cls, results: Sequence) -> "FittedWindows":
        """The window models, regimes and verdicts of identification results (``xarray.Dataset`` each)."""
        from vivbench.models.window_model import WindowSINDy

        if not results:
            raise ValueError("no identification results")
        parts = [WindowSINDy.from_result(r) for r in results]
        model = parts[0]
        ids = [p.event_ids_[0] for p in parts]
        model.event_ids_ = ids
        model.window_event_ = np.concatenate([np.full(p.coef_.shape[0], k) for k, p in enumerate(parts)])
        for name in ("coef_", "window_start_", "window_end_", "threshold_", "n_terms_", "rss_", "aicc_"):
            setattr(model, name, np.concatenate([getattr(p, name) for p in parts]))
        regimes = {i: r["regime"].values.astype(np.int8) for i, r in zip(ids, results)}
        flags = {i: r["identifiable"].values.astype(bool) for i, r in zip(ids, results)}
        starts = {i: (r["window_start"].values, r["window_end"].values) for i, r in zip(ids, results)}
        return cls(model, regimes, flags, starts)


class WindowMethod:
    """The paper's window SINDy as a method: the identification's estimator and verdicts on each record.

    Each record is split into runs of valid samples (A, U, dA finite) at least one window long;
    on each run dA/dt is differentiated again from A with the configuration's derivative (as
    :func:`vivbench.analysis.identify_event` does, whatever dA/dt the records carry) and the chain's
    estimator is fitted with :func:`vivbench.regimes.window.label_windows` (the competitor-based
    identifiability verdict).

    Parameters
    ----------
    config : vivbench.analysis.identify.IdentifyConfig, optional
        Window, step, thresholds, scaling, optimiser, tau and verdict settings (default: the chain's).
    """

    def __init__(self, config=None):
        self.config = config

    def __repr__(self) -> str:
        return "WindowMethod()" if self.config is None else f"WindowMethod(window={self.config.window})"

    def fit(self, records: Sequence[Record]) -> FittedWindows:
        from vivbench.analysis.identify import IdentifyConfig
        from vivbench.models.window_model import WindowSINDy
        from vivbench.regimes.window import label_windows

        cfg = self.config or IdentifyConfig()
        coefs, starts, ends, events, regimes, flags, bounds, ids = [], [], [], [], {}, {}, {}, []
        S = records[0].n_sections if records else 0
        est = None
        for k, rec in enumerate(records):
            ids.append(rec.event_id)
            reg_e, ok_e, s_e, e_e = [], [], [], []
            for run in mask_runs(rec.valid(need_dA=True), rec.t):
                t = rec.t[run]
                if t.size < 2 or t[-1] - t[0] < cfg.window:
                    continue
                est = cfg.estimator()
                dA = cfg.derivative.differentiate(rec.A[run], t)
                v = label_windows(est, t, rec.A[run], rec.U[run], dA, tau=cfg.tau, margin=cfg.aicc_margin,
                                  fit_tolerance=cfg.fit_tolerance)
                coefs.append(est.coef_)
                s_e.append(est.window_start_)
                e_e.append(est.window_end_)
                events.append(np.full(est.window_start_.size, k))
                reg_e.append(v["regime"])
                floor = above_noise_floor(rec, est.window_start_, est.window_end_, cfg.min_snr)
                ok_e.append(np.asarray(v["identifiable"], dtype=bool) & floor)
            if s_e:
                starts += s_e
                ends += e_e
                regimes[rec.event_id] = np.concatenate(reg_e)
                flags[rec.event_id] = np.concatenate(ok_e)
                bounds[rec.event_id] = (np.concatenate(s_e), np.concatenate(e_e))
        if est is None:
            raise ValueError(f"no run of valid samples is as long as one window ({cfg.window:g} s)")
        model = WindowSINDy(**{k: v for k, v in est.get_params().items() if k in WindowSINDy._param_names()})
        model.coef_ = np.concatenate(coefs)
        model.window_start_ = np.concatenate(starts)
        model.window_end_ = np.concatenate(ends)
        model.window_event_ = np.concatenate(events)
        model.event_ids_ = ids
        model.n_sections_ = S
        model.feature_names_ = est.feature_names_
        return FittedWindows(model, regimes, flags, bounds)


def check_method_spec(spec) -> str:
    """The spec if it is a built-in name or has the form ``package.module:factory``; InputError otherwise."""
    if isinstance(spec, str) and spec in RENAMED_METHODS:
        raise InputError(f"method {spec!r} is now named {RENAMED_METHODS[spec]!r}")
    if not isinstance(spec, str) or not (spec in BUILTIN_METHODS or _SPEC.match(spec)):
        raise InputError(f"method {spec!r} is not one of {', '.join(BUILTIN_METHODS)} nor of the form "
                         "'package.module:factory'")
    return spec


def resolve_method(spec: str):
    """The method named by ``spec``.

    Parameters
    ----------
    spec : str
        ``"windows"`` (:class:`WindowMethod`: the paper's window SINDy with the chain's verdict),
        ``"pooled"`` (:class:`CampaignMethod`: ``PooledSINDy`` with its bootstrap and
        confidence-region verdict), ``"varying"`` (``VaryingCoefficientSINDy`` with its own defaults,
        those of ``vivbench pool --model varying``: the yaw covariate when the records carry the
        yaw, 30 s wind smoothing; bootstrap and confidence-set verdict), ``"pysindy-cp"``
        (:class:`vivbench.models.PySINDyCP`, no verdict),
        ``"binned"`` (:class:`vivbench.models.BinnedPolynomial`: per 0.5 m/s bin of mean wind, dA_k/dt
        on [1, A_k, A_k^2, A_k^3] by least squares; no verdict; the floor to beat), or
        ``"package.module:factory"``: the module is imported and ``factory()`` called with no
        arguments; it must return an object with a callable ``fit``.

    Returns
    -------
    method : an object with ``fit(records)``

    Raises
    ------
    InputError
        One line naming the spec and what is wrong (bad form, module not importable, no such
        factory, factory failed, result without ``fit``).
    """
    check_method_spec(spec)
    if spec == "windows":
        return WindowMethod()
    if spec in ("pooled", "varying"):
        return CampaignMethod(spec)
    if spec == "pysindy-cp":
        from vivbench.models.pysindy_adapter import PySINDyCP

        return PySINDyCP()
    if spec == "binned":
        from vivbench.models.binned import BinnedPolynomial

        return BinnedPolynomial()
    module_name, _, attr = spec.partition(":")
    try:
        module = importlib.import_module(module_name)
    except ImportError as exc:
        raise InputError(f"method {spec!r}: cannot import module {module_name!r} ({exc}); is it on PYTHONPATH?") from None
    factory = getattr(module, attr, None)
    if factory is None or not callable(factory):
        raise InputError(f"method {spec!r}: module {module_name!r} has no callable {attr!r}")
    try:
        method = factory()
    except Exception as exc:
        raise InputError(f"method {spec!r}: {attr}() failed: {type(exc).__name__}: {exc}") from None
    if not callable(getattr(method, "fit", None)):
        raise InputError(f"method {spec!r}: {attr}() returned a {type(method).__name__}, which has no fit(records) "
                         "method")
    return method


# -- scoring ----------------------------------------------------------------------------------------------


def default_windows(record: Record, window: float = 50.0, step: float = 25.0) -> tuple[np.ndarray, np.ndarray]:
    """Sliding windows (``window`` s wide, every ``step`` s) over each run of the record's valid samples.

    A, U (and dA when the record has it) finite; runs shorter than one window have none. The
    windows of :func:`vivbench.preprocess.windows.window_bounds`, as the chain places them per segment.

    Returns
    -------
    window_start, window_end : ndarray, shape (W,), s
    """
    from vivbench.preprocess.windows import window_bounds

    ok = record.valid(need_dA=record.dA is not None)
    starts, ends = [], []
    for run in mask_runs(ok, record.t):
        t = record.t[run]
        if t.size < 2 or t[-1] - t[0] < window:
            continue
        s, e, _first, _stop = window_bounds(t, window, step)
        starts.append(s)
        ends.append(e)
    if not starts:
        return np.empty(0), np.empty(0)
    return np.concatenate(starts), np.concatenate(ends)


class _SumPredict:
    """``predict`` as the sum of the order contributions, for models that give only those."""

    def __init__(self, model):
        self.model = model

    def predict(self, record):
        return np.asarray(self.model.order_contributions(record), dtype=float).sum(axis=-1)


def _longest_run(record: Record) -> slice | None:
    runs = mask_runs(record.valid(), record.t)
    if not runs:
        return None
    return max(runs, key=lambda s: s.stop - s.start)


def simulation_nmse(fitted, records: Sequence[Record]) -> tuple[float, float]:
    """Median NMSE of ``fitted.simulate`` over each record's longest run of valid samples, and the share run.

    Each run starts from the measured A at its first sample and uses the record's wind; the NMSE
    per section is that of :func:`vivbench.models.nmse`, over the part simulated before a run
    stopped (it stops when A leaves the data's range), so read it with the second figure.

    Returns
    -------
    nmse : float, median over records and sections (NaN without ``simulate``)
    covered : float, median over records of the share of the run simulated before a stop
        (the Simulation's ``covered``; NaN without ``simulate``)
    """
    if not callable(getattr(fitted, "simulate", None)):
        return math.nan, math.nan
    values, covered = [], []
    for rec in records:
        run = _longest_run(rec)
        if run is None or run.stop - run.start < 3:
            continue
        sim = fitted.simulate(rec, float(rec.t[run.start]), float(rec.t[run.stop - 1]))
        values.append(np.asarray(sim.nmse, dtype=float).ravel())
        covered.append(float(getattr(sim, "covered", math.nan)))
    if not values:
        return math.nan, math.nan
    return finite_median(np.concatenate(values)), finite_median(np.array(covered))


def curve_scores(fitted, records, truths) -> tuple[float, float, float]:
    """Curve errors of a fitted model: reference section's linear and total, and the energy-weighted one.

    The curves are evaluated on :func:`vivbench.analysis.curve_wind_grid` of the records' wind
    and scored only inside each equation's data range (:func:`vivbench.models.data_wind_range`):
    extrapolated points are left out. The energy-weighted error
    (:func:`vivbench.validate.metrics.curve_energy_error`) compares the dA/dt the model's
    curves give at the truth's (A, U) of every sample with the truth's curves' there. All
    three are NaN when the truth has no single curve.

    Parameters
    ----------
    fitted : a fitted model (``curves(wind)`` of the protocol; NaNs without it)
    records : sequence of Record, the data it was fitted on
    truths : sequence of xarray.Dataset, each record's event ``/truth``, same order

    Returns
    -------
    (linear, total, energy) : floats, relative errors (``curve_error_linear``, ``curve_error_total`` and
    ``curve_error_energy`` of :func:`score_fitted`)
    """
    if not callable(getattr(fitted, "curves", None)):
        return math.nan, math.nan, math.nan
    from vivbench.analysis.pool import curve_wind_grid
    from vivbench.core.terms import reference_section
    from vivbench.models.curve_support import curves_inside_data, data_wind_range
    from vivbench.validate.campaign import event_truth_curves

    c = fitted.curves(curve_wind_grid(np.concatenate([r.U.ravel() for r in records])))
    wind_range = data_wind_range(records)
    if c["curves"].shape[0] != records[0].n_sections:
        return math.nan, math.nan, math.nan
    curves = curves_inside_data(c, wind_range)
    wind = c["wind"].values
    tcs = [event_truth_curves(tr) for tr in truths]
    if not tcs or any(tc is None for tc in tcs):
        return math.nan, math.nan, math.nan
    tc0, tw0 = tcs[0]
    if any(tw.shape != tw0.shape or not np.array_equal(tw, tw0) or not np.array_equal(tc, tc0) for tc, tw in tcs[1:]):
        return math.nan, math.nan, math.nan  # slow changes: no single campaign curve to compare with
    U = np.concatenate([tr["U"].values for tr in truths])
    A = np.concatenate([tr["A"].values for tr in truths])
    energy = curve_energy_error(c["curves"].values, wind, U, A, curves_rhs(tc0, tw0, U, A), wind_range)
    excited = np.concatenate([tr["regime"].values >= 2 for tr in truths])
    err = curve_errors(curves, wind, tc0, tw0, U, A, excited)
    k = reference_section(curves.shape[0])
    return float(err["linear"][k]), float(err["total"][k]), energy


def scoring_inputs(event_files: Sequence, result_files: Sequence, *,
                   derivative=CAMPAIGN_DERIVATIVE) -> tuple[list, list, list]:
    """Records, truths and windows of a synthetic campaign's identification, ready for :func:`score_method`.

    The records are those ``vivbench pool`` fits its campaign model on: dA/dt
    recomputed from each result's A with :data:`vivbench.analysis.CAMPAIGN_DERIVATIVE`,
    so that a study scores the model a user gets.

    Parameters
    ----------
    event_files : the events' files (with ``/truth``), in the results' order
    result_files : their ``<event_id>.identify.nc``
    derivative : see :func:`vivbench.analysis.records_from_results`
        (default :data:`~vivbench.analysis.CAMPAIGN_DERIVATIVE`, as ``vivbench pool``; None: the results' own dA)

    Returns
    -------
    records : list of Record
    truths : list of xarray.Dataset (each event's ``/truth``)
    windows : list of (window_start, window_end), the identification's windows (s)
    """
    from vivbench.io.event import read_event
    from vivbench.io.result import read_result

    if len(event_files) != len(result_files):
        raise InputError(f"{len(event_files)} event files but {len(result_files)} results; give one result per event")
    records = records_from_results(result_files, derivative=derivative)
    truths, windows = [], []
    for ev, res_path, rec in zip(event_files, result_files, records):
        tree = read_event(ev)
        if "truth" not in tree.children:
            raise InputError(f"{ev}: no /truth group: a method can be scored only against a synthetic truth")
        if str(tree.attrs.get("event_id", rec.event_id)) != rec.event_id:
            raise InputError(f"{res_path}: its event {rec.event_id} is not the event of {ev}")
        truths.append(tree["truth"].ds)
        res = read_result(res_path, ["window_start", "window_end"])
        windows.append((res["window_start"].values, res["window_end"].values))
    return records, truths, windows


def fit_method(method, records: Sequence[Record]):
    """``method.fit(records)`` and its wall time (s). Returns (fitted, fit_time_s).

    ``fit`` may return the fitted model or None (then the method itself is taken as fitted).
    """
    t0 = time.perf_counter()
    fitted = method.fit(list(records))
    return (method if fitted is None else fitted), time.perf_counter() - t0


def score_fitted(fitted, records: Sequence[Record], truths: Sequence, *, windows=None, window: float = 50.0,
                 step: float = 25.0, tau: float = DEFAULT_TAU, active_share: float = 0.1, fit_time_s: float = math.nan,
                 simulate: bool = True) -> dict:
    """The standard scores of a fitted model against the truths (module docstring, :data:`SCORE_KEYS`).

    Parameters
    ----------
    fitted : an object with ``order_contributions(record)`` (optionally ``identifiable``,
        ``window_regimes``, ``predict``, ``simulate``, ``curves``)
    records : sequence of Record, the data the model is evaluated on (as fitted)
    truths : sequence of xarray.Dataset, each record's event ``/truth``, same order
    windows : sequence of (window_start, window_end), one per record, optional
        Default :func:`default_windows` with ``window`` and ``step`` (s).
    tau : regime threshold of docs/concepts.md (regimes) (model and truth)
    active_share : see :func:`vivbench.validate.model_window_rhs_errors_true_AU`
    fit_time_s : reported as is
    simulate : False skips ``simulation_nmse`` (NaN)

    Returns
    -------
    dict, flat: the keys of :data:`SCORE_KEYS`, floats (``n_scored`` int)
    """
    records = list(records)
    truths = list(truths)
    if len(records) != len(truths):
        raise ValueError(f"{len(records)} records but {len(truths)} truths; give one truth per record")
    if not records:
        raise ValueError("no records to score")
    if windows is None:
        windows = [default_windows(r, window, step) for r in records]
    elif len(windows) != len(records):
        raise ValueError(f"{len(records)} records but {len(windows)} window sets")
    has_verdict = callable(getattr(fitted, "identifiable", None))
    has_own = callable(getattr(fitted, "window_regimes", None))
    predictor = fitted if callable(getattr(fitted, "predict", None)) else _SumPredict(fitted)
    reg, tru, flag, et, et_act, em, em_act = [], [], [], [], [], [], []
    fm_all, ft_all = [], []
    for rec, truth, (start, end) in zip(records, truths, windows):
        start = np.atleast_1d(np.asarray(start, dtype=float))
        end = np.atleast_1d(np.asarray(end, dtype=float))
        if start.size == 0:
            continue
        if has_own:
            r = np.asarray(fitted.window_regimes(rec, start, end), dtype=int)
            if r.shape != (start.size, rec.n_sections):
                raise ValueError(f"window_regimes must return shape {(start.size, rec.n_sections)}; got {r.shape}")
        else:
            r = model_window_regimes(fitted, rec, start, end, tau=tau)["regime"].astype(int)
        reg.append(r)
        tru.append(truth_window_regimes(truth, start, end, tau=tau).astype(int))
        if has_verdict:
            ok = np.asarray(fitted.identifiable(rec, start, end), dtype=bool)
            if ok.shape != r.shape:
                raise ValueError(f"identifiable must return shape {r.shape} (n_windows, n_sections); got {ok.shape}")
        else:
            ok = np.zeros(r.shape, dtype=bool)  # no verdict: scored on all windows, coverage 0
        flag.append(ok)
        # A model using the yaw sees the truth's, or the measured record's where the truth stores none.
        e, act, f_model, f_true = model_window_rhs_true_AU(predictor, truth, start, end, event_id=rec.event_id,
                                                           active_share=active_share,
                                                           yaw=record_yaw_on(rec, truth["time"].values))
        fm_all.append(f_model.ravel())
        ft_all.append(f_true.ravel())
        et.append(e.ravel())
        et_act.append(np.where(act, e, np.nan).ravel())
        if "coef" in truth.data_vars:
            e2, act2 = model_window_rhs_errors(predictor, rec, truth["coef"].values, truth["r"].values, start, end,
                                               active_share=active_share)
            em.append(e2.ravel())
            em_act.append(np.where(act2, e2, np.nan).ravel())
    if not reg:
        raise ValueError("no window to score: every record is shorter than one window")
    reg_all, tru_all, ok_all = (np.concatenate([x.ravel() for x in xs]) for xs in (reg, tru, flag))
    out = dict(regime_scores(reg_all, tru_all, ok_all))
    out["n_scored"] = out.pop("n")
    scored = (tru_all > 0) & (reg_all > 0)
    shares = {k: float(np.mean(tru_all[scored] == k)) if scored.any() else math.nan for k in (1, 2, 3, 4)}
    out["truth_majority_share"] = max(shares.values()) if scored.any() else math.nan
    for k, v in shares.items():
        out[f"truth_share_regime{k}"] = v
    out["no_model_share"] = float(np.mean(reg_all == 0))
    out["rhs_error_true_AU_median"] = finite_median(np.concatenate(et))
    out["rhs_error_true_AU_median_active"] = finite_median(np.concatenate(et_act))
    out["rhs_error_true_AU_energy"] = energy_relative_error(np.concatenate(fm_all), np.concatenate(ft_all))
    out["rhs_median_rel_error"] = finite_median(np.concatenate(em)) if em else math.nan
    out["rhs_median_rel_error_active"] = finite_median(np.concatenate(em_act)) if em else math.nan
    out["curve_error_linear"], out["curve_error_total"], out["curve_error_energy"] = curve_scores(fitted, records,
                                                                                                   truths)
    out["simulation_nmse"], out["simulation_covered"] = (simulation_nmse(fitted, records) if simulate
                                                         else (math.nan, math.nan))
    out["fit_time_s"] = float(fit_time_s)
    return {k: out[k] for k in SCORE_KEYS}


def score_method(method, records: Sequence[Record], truths: Sequence, **kwargs) -> dict:
    """Fit ``method`` (an object, or a spec for :func:`resolve_method`) on the records and score it.

    ``kwargs`` are those of :func:`score_fitted` (but ``fit_time_s``, measured here).
    """
    if isinstance(method, str):
        method = resolve_method(method)
    fitted, seconds = fit_method(method, records)
    return score_fitted(fitted, records, truths, fit_time_s=seconds, **kwargs)
