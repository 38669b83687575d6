"""Recovery of the truth by the identification, window by window.

The truth of a synthetic event (``/truth``) is compared with the windows of an
identification result (``<event_id>.identify.nc``): the true regime of each
window and equation by the same rule as the models (docs/concepts.md (regimes)), and the
right-hand side dA/dt, in two ways:

- on the true (A, U) (``rhs_error_true_AU``, any truth): the model's
  ``predict`` on a record of the truth's own time, A and U
  (:func:`truth_record`) against the truth's dA_k/dt, the sum over orders of
  ``/truth/r``. No coefficient matrix is needed, so realistic truths (aero
  functions outside the library, docs/concepts.md (no inverse crime)) are scored too; the error is that
  of the dynamics where the truth is, free of the measurement's errors in A and
  U (errors-in-variables).
- on the measured (A, U) with the exact matrix (``rhs_median_rel_error``,
  in-library truths only): the model and ``/truth/coef`` both evaluated on the
  result's own A and U.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import xarray as xr

from vivbench.core.record import Record
from vivbench.core.terms import evaluate_library
from vivbench.regimes.truth import truth_window_regimes
from vivbench.validate.metrics import energy_relative_error

__all__ = ["recovery_by_event", "model_rhs_true_AU", "model_window_rhs_true_AU", "window_rhs_true_AU",
           "window_relative_errors", "rhs_relative_error", "window_rhs_errors", "model_window_rhs_errors",
           "regime_scores",
           "campaign_recovery", "truth_record", "model_window_rhs_errors_true_AU", "window_rhs_errors_true_AU",
           "truth_window_activity", "truth_rhs_errors", "finite_median", "record_yaw_on", "record_with_truth_wind",
           "record_with_truth_amplitude"]


def rhs_relative_error(coef_identified: np.ndarray, coef_true: np.ndarray, A: np.ndarray, U: np.ndarray) -> np.ndarray:
    """Relative RMS error of an identified right-hand side over one window.

    Both models are evaluated on the same measured data (the identified
    model's own inputs), so the error is that of the dynamics, not of the
    trajectory.

    Parameters
    ----------
    coef_identified : ndarray, shape (n_eq, n_features)
    coef_true : ndarray, shape (n_eq, n_features)
    A, U : ndarray, shape (n_samples, n_sections), m and m/s

    Returns
    -------
    ndarray, shape (n_eq,): rms(f_id - f_true) / rms(f_true)
    """
    theta = evaluate_library(A, U)
    f_id = theta @ np.nan_to_num(coef_identified).T
    f_true = theta @ coef_true.T
    return np.sqrt(np.mean((f_id - f_true) ** 2, axis=0)) / np.sqrt(np.mean(f_true**2, axis=0))


def regime_scores(identified: np.ndarray, truth: np.ndarray, identifiable: np.ndarray) -> dict:
    """Regime accuracy on identifiable windows, beside coverage and the rest.

    Parameters
    ----------
    identified, truth : ndarray of int, same shape; 0 in ``truth`` means no truth
    identifiable : ndarray of bool, same shape

    Returns
    -------
    dict with ``n``, ``coverage`` (share flagged identifiable), ``accuracy_identifiable``,
    ``accuracy_not_identifiable``, ``accuracy_all`` (NaN where there is nothing to score).
    """
    identified = np.asarray(identified).ravel()
    truth = np.asarray(truth).ravel()
    ok = np.asarray(identifiable, dtype=bool).ravel()
    scored = (truth > 0) & (identified > 0)
    hit = identified == truth

    def acc(mask):
        m = scored & mask
        return float(hit[m].mean()) if m.any() else float("nan")

    return {
        "n": int(scored.sum()),
        "coverage": float(ok[scored].mean()) if scored.any() else float("nan"),
        "accuracy_identifiable": acc(ok),
        "accuracy_not_identifiable": acc(~ok),
        "accuracy_all": acc(np.ones_like(ok)),
    }


def window_rhs_errors(result: xr.Dataset, coef_true: np.ndarray, truth_r: np.ndarray, *,
                      active_share: float = 0.1) -> tuple[np.ndarray, np.ndarray]:
    """Relative RHS error of every window model of one result, and which windows have dynamics.

    Parameters
    ----------
    result : an identification result (``coef``, ``window_start``, ``window_end``, ``time``, ``A``, ``U``)
    coef_true : ndarray, shape (n_eq, n_features), the exact truth matrix
    truth_r : ndarray, shape (n_t, n_sections, 4), m/s
        The truth's order contributions; their sum sets the event's scale of dA/dt.
    active_share : float
        A window-equation is active when the RMS of its true dA/dt is at least
        this share of the event's RMS true dA/dt of that section.

    Returns
    -------
    errors : ndarray, shape (n_windows, n_eq)
        :func:`rhs_relative_error` per window (a window without a model counts
        as predicting zero, error 1; no true dynamics at all gives NaN).
    active : ndarray of bool, shape (n_windows, n_eq)
    """
    start, end = result["window_start"].values, result["window_end"].values
    t = result["time"].values
    A, U, coef = result["A"].values, result["U"].values, result["coef"].values
    scale = np.sqrt(np.mean(np.asarray(truth_r).sum(-1) ** 2, axis=0))
    errors = np.full((start.size, coef_true.shape[0]), np.nan)
    active = np.zeros(errors.shape, dtype=bool)
    with np.errstate(invalid="ignore", divide="ignore"):
        for w in range(start.size):
            sel = (t >= start[w]) & (t < end[w])
            errors[w] = rhs_relative_error(coef[w], coef_true, A[sel], U[sel])
            f_true = evaluate_library(A[sel], U[sel]) @ coef_true.T
            active[w] = np.sqrt(np.mean(f_true**2, axis=0)) >= active_share * scale
    return errors, active


def model_window_rhs_errors(model, record, coef_true: np.ndarray, truth_r: np.ndarray, window_start, window_end, *,
                            active_share: float = 0.1) -> tuple[np.ndarray, np.ndarray]:
    """Relative RHS error of any model of the protocol over every window of one record.

    The model's ``predict(record)`` and the truth's right-hand side are both
    evaluated on the record's A and U (the model's own inputs), so the error is
    that of the dynamics, as in :func:`window_rhs_errors` for window models.

    Parameters
    ----------
    model : fitted model with ``predict(record)`` -> dA/dt, shape (n_samples, S), m/s
    record : vivbench.core.Record
        Typically an identification result's record (:func:`vivbench.io.result.result_record`).
    coef_true : ndarray, shape (S, 23 S), the exact truth matrix on the physical library
    truth_r : ndarray, shape (n_t, S, 4), m/s
        The truth's order contributions; their sum sets the event's scale of dA/dt.
    window_start, window_end : array_like, shape (W,), s
        A window holds the samples with start <= t < end.
    active_share : float
        As in :func:`window_rhs_errors`.

    Returns
    -------
    errors : ndarray, shape (W, S)
        rms(f_model - f_true) / rms(f_true) over each window (NaN where the
        model's prediction or the data are missing on a sample of the window,
        or without true dynamics).
    active : ndarray of bool, shape (W, S)
    """
    f_model = np.asarray(model.predict(record), dtype=float)
    A, U, t = record.A, record.U, record.t
    if f_model.shape != A.shape:
        raise ValueError(f"predict must return shape {A.shape} (n_samples, n_sections); got {f_model.shape}")
    f_truth = evaluate_library(A, U) @ np.asarray(coef_true, dtype=float).T
    start = np.atleast_1d(np.asarray(window_start, dtype=float))
    end = np.atleast_1d(np.asarray(window_end, dtype=float))
    scale = np.sqrt(np.mean(np.asarray(truth_r).sum(-1) ** 2, axis=0))
    errors = np.full((start.size, f_truth.shape[1]), np.nan)
    active = np.zeros(errors.shape, dtype=bool)
    with np.errstate(invalid="ignore", divide="ignore"):
        for w in range(start.size):
            sel = (t >= start[w]) & (t < end[w])
            f_id, f_true = f_model[sel], f_truth[sel]
            rms_true = np.sqrt(np.mean(f_true**2, axis=0))
            errors[w] = np.sqrt(np.mean((f_id - f_true) ** 2, axis=0)) / rms_true
            active[w] = rms_true >= active_share * scale
    return errors, active


def truth_record(truth: xr.Dataset, event_id: str = "truth", yaw=None) -> Record:
    """The truth of an event as a record of the model protocol.

    Parameters
    ----------
    truth : xarray.Dataset
        An event's ``/truth`` group: ``time`` (n_t,) s, ``A``, ``U`` (n_t, S)
        in m and m/s, ``r`` (n_t, S, 4) in m/s, and ``yaw`` (n_t, S) in degrees
        where the truth's aerodynamics depend on it.
    event_id : str
        The record's event id (window models look their coefficients up by it).
    yaw : array_like, shape (n_t, S), degrees, optional
        The mean wind's yaw on the truth's grid where the truth stores none (e.g.
        the measured record's, :func:`record_yaw_on`), for models that use it.

    Returns
    -------
    Record
        ``t``, ``A``, ``U`` of the truth, ``dA`` its dA_k/dt, the sum of ``r`` over
        the orders (m/s), and ``yaw`` the truth's own where stored, else ``yaw``:
        a model is scored at the state the truth's dynamics had.
    """
    r = np.asarray(truth["r"].values, dtype=float)
    if "yaw" in truth.data_vars:
        yaw = truth["yaw"].values
    return Record(event_id=str(event_id), t=truth["time"].values, A=truth["A"].values, U=truth["U"].values,
                  dA=r.sum(axis=-1), yaw=yaw)


def record_yaw_on(record: Record, t) -> np.ndarray | None:
    """The record's yaw (degrees) interpolated to times ``t`` (s), held at its first and last known values.

    Returns None when the record carries no yaw. Shape (len(t), n_sections).
    """
    if record.yaw is None:
        return None
    t = np.asarray(t, dtype=float)
    out = np.full((t.size, record.n_sections), np.nan)
    for k in range(record.n_sections):
        ok = np.isfinite(record.yaw[:, k])
        if ok.any():
            out[:, k] = np.interp(t, record.t[ok], record.yaw[ok, k])
    return out


def record_with_truth_wind(record: Record, truth: xr.Dataset) -> Record:
    """The record with its measured wind replaced by the wind the truth's dynamics sees.

    An oracle for studies: fitted on such records, a method's errors are those of its model
    class and of the measured A, free of the errors in the wind (the anemometers' point
    turbulence, their distance from the deck, the tributary averaging, the yaw's error).

    Parameters
    ----------
    record : Record
        A measured record (``U`` in m/s, shape (n, S)).
    truth : xarray.Dataset
        Its event's ``/truth`` group: ``time`` (n_t,) s and ``U`` (n_t, S) or (n_t,) m/s, and
        ``yaw`` (n_t, S) degrees where the truth's aerodynamics depend on it.

    Returns
    -------
    Record
        ``U`` is the truth's wind interpolated linearly to ``record.t`` (NaN where the measured
        wind is NaN: no sample there), and so is ``yaw`` where the truth stores one;
        ``wind_distance`` is None (the wind is the deck's own); every other field is the record's.
    """
    tt = np.asarray(truth["time"].values, dtype=float)
    Ut = np.asarray(truth["U"].values, dtype=float)
    Ut = Ut[:, None] if Ut.ndim == 1 else Ut
    S = record.n_sections
    if Ut.shape[1] not in (1, S):
        raise ValueError(f"the truth's wind has {Ut.shape[1]} sections and the record {record.event_id} has {S}")
    missing = ~np.isfinite(record.U)
    U = _on_record_grid(record.t, tt, np.repeat(Ut, S, axis=1) if Ut.shape[1] == 1 else Ut, missing)
    yaw = record.yaw
    if "yaw" in truth.data_vars:
        yaw = _on_record_grid(record.t, tt, np.asarray(truth["yaw"].values, dtype=float), missing)
    return dataclasses.replace(record, U=U, yaw=yaw, wind_distance=None)


def _on_record_grid(t, tt, values, missing) -> np.ndarray:
    """Columns ``values`` (n_t, S) given at times ``tt`` interpolated linearly to ``t`` (n,), NaN where ``missing``."""
    out = np.column_stack([np.interp(t, tt, values[:, k]) for k in range(values.shape[1])])
    out[missing] = np.nan
    return out


def record_with_truth_amplitude(record: Record, truth: xr.Dataset) -> Record:
    """The record with its measured amplitude and dA/dt replaced by the truth's averaged ones.

    An oracle for studies: with :func:`record_with_truth_wind` as well, a method's errors are
    those of its model class alone, free of the errors in the measured envelope (buffeting, the
    noise floor, the envelope's and the derivative's estimation) and in the wind.

    Parameters
    ----------
    record : Record
        A measured record (``A`` in m, shape (n, S)).
    truth : xarray.Dataset
        Its event's ``/truth`` group: ``time`` (n_t,) s, ``A`` (n_t, S) m and ``r`` (n_t, S, 4) m/s.

    Returns
    -------
    Record
        ``A`` and ``dA`` (the sum of ``r`` over the orders) of the truth interpolated linearly to
        ``record.t`` (NaN where the measured ``A`` is NaN: no sample there); every other field
        is the record's (:func:`record_with_truth_wind` gives it the truth's wind and yaw).
    """
    tt = np.asarray(truth["time"].values, dtype=float)
    At = np.asarray(truth["A"].values, dtype=float)
    dAt = np.asarray(truth["r"].values, dtype=float).sum(axis=-1)
    At, dAt = (At[:, None], dAt[:, None]) if At.ndim == 1 else (At, dAt)
    S = record.n_sections
    if At.shape[1] != S:
        raise ValueError(f"the truth's amplitude has {At.shape[1]} sections and the record {record.event_id} has {S}")
    missing = ~np.isfinite(record.A)
    return dataclasses.replace(record, A=_on_record_grid(record.t, tt, At, missing),
                               dA=_on_record_grid(record.t, tt, dAt, missing))


def window_relative_errors(f_model: np.ndarray, f_true: np.ndarray, t: np.ndarray, start, end, scale: np.ndarray,
                           active_share: float) -> tuple[np.ndarray, np.ndarray]:
    """Relative RMS error of ``f_model`` against ``f_true`` over each window, and the active mask.

    Parameters
    ----------
    f_model, f_true : ndarray, shape (n, S); t : ndarray, shape (n,), s
    start, end : array_like, shape (W,), s; a window holds the samples with start <= t < end
    scale : ndarray, shape (S,); a window-equation is active when its RMS f_true >= active_share * scale
    active_share : float

    Returns
    -------
    errors : ndarray, shape (W, S); active : ndarray of bool, shape (W, S)
    """
    start = np.atleast_1d(np.asarray(start, dtype=float))
    end = np.atleast_1d(np.asarray(end, dtype=float))
    inside = (t[None, :] >= start[:, None]) & (t[None, :] < end[:, None])  # (W, n)
    count = inside.sum(axis=1)[:, None]
    with np.errstate(invalid="ignore", divide="ignore"):
        # NaN in a window's samples propagates to its error through the products.
        mse = np.where(inside[:, :, None], (f_model - f_true)[None] ** 2, 0.0).sum(axis=1) / count
        ms_true = np.where(inside[:, :, None], f_true[None] ** 2, 0.0).sum(axis=1) / count
        errors = np.sqrt(mse) / np.sqrt(ms_true)
    active = np.sqrt(ms_true) >= active_share * scale
    return errors, active & (count > 0)


def model_window_rhs_errors_true_AU(model, truth: xr.Dataset, window_start, window_end, *, event_id: str = "truth",
                                    active_share: float = 0.1, yaw=None) -> tuple[np.ndarray, np.ndarray]:
    """Relative dA/dt error of any model of the protocol on the true (A, U), window by window.

    The model's ``predict`` on :func:`truth_record` (the truth's own time, A and
    U) against the truth's dA_k/dt = sum_i r_ki: the error of the model's
    dynamics where the truth is, with no coefficient matrix (any truth, in or
    outside the library).

    Parameters
    ----------
    model : fitted model with ``predict(record)`` -> dA/dt, shape (n_samples, S), m/s
    truth : xarray.Dataset, an event's ``/truth`` (``time``, ``A``, ``U``, ``r``)
    window_start, window_end : array_like, shape (W,), s
        A window holds the truth samples with start <= t < end.
    event_id : str
        Event id of the record (a window model must know it).
    active_share : float
        A window-equation has dynamics (is active) when the RMS of its true dA/dt
        is at least this share of the event's RMS true dA/dt of that section.
    yaw : array_like, shape (n_t, S), degrees, optional
        The mean wind's yaw on the truth's grid (see :func:`truth_record`).

    Returns
    -------
    errors : ndarray, shape (W, S)
        rms(f_model - f_true) / rms(f_true) over the window's truth samples (NaN
        where the prediction is missing on a sample of the window, or without
        true dynamics).
    active : ndarray of bool, shape (W, S)
    """
    errors, active, _f_model, _f_true = model_window_rhs_true_AU(model, truth, window_start, window_end,
                                                                 event_id=event_id, active_share=active_share, yaw=yaw)
    return errors, active


def model_window_rhs_true_AU(model, truth: xr.Dataset, window_start, window_end, *, event_id: str = "truth",
                             active_share: float = 0.1, yaw=None):
    """:func:`model_window_rhs_errors_true_AU` and the samples behind it, for energy-weighted errors.

    Returns
    -------
    errors, active : ndarray, shape (W, S), as :func:`model_window_rhs_errors_true_AU`
    f_model, f_true : ndarray, shape (n_t, S), m/s, every truth sample (:func:`model_rhs_true_AU`)
    """
    t, f_model, f_true = model_rhs_true_AU(model, truth, event_id=event_id, yaw=yaw)
    scale = np.sqrt(np.mean(f_true**2, axis=0))
    errors, active = window_relative_errors(f_model, f_true, t, window_start, window_end, scale, active_share)
    return errors, active, f_model, f_true


def model_rhs_true_AU(model, truth: xr.Dataset, *, event_id: str = "truth",
                      yaw=None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A model's dA/dt and the truth's on the true (A, U) of an event, sample by sample.

    Parameters
    ----------
    model : fitted model with ``predict(record)`` -> dA/dt, shape (n_samples, S), m/s
    truth : xarray.Dataset, an event's ``/truth`` (``time``, ``A``, ``U``, ``r``)
    event_id : str, the record's event id
    yaw : array_like, shape (n_t, S), degrees, optional (see :func:`truth_record`)

    Returns
    -------
    t : ndarray, shape (n_t,), s
    f_model, f_true : ndarray, shape (n_t, S), m/s
    """
    record = truth_record(truth, event_id, yaw)
    f_model = np.asarray(model.predict(record), dtype=float)
    if f_model.shape != record.A.shape:
        raise ValueError(f"predict must return shape {record.A.shape} (n_samples, n_sections); got {f_model.shape}")
    return record.t, f_model, record.dA


