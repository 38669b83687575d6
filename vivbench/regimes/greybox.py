"""Regimes of the grey-box refit per window and their identifiability (docs/concepts.md (regimes)).

A window's regime is the rule of docs/concepts.md (regimes) applied to the grey-box model's
order contributions over the window's data. It counts as identifiable when at
least ``agreement`` of ``n_draws`` parameter draws from the model's sandwich
covariance (a Gaussian around the fitted spline and yaw coefficients) give the window
the same regime: the draws are the confidence band evaluated on the window's
own (A, U, yaw). The covariance does not include the penalty's smoothing bias or
the model's own limits, so the verdict is only as honest as the bands (the
validation reports how often flagged windows carry the true regime).

Bounded coefficients (e1, e2, C_L >= 0, yaw c >= 0) are drawn by reflecting a
Gaussian draw that falls below its bound back above it, not by clipping it to
the bound. Clipping puts every draw beyond the bound on the bound itself: where
a curve is fitted near its bound with a wide band (e2 on a bridge whose
amplitudes barely tell e1 A^2 from e2 A^3 apart), about half the draws then
carry exactly no cubic term and vote together for regime 3, an agreement made
by the clipping, not by the data. Reflection is the Gaussian restricted to the
feasible side (exact for a mean on the bound), so the draws spread over the
values the fit allows.

The parameter draws cannot see a model error: a fit that stayed near its
start along a nearly flat direction (e1 against e2) has a band that need not
hold the truth. So a ``reference`` model, a second campaign-level estimate of
the same dynamics fitted independently of the grey-box curves (``vivbench
greybox`` passes the campaign model of ``vivbench pool``), must give the window
the same regime (its point estimate, on the same data) for the window to count
as identifiable: where two estimators of the same curves disagree on the
regime, at least one carries a model error the bands miss.

A reference with a confidence set of penalties (the varying campaign model's
``penalty_order_contributions`` and ``penalty_plausible_``) must give the
window the grey-box regime at every plausible penalty as well, the rule of its
own verdict: its point estimate is one member of that set. The share of
flagged windows with the true regime and the coverage are reported by
``vivbench validate`` and ``vivbench greybox`` on a synthetic campaign, and
compared over bounds and references by benchmarks/study_greybox_verdict_bounds.py.
"""

from __future__ import annotations

import numpy as np

from vivbench.core.errors import InputError
from vivbench.core.record import Record
from vivbench.core.regime import DEFAULT_TAU, regime_rule
from vivbench.models.greybox import GreyBoxRefit
from vivbench.models.varying_verdicts import window_order_stats

__all__ = ["greybox_draws", "greybox_window_verdicts"]


def greybox_draws(model: GreyBoxRefit, n_draws: int, seed: int = 0, *, with_yaw: bool = False,
                  bounds: str = "reflect"):
    """Spline coefficients drawn from the fitted model's covariance, shape (n_draws, 4, M).

    The bounds of the fit (e1, e2, C_L >= 0 and the yaw coefficient c >= 0)
    are kept by reflecting the draws at 0 (``bounds="reflect"``, default:
    the Gaussian restricted to the feasible side, see the module docstring)
    or by clipping them to 0 (``"clip"``, which piles the mass beyond the
    bound on the bound). With ``with_yaw``, also the yaw coefficients drawn
    jointly, shape (n_draws,) (the fitted 0 when the yaw factor was not
    fitted): returns ``(coef, yaw_coef)``.
    """
    if bounds not in ("reflect", "clip"):
        raise InputError(f"bounds must be 'reflect' or 'clip'; got {bounds!r}")
    keep = np.abs if bounds == "reflect" else (lambda x: np.maximum(x, 0.0))
    rng = np.random.default_rng(seed)
    mean = model.coef_.ravel()
    if model.yaw_used_:
        mean = np.append(mean, model.yaw_coef_)
    cov = 0.5 * (model.cov_ + model.cov_.T)
    w, V = np.linalg.eigh(cov)
    z = rng.standard_normal((n_draws, mean.size))
    draws = mean + (z * np.sqrt(np.clip(w, 0.0, None))) @ V.T
    M = model.coef_.shape[1]
    coef = draws[:, :4 * M].reshape(n_draws, 4, M)
    coef[:, 1:] = keep(coef[:, 1:])
    if not with_yaw:
        return coef
    yaw = keep(draws[:, 4 * M]) if model.yaw_used_ else np.zeros(n_draws)
    return coef, yaw


