"""The regime rule of docs/concepts.md (regimes) applied to any model of the protocol, through its order contributions."""

from __future__ import annotations

import numpy as np

from vivbench.core.record import Record
from vivbench.core.regime import DEFAULT_TAU, regime_rule
from vivbench.models.model_input import measured_input
from vivbench.models.protocol import FittedModel

__all__ = ["measured_verdicts", "model_verdicts", "model_window_regimes"]


def model_window_regimes(model: FittedModel, record: Record, window_start, window_end,
                         tau: float = DEFAULT_TAU) -> dict:
    """Regime of every window and section from ``model.order_contributions(record)``.

    Parameters
    ----------
    model : FittedModel
        Any object with ``order_contributions(record)`` -> (n_samples, S, 4), m/s.
    record : Record
    window_start, window_end : array_like, shape (W,), s
        A window holds the samples with start <= t < end.
    tau : float
        Regime threshold of docs/concepts.md (regimes).

    Returns
    -------
    dict
        ``regime`` (W, S) int8 (0: no sample with finite contributions in the
        window), ``order_rms`` (W, S, 4) m/s (RMS over the window's valid
        samples), ``c1`` (W, S) 1/s (window mean of r_1 / A over samples with
        A > 0), ``n_valid`` (W, S) int.
    """
    r = np.asarray(model.order_contributions(record), dtype=float)
    A = record.A
    if r.shape != A.shape + (4,):
        raise ValueError(f"order_contributions must have shape {A.shape + (4,)} (n_samples, n_sections, 4); "
                         f"got {r.shape}")
    start = np.atleast_1d(np.asarray(window_start, dtype=float))
    end = np.atleast_1d(np.asarray(window_end, dtype=float))
    if start.shape != end.shape or start.ndim != 1:
        raise ValueError(f"window_start and window_end must have one shape (W,); got {start.shape}, {end.shape}")
    lo = np.searchsorted(record.t, start, side="left")
    hi = np.searchsorted(record.t, end, side="left")
    ok = np.isfinite(r).all(axis=-1) & np.isfinite(A)  # (n, S)
    okA = ok & (A > 0)

    def wsum(x):
        # window sums by one cumulative sum (no loop over windows or samples)
        c = np.concatenate([np.zeros((1,) + x.shape[1:]), np.cumsum(x, axis=0)], axis=0)
        return c[hi] - c[lo]

    rz = np.where(ok[..., None], r, 0.0)
    nv = wsum(ok.astype(float))
    inv = np.where(okA, 1.0 / np.where(okA, A, 1.0), 0.0)
    with np.errstate(invalid="ignore", divide="ignore"):
        R = np.sqrt(wsum(rz**2) / nv[..., None])
        c1 = wsum(rz[..., 1] * inv) / wsum(okA.astype(float))
    regime = np.where(nv > 0, regime_rule(np.nan_to_num(R), c1, tau), 0).astype(np.int8)
    return {"regime": regime, "order_rms": R, "c1": c1, "n_valid": nv.astype(int)}


def model_verdicts(model: FittedModel, record: Record, window_start, window_end, *, tau: float = DEFAULT_TAU) -> dict:
    """The model's regime of every window and its verdict, on the record as the model sees it.

    Parameters
    ----------
    model : FittedModel
        Its ``window_verdicts(record, window_start, window_end)`` when it has
        one (the built-in campaign models: :func:`vivbench.regimes.campaign_window_verdicts`,
        :func:`vivbench.regimes.varying_window_verdicts`); otherwise the rule on
        its order contributions (:func:`model_window_regimes`, or its own
        ``window_regimes``) with its ``identifiable`` when it has one, else
        no window identifiable.
    record : Record
    window_start, window_end : array_like, shape (W,), s
    tau : float
        Regime threshold for the default.

    Returns
    -------
    dict
        At least ``regime`` (W, S) int, ``identifiable`` (W, S) bool,
        ``agreement`` (W, S) (NaN: no replicates) and ``order_rms`` (W, S, 4) m/s.
    """
    own = getattr(model, "window_verdicts", None)
    if callable(own):
        return dict(own(record, window_start, window_end))
    base = model_window_regimes(model, record, window_start, window_end, tau=tau)
    regimes = getattr(model, "window_regimes", None)
    regime = (np.asarray(regimes(record, window_start, window_end), dtype=np.int8) if callable(regimes)
              else base["regime"])
    verdict = getattr(model, "identifiable", None)
    flag = (np.asarray(verdict(record, window_start, window_end), dtype=bool) if callable(verdict)
            else np.zeros(regime.shape, dtype=bool))
    return {"regime": regime, "identifiable": flag, "agreement": np.full(regime.shape, np.nan),
            "order_rms": base["order_rms"]}


def measured_verdicts(model: FittedModel, record: Record, window_start, window_end, *,
                      wind_smoothing_s: float = 0.0, tau: float = DEFAULT_TAU) -> dict:
    """:func:`model_verdicts` of a measured record, its wind transformed as at fit.

    A model with ``measured_verdicts(record, window_start, window_end)`` (a
    :class:`vivbench.analysis.ModelSelection`, whose members each see the
    wind as at their fit) gives them itself; any other model gets
    :func:`vivbench.models.measured_input` of the record (``wind_smoothing_s``
    for a model that does not know its own smoothing).
    """
    own = getattr(model, "measured_verdicts", None)
    if callable(own):
        return dict(own(record, window_start, window_end))
    rec = measured_input(model, record, wind_smoothing_s=wind_smoothing_s)
    return model_verdicts(model, rec, window_start, window_end, tau=tau)