def window_rhs_errors_true_AU(result: xr.Dataset, truth: xr.Dataset, *,
                              active_share: float = 0.1) -> tuple[np.ndarray, np.ndarray]:
    """Relative dA/dt error of every window model of one result on the true (A, U).

    Window w's own model (:meth:`vivbench.models.WindowSINDy.from_result` with
    ``windows=[w]``, through the protocol's ``predict``) on the truth's samples
    inside window w, against the truth's dA_k/dt = sum_i r_ki. On an in-library
    event this is :func:`window_rhs_errors` with the truth's (A, U) in place of
    the result's measured ones.

    Parameters
    ----------
    result : an identification result (``coef``, ``window_start``, ``window_end``, attribute ``event_id``)
    truth : xarray.Dataset, the event's ``/truth``
    active_share : float
        As in :func:`model_window_rhs_errors_true_AU`.

    Returns
    -------
    errors : ndarray, shape (n_windows, n_eq)
        A window without a model counts as predicting zero (error 1); NaN without
        true dynamics.
    active : ndarray of bool, shape (n_windows, n_eq)
    """
    errors, active, _f_model, _f_true = window_rhs_true_AU(result, truth, active_share=active_share)
    return errors, active


def window_rhs_true_AU(result: xr.Dataset, truth: xr.Dataset, *,
                       active_share: float = 0.1) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """:func:`window_rhs_errors_true_AU` and the samples it compares, for energy-weighted errors.

    Returns
    -------
    errors, active : ndarray, shape (n_windows, n_eq), as :func:`window_rhs_errors_true_AU`
    f_model, f_true : ndarray, shape (m, n_eq), m/s
        Each window's model's dA/dt (zero for a window without a model) and
        the truth's on the truth's samples inside that window, windows one
        after the other (a sample in two overlapping windows appears twice).
    """
    from vivbench.models.window_model import WindowSINDy

    event_id = str(result.attrs.get("event_id", "truth"))
    record = truth_record(truth, event_id)
    start, end = result["window_start"].values, result["window_end"].values
    fitted = np.all(np.isfinite(result["coef"].values), axis=(1, 2))
    scale = np.sqrt(np.mean(record.dA**2, axis=0))
    errors = np.full((start.size, record.n_sections), np.nan)
    active = np.zeros(errors.shape, dtype=bool)
    f_models, f_trues = [np.empty((0, record.n_sections))], [np.empty((0, record.n_sections))]
    for w in range(start.size):
        sel = (record.t >= start[w]) & (record.t < end[w])
        if not sel.any():
            continue
        f_true = record.dA[sel]
        if fitted[w]:
            part = Record(event_id=event_id, t=record.t[sel], A=record.A[sel], U=record.U[sel])
            f_id = WindowSINDy.from_result(result, windows=[w]).predict(part)
        else:
            f_id = np.zeros_like(f_true)
        f_models.append(f_id)
        f_trues.append(f_true)
        rms_true = np.sqrt(np.mean(f_true**2, axis=0))
        with np.errstate(invalid="ignore", divide="ignore"):
            errors[w] = np.sqrt(np.mean((f_id - f_true) ** 2, axis=0)) / rms_true
        active[w] = rms_true >= active_share * scale
    return errors, active, np.concatenate(f_models), np.concatenate(f_trues)