def greybox_window_verdicts(model: GreyBoxRefit, record: Record, window_start, window_end, *,
                            tau: float = DEFAULT_TAU, agreement: float = 0.95, n_draws: int = 100, seed: int = 0,
                            chunk: int = 25, sample_step: float = 1.0, bounds: str = "reflect",
                            reference=None, reference_record: Record | None = None) -> dict:
    """Regimes of a fitted grey-box model over a record's windows, and their identifiability.

    Parameters
    ----------
    model : GreyBoxRefit (fitted)
    record : Record
    window_start, window_end : array_like, shape (W,), s (a window holds start <= t < end)
    tau : float
        Regime threshold (docs/concepts.md (regimes)).
    agreement : float
        Share of the draws that must give the window's regime.
    n_draws : int
        Parameter draws from the covariance.
    seed : int
        Seed of the draws (the same for every record, so verdicts do not depend on the order of events).
    chunk : int
        Draws evaluated together (memory: chunk x n_samples x S x 4 floats).
    sample_step : float, s
        Window statistics use the record's samples thinned to about this
        spacing (the envelope is slow; a 50 s window keeps 50 samples), which
        makes the verdicts of a campaign several times cheaper.
    bounds : {"reflect", "clip"}
        How draws beyond the fit's bounds are kept feasible (:func:`greybox_draws`).
    reference : model of the protocol (``order_contributions``) or None
        A second campaign-level model of the same records (the campaign
        model); a window is identifiable only if its point regime equals the
        grey-box one, and so do its fits at every plausible penalty when it
        has them (``penalty_order_contributions``, ``penalty_plausible_``; see
        the module docstring). None: the draws alone.
    reference_record : Record or None
        The same samples as the reference model saw them at fit
        (:func:`vivbench.models.measured_input`: its own wind smoothing, not
        the grey-box fit's); None: ``record``.

    Returns
    -------
    dict
        ``regime`` (W, S) int8 (0: no valid sample), ``identifiable`` (W, S) bool,
        ``agreement`` (W, S) share of draws with the same regime, ``order_rms`` (W, S, 4) m/s,
        ``c1`` (W, S) 1/s, ``reference_regime`` (W, S) int8 (the reference's
        point regime; 0 without a reference).
    """
    stride = 1
    if record.t.size > 1:
        stride = max(1, int(round(sample_step / float(np.median(np.diff(record.t))))))
    n_samples = record.t.size
    t, A, U = record.t[::stride], record.A[::stride], record.U[::stride]
    yaw = None if record.yaw is None else record.yaw[::stride]
    record = Record(event_id=record.event_id, t=t, A=A, U=U, yaw=yaw)
    if reference_record is not None:
        if reference_record.t.shape != (n_samples,):
            raise ValueError(f"reference_record has {reference_record.t.size} samples, the record {n_samples}")
        ref_yaw = None if reference_record.yaw is None else reference_record.yaw[::stride]
        reference_record = Record(event_id=record.event_id, t=t, A=A, U=reference_record.U[::stride], yaw=ref_yaw)
    R, c1, nv = window_order_stats(model.order_contributions(record), A, t, window_start, window_end)
    point = np.where(nv > 0, regime_rule(np.nan_to_num(R), c1, tau), 0).astype(np.int8)
    draws, yaw_draws = greybox_draws(model, n_draws, seed, with_yaw=True, bounds=bounds)
    amp = np.abs(model.phi_)
    Qpow = (A / amp)[..., None] ** np.arange(4)  # (n, S, 4)
    same = np.zeros(point.shape)
    g_of = model.amplitude_coefficient_function(record.U, yaw)  # the basis once, then one product per chunk of draws
    for c0 in range(0, n_draws, chunk):
        g = g_of(draws[c0:c0 + chunk], yaw_draws[c0:c0 + chunk])  # (c, n, 4)
        r = amp[None, None, :, None] * g[:, :, None, :] * Qpow[None]
        Rb, c1b, _ = window_order_stats(r, A, t, window_start, window_end)
        same += (regime_rule(np.nan_to_num(Rb), c1b, tau) == point[None]).sum(axis=0)
    agree = same / n_draws
    identifiable = (agree >= agreement) & (point > 0)
    ref = np.zeros_like(point)
    if reference is not None:
        ref_in = record if reference_record is None else reference_record
        Rr, c1r, nvr = window_order_stats(reference.order_contributions(ref_in), A, t, window_start, window_end)
        ref = np.where(nvr > 0, regime_rule(np.nan_to_num(Rr), c1r, tau), 0).astype(np.int8)
        identifiable &= ref == point
        pen = getattr(reference, "penalty_order_contributions", None)
        r_pen = pen(ref_in) if pen is not None else None
        if r_pen is not None:
            # the reference's fits at its other plausible penalties must agree too (its own verdict's rule)
            Rp, c1p, nvp = window_order_stats(r_pen, A, t, window_start, window_end)  # (n_pen, W, S, ...)
            ref_pen = np.where(nvp > 0, regime_rule(np.nan_to_num(Rp), c1p, tau), 0)
            plausible = np.asarray(reference.penalty_plausible_, dtype=bool)[:, None, :]  # (n_pen, 1, S)
            identifiable &= np.all((ref_pen == point[None]) | ~plausible, axis=0)
    return {"regime": point, "identifiable": identifiable, "agreement": agree,
            "order_rms": R, "c1": c1, "reference_regime": ref}