def truth_window_activity(truth: xr.Dataset, window_start, window_end, *, active_share: float = 0.1) -> np.ndarray:
    """Which window-equations have dynamics, from the truth alone (no coefficient matrix needed).

    A window is active for a section when the RMS of the true dA/dt (the sum of the truth's
    order contributions r0..r3 on its own time grid, start <= t < end) is at least
    ``active_share`` of the event's RMS true dA/dt of that section.

    Returns
    -------
    active : ndarray of bool, shape (W, n_sections)
    """
    t = truth["time"].values
    f = np.asarray(truth["r"].values, dtype=float).sum(-1)
    scale = np.sqrt(np.mean(f**2, axis=0))
    start = np.atleast_1d(np.asarray(window_start, dtype=float))
    end = np.atleast_1d(np.asarray(window_end, dtype=float))
    inside = (t[None, :] >= start[:, None]) & (t[None, :] < end[:, None])  # (W, n_t)
    n = inside.sum(axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        rms = np.sqrt((inside.astype(float) @ f**2) / n[:, None])
    return (n[:, None] > 0) & (rms >= active_share * scale)


def truth_rhs_errors(result: xr.Dataset, truth: xr.Dataset, *, active_share: float = 0.1) -> tuple[np.ndarray, np.ndarray]:
    """:func:`window_rhs_errors` when the truth has an exact coefficient matrix (``coef``); otherwise
    (a truth outside the library, docs/concepts.md (no inverse crime)) the errors are NaN (not scored) and the activity comes
    from :func:`truth_window_activity`."""
    if "coef" in truth.data_vars:
        return window_rhs_errors(result, truth["coef"].values, truth["r"].values, active_share=active_share)
    active = truth_window_activity(truth, result["window_start"].values, result["window_end"].values,
                                   active_share=active_share)
    return np.full(active.shape, np.nan), active


def finite_median(x: np.ndarray) -> float:
    """Median of the finite values; NaN (without a warning) when there is none."""
    x = np.asarray(x, dtype=float)
    x = x[np.isfinite(x)]
    return float(np.median(x)) if x.size else float("nan")


def campaign_recovery(event_files, result_files, *, active_share: float = 0.1) -> dict:
    """Regime scores and right-hand-side errors of a campaign's results against its truth.

    Parameters
    ----------
    event_files : synthetic event files (with ``/truth``; without its ``coef``, a truth outside the
        library, the RHS errors are NaN and ``active_share`` counts the active windows)
    result_files : the matching ``<event_id>.identify.nc``, same order
    active_share : a window counts as active when the RMS of its true dA/dt is at
        least this share of the event's RMS true dA/dt (relative errors on windows
        with almost no dynamics say little)

    Returns
    -------
    dict
        :func:`regime_scores` plus ``rhs_median_rel_error`` (all windows),
        ``rhs_median_rel_error_active``, ``active_share`` (share of active
        window-equations) on the measured (A, U) with the exact matrix (NaN
        for truths without ``coef``); ``rhs_error_true_AU_median``,
        ``rhs_error_true_AU_median_active`` and ``active_share_true_AU`` on the
        true (A, U) (:func:`window_rhs_errors_true_AU`, any truth),
        ``rhs_error_true_AU_energy`` the same error energy-weighted over the
        windows' samples (:func:`vivbench.validate.metrics.energy_relative_error`
        of :func:`window_rhs_true_AU`'s samples); and
        ``truth_regime_shares``. The fuller tables are
        :func:`vivbench.validate.validate_campaign`.
    """
    return recovery_by_event(event_files, result_files, active_share=active_share)[0]


def recovery_by_event(event_files, result_files, *, active_share: float = 0.1) -> tuple[dict, list[dict]]:
    """:func:`campaign_recovery` over all events and for each event, every event scored once.

    Returns
    -------
    campaign : dict, as :func:`campaign_recovery`
    events : list of dict, the same scores per event, in the order of the files
    """
    from vivbench.io.event import read_event
    from vivbench.io.result import read_result

    parts = []
    for ev_path, res_path in zip(event_files, result_files):
        truth = read_event(ev_path)["truth"].ds
        res = read_result(res_path)
        start, end = res["window_start"].values, res["window_end"].values
        e, active = truth_rhs_errors(res, truth, active_share=active_share)
        et, act_t, f_win, f_true = window_rhs_true_AU(res, truth, active_share=active_share)
        parts.append({"regime": res["regime"].values, "truth": truth_window_regimes(truth, start, end),
                      "flag": res["identifiable"].values.astype(bool), "err": e.ravel(),
                      "err_active": np.where(active, e, np.nan).ravel(),
                      # scored and active; without a coefficient matrix nothing is scored: active alone
                      "active": (active & np.isfinite(e) if "coef" in truth.data_vars else active).ravel(),
                      "err_true": et.ravel(), "err_true_active": np.where(act_t, et, np.nan).ravel(),
                      "f_window": f_win.ravel(), "f_true": f_true.ravel()})
    return _recovery_scores(parts), [_recovery_scores([p]) for p in parts]


def _recovery_scores(parts: list[dict]) -> dict:
    cat = {k: np.concatenate([np.ravel(p[k]) for p in parts]) for k in parts[0]}
    scores = regime_scores(cat["regime"], cat["truth"], cat["flag"])
    scores["rhs_median_rel_error"] = finite_median(cat["err"])
    scores["rhs_median_rel_error_active"] = finite_median(cat["err_active"])
    scores["active_share"] = float(np.mean(cat["active"]))
    scores["rhs_error_true_AU_median"] = finite_median(cat["err_true"])
    scores["rhs_error_true_AU_median_active"] = finite_median(cat["err_true_active"])
    scores["rhs_error_true_AU_energy"] = energy_relative_error(cat["f_window"], cat["f_true"])
    scores["active_share_true_AU"] = float(np.mean(np.isfinite(cat["err_true_active"])))
    scores["truth_regime_shares"] = {k: float(np.mean(cat["truth"] == k)) for k in (1, 2, 3, 4)}
    return scores
