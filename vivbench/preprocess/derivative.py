"""Numerical differentiation of slowly varying envelopes (docs/field_workflow.md).

The identification regresses dA/dt on a library of A and U, so the derivative
of a noisy envelope A(t) is the first quantity it needs. The default is a
total-variation (TV) regularised derivative after Chartrand (2011); Savitzky-
Golay, smoothing-spline and plain finite-difference derivatives are available
for comparison through the same :class:`Derivative` configuration.

TV-regularised derivative
-------------------------
Chartrand (2011, "Numerical differentiation of noisy, nonsmooth data", ISRN
Applied Mathematics 2011:164564) defines the derivative ``u`` of data ``f`` as
the minimiser of ``alpha * TV(u) + 1/2 ||A u + c - f||^2``, where ``A`` is
integration and ``c`` the integration constant. We solve exactly this problem,
discretised so that it stays banded:

* ``u`` is piecewise constant between samples (``u_{i+1/2}``), so its integral
  ``g = c + A u`` is the piecewise-linear signal through the node values
  ``g_i`` and integration is exact: ``u_{i+1/2} = (g_{i+1} - g_i) / dt``.
* ``TV(u) = sum_i |u_{i+1/2} - u_{i-1/2}| = sum_i |g_{i+1} - 2 g_i + g_{i-1}| / dt``.

Substituting ``g`` for ``(u, c)`` (a one-to-one change of variables) turns
Chartrand's problem into

    minimise over g:  1/2 ||g - f||^2 + alpha * sum_i H((D2 g)_i / dt)

with ``D2`` the second difference and ``H(s) = |s|``: this is l1 trend
filtering (Kim, Koh, Boyd and Gorinevsky 2009, SIAM Review 51:339), whose
solution is piecewise linear with a piecewise-constant derivative, exactly the
TV prior on ``u``. Unlike Chartrand's "small" variant, the integration constant
is estimated with everything else instead of being pinned to ``f[0]``.

Solver. The dual of this problem is a box-constrained quadratic programme with
a pentadiagonal Hessian ``D D^T``; a primal-dual interior-point method
(Boyd and Vandenberghe 2004, section 11.7, as used for l1 trend filtering by
Kim et al.) solves it to a certified duality gap in a few tens of Newton steps,
each one banded Cholesky solve (LAPACK ``pbsv``), O(n) per step, whatever the
regularisation weight. Columns are stacked into one block-banded system, so all
sections are solved in the same calls. Chartrand's own lagged-diffusivity
iteration needs a smoothing ``sqrt(s^2 + eps)`` of ``|s|`` that must be large
to converge in few iterations; the interior-point method does not.

Huber smoothing. With ``huber > 0`` the penalty ``|s|`` is replaced by
the Huber function (quadratic for ``|s| <= delta``, linear beyond): changes of
slope smaller than ``delta`` are smoothed as by a second-difference (Whittaker)
smoother, larger ones still cost their total variation. This is the analogue
of Chartrand's ``eps``; in the dual it adds ``(delta / alpha) I`` to the
Hessian, so the same solver serves. ``huber = 0`` (the default) is exact TV.

Regularisation rule (``alpha=None``). With ``sigma`` the noise standard
deviation and ``tau`` a time scale (``time_scale``, s),

    alpha = sigma * dt * (tau / dt) ** 1.5          (units of x times s)

The dual variable of the problem is the twice-integrated residual; over a
stretch of ``L`` samples white noise makes it grow like ``sigma * dt * L**1.5``,
so this ``alpha`` is the level that noise reaches over about ``tau``: noise
alone cannot put kinks in ``g`` (steps in the derivative) much closer than
``tau``: on white noise around a line they come a few ``tau`` apart. The
Huber threshold on the change of the derivative per sample is
``delta = huber * sigma * dt / tau**2``. Both scale with the data, so scaling
``x`` by ``c`` scales the derivative by exactly ``c`` when ``alpha`` is
automatic (an explicit ``alpha`` must be scaled by the caller).

Noise level at the regulariser's time scale. The twice-integrated residual
over a stretch much longer than the noise's correlation time grows with the
noise's low-frequency power spectral density ``S0`` (x^2/Hz, two-sided), not
with its variance; ``sigma`` must therefore be the standard deviation of the
white noise with the same low-frequency density, ``sqrt(S0 / dt)``. For white
noise the two coincide and the plain third differences estimate it. The
envelopes of the identification chain are different: the Hilbert envelope of
a displacement band-limited to f_mode +- 30 % carries noise only below the
band's half-width (about 0.1 Hz), correlated over seconds, which third
differences at 4 Hz barely see (they find a noise level orders of magnitude
too small, and the weight they give leaves TV equal to finite differences).
For such data ``sigma`` is
estimated per column by :func:`estimate_noise_std` with block length
``L = noise_scale / dt``: third differences at lag ``L`` of ``L``-sample
means, scaled by ``sqrt(L)``. This is unbiased for white noise at any ``L``
and gives ``sqrt(S0 / dt)`` for noise correlated over fewer than ``L``
samples. ``noise_scale = time_scale / 2`` measures the noise where the
regulariser acts: fluctuations faster than about ``tau`` count as noise,
slower ones as signal. This is a prior, not a separation: an envelope
that genuinely varies on periods of a few ``tau`` raises the estimate and is
smoothed more (on white noise, the 75 s modulation of
``benchmarks/bench_derivative.py`` is the case). ``noise_scale=0`` (the
default) gives the plain third differences, the white-noise rule.

Choosing the settings. The class defaults (``time_scale = 10`` s, exact TV,
``noise_scale = 0``: the white-noise rule) suit white noise and are what the
campaign model uses; ``time_scale = 20``, ``huber = 10``, ``noise_scale = 10``
is the setting for band-limited envelope noise (:meth:`Derivative.for_envelope`),
the identification chain's default, chosen on synthetic campaigns by the
relative RMS error of dA/dt against the true averaged dA/dt
(``benchmarks/study_derivative_campaign.py`` measures it). With ``huber =
10`` most changes of slope fall below the Huber threshold and the fit behaves
as a second-difference (Whittaker) smoother whose cut-off is set by
``time_scale`` alone (about 0.024 Hz at 20 s), while large changes still cost
only their total variation; Chartrand's own algorithm smooths ``|.|`` in the
same way. The campaign model differentiates with the white-noise rule
(``vivbench.models.campaign``): its pooled regression averages the noise over
the whole campaign anyway, but not a smoother's bias. With exact TV and the
white-noise rule on band-limited envelopes the automatic weight is tiny and
the derivative is nearly the finite differences.

NaN. All methods refuse input containing NaN or infinity with a
``ValueError``: the derivative is global, a gap would contaminate the whole
record, so the caller splits the record at gaps and differentiates each piece.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass
from typing import Literal

import numpy as np
from scipy.interpolate import make_smoothing_spline
from scipy.linalg import solveh_banded
from scipy.signal import savgol_filter
from vivbench.core.errors import InputError

__all__ = [
    "DERIVATIVE_METHODS",
    "Derivative",
    "TVDerivativeResult",
    "estimate_noise_std",
    "tv_derivative",
]

DERIVATIVE_METHODS = ("tv", "savgol", "spline", "finite_difference")

# Defaults of the method-specific options (used when the option is None).
_TV_TIME_SCALE = 10.0  # s
_TV_HUBER = 0.0
_TV_NOISE_SCALE = 0.0  # s; 0: plain third differences (white-noise estimate)
_TV_TOL = 1e-6
_TV_MAX_ITER = 100
_SAVGOL_WINDOW = 20.0  # s
_SAVGOL_POLYORDER = 3
_FD_ORDER = 2

# The band-limited-noise setting of the TV derivative (Derivative.for_envelope):
# chosen on 8 events of the default campaign against the true dA/dt, checked on
# the other 23 (benchmarks/study_derivative_campaign.py).
_ENVELOPE_TV = {"time_scale": 20.0, "huber": 10.0, "noise_scale": 10.0}

_METHOD_OPTIONS = {
    "tv": ("alpha", "time_scale", "huber", "noise_scale", "tol", "max_iter"),
    "savgol": ("window", "polyorder"),
    "spline": ("smoothing",),
    "finite_difference": ("fd_order",),
}

# Relative spacing error tolerated on a "uniform" time grid (float rounding of
# times read from files).
_UNIFORM_RTOL = 1e-6
# Columns are normalised to unit RMS; noise below this relative level is
# treated as absent (double-precision data), for the noise floor and the
# stopping rule.
_NOISE_FLOOR = 1e-9
# Interior-point constants (Boyd and Vandenberghe 2004, 11.7): barrier growth
# factor, fraction of the step to the boundary, sufficient-decrease factor of
# the backtracking line search and its maximum number of halvings.
_IP_MU = 10.0
_IP_STEP_FRACTION = 0.99
_IP_ARMIJO = 0.01
_IP_MAX_HALVINGS = 40
# Iterations without a smaller duality gap, and the relative slack, at which a
# signal has reached the round-off floor of the interior-point method.
_IP_MAX_STALL = 3
_IP_MIN_SLACK = 1e-13
_MAD_TO_STD = 1.482602218505602  # 1 / Phi^-1(3/4)


@dataclass(frozen=True)
class TVDerivativeResult:
    """Result of :func:`tv_derivative`; arrays have the shape of the input.

    Attributes
    ----------
    dxdt : ndarray, shape (n,) or (n, k), units of x per s
        TV-regularised derivative on the input grid (mean of the two adjacent
        piecewise-constant slopes; the end samples take the adjacent slope).
    x_smooth : ndarray, shape (n,) or (n, k), units of x
        The piecewise-linear antiderivative ``g`` (the regularised signal).
    alpha : ndarray, shape () or (k,), units of x times s
        Regularisation weight used per column.
    noise_std : ndarray, shape () or (k,), units of x
        Estimated white-equivalent noise standard deviation per column at the
        noise scale (NaN if not needed: explicit ``alpha`` and ``huber == 0``).
    iterations : int
        Interior-point iterations.
    converged : bool
        Whether every column reached the duality-gap tolerance.
    """

    dxdt: np.ndarray
    x_smooth: np.ndarray
    alpha: np.ndarray
    noise_std: np.ndarray
    iterations: int
    converged: bool


def estimate_noise_std(x: np.ndarray, lag: int = 1) -> np.ndarray:
    """White-equivalent noise standard deviation from third differences of block means.

    Parameters
    ----------
    x : array_like, shape (n,) or (n, k), n >= 4 * lag
        Samples along axis 0; finite.
    lag : int
        Block length ``L``, samples. The signal is averaged over ``L``
        consecutive samples (a moving mean) and differenced three times at
        lag ``L``, so that the four block means of each difference are
        disjoint. ``lag=1`` is the plain third difference.

    Returns
    -------
    sigma : ndarray, shape () or (k,), units of x
        ``sqrt(L) * 1.4826 * median(|d - median(d)|) / sqrt(20)`` with ``d``
        the lag-``L`` third difference of the ``L``-sample means. For white
        noise of standard deviation ``s`` the block means have variance
        ``s**2 / L`` and ``var(d) = 20 s**2 / L``, so every ``L`` returns
        ``s``. For noise correlated over fewer than ``L`` samples the block
        means have variance ``S0 / (L dt)`` (``S0``: two-sided power spectral
        density at low frequency, x^2/Hz), so the result is
        ``sqrt(S0 / dt)``, the standard deviation of the white noise with the
        same low-frequency density: the level that matters to a
        regularisation acting on time scales longer than ``L`` samples. The
        median absolute deviation is robust to spikes and to the slow signal,
        whose contribution (third derivative times ``(L dt)**3``) grows with
        ``L``.
    """
    x = np.asarray(x, dtype=float)
    if isinstance(lag, bool) or not isinstance(lag, (int, np.integer)) or lag < 1:
        raise InputError(f"lag must be a positive integer (samples); got {lag!r}")
    if x.shape[0] < 4 * lag:
        raise InputError(f"need at least 4 * lag = {4 * lag} samples to estimate the noise level; got {x.shape[0]}")
    if lag == 1:
        d = np.diff(x, 3, axis=0)
    else:
        # Moving mean over `lag` samples from a cumulative sum: O(n) for any lag.
        c = np.cumsum(np.concatenate([np.zeros((1,) + x.shape[1:]), x], axis=0), axis=0)
        m = (c[lag:] - c[:-lag]) / lag
        d = m[3 * lag :] - 3.0 * m[2 * lag : -lag] + 3.0 * m[lag : -2 * lag] - m[: -3 * lag]
    mad = np.median(np.abs(d - np.median(d, axis=0)), axis=0)
    return math.sqrt(lag) * _MAD_TO_STD * mad / math.sqrt(20.0)


def tv_derivative(
    x: np.ndarray,
    dt: float,
    *,
    alpha: float | None = None,
    time_scale: float = _TV_TIME_SCALE,
    huber: float = _TV_HUBER,
    noise_scale: float = _TV_NOISE_SCALE,
    tol: float = _TV_TOL,
    max_iter: int = _TV_MAX_ITER,
) -> TVDerivativeResult:
    """Total-variation regularised derivative (Chartrand 2011), exact solver.

    Minimises ``1/2 ||g - x||^2 + alpha * sum H((g[i+1] - 2 g[i] + g[i-1]) / dt)``
    over the antiderivative ``g`` (module docstring: this is Chartrand's
    ``alpha TV(u) + 1/2 ||A u + c - x||^2`` with exact integration of a
    piecewise-constant ``u``), ``H = |.|`` or its Huber smoothing.

    Parameters
    ----------
    x : array_like, shape (n,) or (n, k), n >= 5
        Samples on a uniform grid, columns independent (e.g. three sections).
        Must be finite: split records at NaN gaps first.
    dt : float
        Sampling interval, s.
    alpha : float or None
        TV weight in units of x times s (same meaning as Chartrand's ``alph``
        for data on a grid of step ``dt``), one value for all columns; None
        for the automatic rule ``sigma * dt * (time_scale / dt) ** 1.5`` with
        ``sigma`` estimated per column at ``noise_scale``
        (:func:`estimate_noise_std`, module docstring).
    time_scale : float
        ``tau``, s: noise alone does not create derivative steps closer than
        about ``tau`` (used only by the automatic ``alpha`` and by ``huber``).
        Default 10.
    huber : float
        Dimensionless Huber threshold: changes of the derivative per sample
        below ``huber * sigma * dt / tau**2`` are penalised quadratically.
        0 (default) gives exact TV.
    noise_scale : float
        Time scale at which the noise level ``sigma`` is measured, s (>= 0):
        :func:`estimate_noise_std` with block length
        ``max(1, round(noise_scale / dt))`` samples (at most a quarter of the
        record). 0 (default) gives the plain third differences, the
        white-noise estimate; ``time_scale / 2`` measures the noise where the
        regulariser acts (module docstring: the setting for band-limited
        envelope noise). Used only by the automatic ``alpha`` and by
        ``huber``.
    tol : float
        Stopping tolerance on the duality gap relative to the objective.
    max_iter : int
        Maximum interior-point iterations; a ``RuntimeWarning`` is issued if
        reached.

    Returns
    -------
    TVDerivativeResult
    """
    _check_positive("dt", dt)
    _check_positive("time_scale", time_scale)
    if alpha is not None:
        _check_positive("alpha", alpha)
    if not (math.isfinite(huber) and huber >= 0):
        raise InputError(f"huber must be a finite number >= 0; got {huber!r}")
    _check_nonnegative("noise_scale", noise_scale)
    if not 0.0 < tol < 1.0:
        raise InputError(f"tol must lie strictly between 0 and 1; got {tol!r}")
    if int(max_iter) != max_iter or max_iter < 1:
        raise InputError(f"max_iter must be a positive integer; got {max_iter!r}")
    x = _as_samples(x, min_samples=5)
    one_d = x.ndim == 1
    f = x.reshape(x.shape[0], -1)
    n, k = f.shape

    # Normalise each column to zero mean and unit RMS: the problem is
    # equivariant to this (alpha and delta scale alike) and the solver's
    # tolerances become dimensionless.
    mean = f.mean(axis=0)
    scale = np.sqrt(np.mean((f - mean) ** 2, axis=0))
    constant = scale == 0.0
    scale = np.where(constant, 1.0, scale)
    y = (f - mean) / scale

    need_sigma = alpha is None or huber > 0
    if need_sigma:
        # Block length of the noise estimate; capped so that a short record
        # still holds one lag-L third difference.
        lag = int(min(max(1, round(noise_scale / dt)), n // 4))
        sigma_n = np.maximum(estimate_noise_std(y, lag), _NOISE_FLOOR)
        noise_std = sigma_n * scale
    else:
        sigma_n = np.full(k, np.nan)
        noise_std = np.full(k, np.nan)
    if alpha is None:
        alpha_n = sigma_n * dt * (time_scale / dt) ** 1.5
    else:
        alpha_n = np.full(k, float(alpha)) / scale
    delta_n = huber * sigma_n * dt / time_scale**2 if huber > 0 else np.zeros(k)

    g, iterations, converged, gap = _tv_interior_point(y, dt, alpha_n, delta_n, tol, int(max_iter))
    if not np.all(converged):
        warnings.warn(
            f"tv_derivative: interior-point solver stopped after {iterations} iterations with relative "
            f"duality gap {np.max(gap):.2e} > tol {tol:.1e}; raise max_iter or tol",
            RuntimeWarning,
            stacklevel=2,
        )
    g = np.where(constant, 0.0, g)
    dgdt = np.gradient(g, dt, axis=0) * scale
    x_smooth = g * scale + mean
    alpha_out = alpha_n * scale
    if one_d:
        return TVDerivativeResult(dgdt[:, 0], x_smooth[:, 0], alpha_out[0], noise_std[0], iterations, bool(converged.all()))
    return TVDerivativeResult(dgdt, x_smooth, alpha_out, noise_std, iterations, bool(converged.all()))


@dataclass(frozen=True, kw_only=True)
class Derivative:
    """Configuration of the numerical derivative of the identification chain.

    Options that belong to a method other than ``method`` must stay None; a
    None option takes the method's default.

    Parameters
    ----------
    method : {"tv", "savgol", "spline", "finite_difference"}
        ``"tv"``: total-variation regularised (:func:`tv_derivative`, the
        default of docs/field_workflow.md). ``"savgol"``: Savitzky-Golay derivative
        (``scipy.signal.savgol_filter`` with ``deriv=1``). ``"spline"``: cubic
        smoothing spline (``scipy.interpolate.make_smoothing_spline``),
        differentiated. ``"finite_difference"``: ``pysindy.FiniteDifference``.
    alpha : float, optional
        tv: TV weight, units of x times s; default automatic (see module).
    time_scale : float, optional
        tv: time scale of the automatic rule, s; default 10.
    huber : float, optional
        tv: dimensionless Huber threshold; default 0 (exact TV).
    noise_scale : float, optional
        tv: time scale at which the noise level of the automatic rule is
        measured, s; default 0 (white-noise estimate from plain third
        differences). ``Derivative(time_scale=20, huber=10, noise_scale=10)``
        is the band-limited-noise setting of the module docstring
        (:meth:`for_envelope`, the identification chain's default): about
        2.7x more accurate dA/dt on campaign envelopes.
    tol : float, optional
        tv: relative duality-gap tolerance; default 1e-6.
    max_iter : int, optional
        tv: maximum interior-point iterations; default 100.
    window : float, optional
        savgol: window length, s (rounded to an odd number of samples);
        default 20.
    polyorder : int, optional
        savgol: polynomial order; default 3.
    smoothing : float, optional
        spline: penalty ``lam`` on the integral of the squared second
        derivative, s^3; default chosen per column by generalised
        cross-validation.
    fd_order : int, optional
        finite_difference: order of accuracy; default 2 (central
        differences, one-sided at the ends).
    """

    method: Literal["tv", "savgol", "spline", "finite_difference"] = "tv"
    alpha: float | None = None
    time_scale: float | None = None
    huber: float | None = None
    noise_scale: float | None = None
    tol: float | None = None
    max_iter: int | None = None
    window: float | None = None
    polyorder: int | None = None
    smoothing: float | None = None
    fd_order: int | None = None

    def __post_init__(self) -> None:
        if self.method not in DERIVATIVE_METHODS:
            raise InputError(f"method must be one of {DERIVATIVE_METHODS}; got {self.method!r}")
        for method, names in _METHOD_OPTIONS.items():
            if method == self.method:
                continue
            for name in names:
                if getattr(self, name) is not None:
                    raise InputError(f"option {name!r} applies only to method={method!r}; got method={self.method!r}")
        for name in ("alpha", "time_scale", "window"):
            value = getattr(self, name)
            if value is not None:
                _check_positive(name, value)
        if self.huber is not None and not (math.isfinite(self.huber) and self.huber >= 0):
            raise InputError(f"huber must be a finite number >= 0; got {self.huber!r}")
        if self.noise_scale is not None:
            _check_nonnegative("noise_scale", self.noise_scale)
        if self.tol is not None and not 0.0 < self.tol < 1.0:
            raise InputError(f"tol must lie strictly between 0 and 1; got {self.tol!r}")
        if self.smoothing is not None and not (math.isfinite(self.smoothing) and self.smoothing >= 0):
            raise InputError(f"smoothing must be a finite number >= 0 (s^3); got {self.smoothing!r}")
        for name in ("max_iter", "polyorder", "fd_order"):
            value = getattr(self, name)
            if value is not None and (isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1):
                raise InputError(f"{name} must be a positive integer; got {value!r}")

    @classmethod
    def for_envelope(cls, method: str = "tv", **options) -> "Derivative":
        """The derivative for Hilbert envelopes of band-pass filtered vibration.

        For ``method="tv"`` the options not given take the band-limited-noise
        setting (``time_scale=20, huber=10, noise_scale=10``): the envelope's
        noise is correlated over seconds, which the white-noise rule does not
        see. Other methods take their own defaults. This is the default of
        the identification chain (``IdentifyConfig``, ``vivbench identify``,
        comparisons and sweeps).
        """
        if method == "tv":
            options = {**_ENVELOPE_TV, **options}
        return cls(method=method, **options)

    def differentiate(self, x: np.ndarray, t: np.ndarray | float) -> np.ndarray:
        """Time derivative of ``x``.

        Parameters
        ----------
        x : array_like, shape (n,) or (n, k)
            Samples along axis 0 (e.g. envelopes of k sections, m); finite.
        t : array_like, shape (n,), or float
            Sample times (s, strictly increasing; uniform for "tv" and
            "savgol") or the sampling interval.

        Returns
        -------
        dxdt : ndarray, shape of ``x``, units of x per s

        Raises
        ------
        ValueError
            If ``x`` contains NaN or infinity (split the record at gaps), or
            the time grid is invalid.
        """
        return self.smooth_and_differentiate(x, t)[1]

    def smooth_and_differentiate(self, x: np.ndarray, t: np.ndarray | float) -> tuple[np.ndarray, np.ndarray]:
        """The method's smoothed signal and derivative (parameters as :meth:`differentiate`).

        Returns
        -------
        x_smooth : ndarray, shape of ``x``
            The regularised signal (tv), the Savitzky-Golay or spline fit, or
            ``x`` itself (finite_difference).
        dxdt : ndarray, shape of ``x``, units of x per s
        """
        x = _as_samples(x, min_samples=3)
        times, dt = _as_times(t, x.shape[0], uniform=self.method in ("tv", "savgol"))
        if self.method == "tv":
            res = tv_derivative(
                x,
                dt,
                alpha=self.alpha,
                time_scale=_default(self.time_scale, _TV_TIME_SCALE),
                huber=_default(self.huber, _TV_HUBER),
                noise_scale=_default(self.noise_scale, _TV_NOISE_SCALE),
                tol=_default(self.tol, _TV_TOL),
                max_iter=_default(self.max_iter, _TV_MAX_ITER),
            )
            return res.x_smooth, res.dxdt
        if self.method == "savgol":
            return _savgol(x, dt, _default(self.window, _SAVGOL_WINDOW), _default(self.polyorder, _SAVGOL_POLYORDER))
        if self.method == "spline":
            return _spline(x, times, self.smoothing)
        return x, _finite_difference(x, times, _default(self.fd_order, _FD_ORDER))


# ---------------------------------------------------------------------------
# TV solver


def _d2(v: np.ndarray) -> np.ndarray:
    """Second difference along the last axis: shape (k, n) -> (k, n - 2)."""
    return v[:, :-2] - 2.0 * v[:, 1:-1] + v[:, 2:]


def _d2t(w: np.ndarray) -> np.ndarray:
    """Adjoint of :func:`_d2`: shape (k, m) -> (k, m + 2)."""
    out = np.zeros((w.shape[0], w.shape[1] + 2))
    out[:, :-2] += w
    out[:, 1:-1] -= 2.0 * w
    out[:, 2:] += w
    return out


def _huber_sum(s: np.ndarray, delta: np.ndarray) -> np.ndarray:
    """Row sums of the Huber function of threshold ``delta`` (k, 1); |s| where delta == 0."""
    a = np.abs(s)
    safe = np.where(delta > 0, delta, 1.0)
    return np.sum(np.where(a <= delta, 0.5 * s * s / safe, a - 0.5 * delta), axis=1)


def _tv_interior_point(
    y: np.ndarray, dt: float, lam: np.ndarray, delta: np.ndarray, tol: float, max_iter: int
) -> tuple[np.ndarray, int, np.ndarray, np.ndarray]:
    """Primal-dual interior point for Huber/l1 trend filtering, columns at once.

    Primal: ``min_g 1/2 ||g - y||^2 + lam * sum H_delta(D g)`` with
    ``D = D2 / dt``. Dual: ``min_nu 1/2 nu' Q nu - b' nu`` subject to
    ``|nu| <= lam``, ``Q = D D' + (delta / lam) I``, ``b = D y``; primal from
    dual ``g = y - D' nu``.

    Parameters
    ----------
    y : ndarray, shape (n, k)
        Normalised data, one column per signal.
    dt : float
        Step, s.
    lam, delta : ndarray, shape (k,)
        TV weight (> 0) and Huber threshold (>= 0) per column.
    tol : float
        Relative duality-gap tolerance.
    max_iter : int
        Iteration limit.

    Returns
    -------
    g : ndarray, shape (n, k)
    iterations : int
    converged : ndarray of bool, shape (k,)
    rel_gap : ndarray, shape (k,)
    """
    # Work with one row per signal so that reductions and the stacked banded
    # solve run over contiguous memory.
    y = np.ascontiguousarray(y.T)
    k, n = y.shape
    m = n - 2
    inv_dt = 1.0 / dt
    inv_dt2 = inv_dt * inv_dt
    lam = lam[:, None]
    delta = delta[:, None]
    ridge = delta / lam
    b = _d2(y) * inv_dt

    # Block-banded (upper) storage of Q for the k stacked signals; couplings
    # across block boundaries are zero so the signals stay independent in
    # one LAPACK call.
    pos = np.arange(k * m) % m
    band = np.empty((3, k * m))
    band[0] = np.where(pos >= 2, inv_dt2, 0.0)
    band[1] = np.where(pos >= 1, -4.0 * inv_dt2, 0.0)
    diag_q = 6.0 * inv_dt2 + ridge  # (k, 1)

    def q_mul(v: np.ndarray) -> np.ndarray:
        return _d2(_d2t(v)) * inv_dt2 + ridge * v

    def residual(nu, mu1, mu2, q_nu, inv_t):
        rd = q_nu - b + mu1 - mu2
        r1 = mu1 * (lam - nu) - inv_t
        r2 = mu2 * (lam + nu) - inv_t
        return np.sqrt(np.einsum("ij,ij->i", rd, rd) + np.einsum("ij,ij->i", r1, r1) + np.einsum("ij,ij->i", r2, r2))

    nu = np.zeros((k, m))
    mu1 = np.ones((k, m))
    mu2 = np.ones((k, m))
    q_nu = np.zeros((k, m))
    t = np.ones((k, 1))
    # The gap is compared with the objective plus a floor for noise-free data
    # (objective ~ 0): n times the squared relative noise floor.
    floor = n * _NOISE_FLOOR**2
    # Round-off bounds the attainable gap (Q is ill-conditioned for long
    # records and large weights): keep the best iterate and retire a signal
    # whose gap stops improving or whose slacks approach machine precision,
    # before the barrier drives a slack to exactly zero.
    best_gap = np.full(k, np.inf)
    best_nu = nu.copy()
    stall = np.zeros(k, dtype=int)
    for iterations in range(max_iter + 1):
        # Duality gap at the primal point g(nu) = y - D' nu.
        dtnu = _d2t(nu) * inv_dt
        primal = 0.5 * np.einsum("ij,ij->i", dtnu, dtnu) + lam[:, 0] * _huber_sum(b - q_nu + ridge * nu, delta)
        dual = np.einsum("ij,ij->i", b, nu) - 0.5 * np.einsum("ij,ij->i", nu, q_nu)
        rel_gap = (primal - dual) / (primal + floor)
        rel_gap = np.where(np.isfinite(rel_gap), rel_gap, np.inf)
        improved = rel_gap < best_gap
        best_gap = np.where(improved, rel_gap, best_gap)
        best_nu[improved] = nu[improved]
        stall = np.where(improved, 0, stall + 1)
        slack1 = lam - nu  # > 0
        slack2 = lam + nu  # > 0
        tight = np.minimum(slack1, slack2).min(axis=1) <= _IP_MIN_SLACK * lam[:, 0]
        done = (best_gap <= tol) | (stall >= _IP_MAX_STALL) | tight
        if np.all(done) or iterations == max_iter:
            break
        eta = np.einsum("ij,ij->i", mu1, slack1) + np.einsum("ij,ij->i", mu2, slack2)
        t = np.maximum(t, (_IP_MU * 2.0 * m / eta)[:, None])
        inv_t = 1.0 / t
        j1 = mu1 / slack1
        j2 = mu2 / slack2
        rhs = b - q_nu - inv_t * (1.0 / slack1 - 1.0 / slack2)
        band[2] = (diag_q + j1 + j2).reshape(-1)
        dnu = solveh_banded(band, rhs.reshape(-1), check_finite=False).reshape(k, m)
        dmu1 = inv_t / slack1 - mu1 + j1 * dnu
        dmu2 = inv_t / slack2 - mu2 - j2 * dnu

        # Longest step keeping the iterate strictly interior, per signal.
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            limit = np.minimum(
                np.minimum(np.where(dmu1 < 0, -mu1 / dmu1, np.inf), np.where(dmu2 < 0, -mu2 / dmu2, np.inf)),
                np.where(dnu > 0, slack1 / dnu, np.where(dnu < 0, -slack2 / dnu, np.inf)),
            ).min(axis=1)
        step = np.where(done, 0.0, _IP_STEP_FRACTION * np.minimum(1.0, limit))[:, None]
        # Backtracking on the norm of the KKT residual.
        r0 = residual(nu, mu1, mu2, q_nu, inv_t)
        q_dnu = q_mul(dnu)
        pending = ~done
        for _ in range(_IP_MAX_HALVINGS):
            r = residual(nu + step * dnu, mu1 + step * dmu1, mu2 + step * dmu2, q_nu + step * q_dnu, inv_t)
            pending &= r > (1.0 - _IP_ARMIJO * step[:, 0]) * r0
            if not pending.any():
                break
            step = np.where(pending[:, None], 0.5 * step, step)
        nu = nu + step * dnu
        mu1 = mu1 + step * dmu1
        mu2 = mu2 + step * dmu2
        # Recompute rather than update so that round-off does not accumulate.
        q_nu = q_mul(nu)
    g = y - _d2t(best_nu) * inv_dt
    return g.T, iterations, best_gap <= tol, best_gap


# ---------------------------------------------------------------------------
# Comparison methods (thin wrappers)


def _savgol(x: np.ndarray, dt: float, window: float, polyorder: int) -> tuple[np.ndarray, np.ndarray]:
    n = x.shape[0]
    length = int(round(window / dt))
    length += 1 - length % 2  # odd
    if length <= polyorder:
        raise InputError(
            f"savgol window of {window} s is {length} samples at dt = {dt} s; it must exceed polyorder = {polyorder}"
        )
    if length > n:
        raise InputError(f"savgol window of {window} s is {length} samples, longer than the record ({n} samples)")
    smooth = savgol_filter(x, length, polyorder, deriv=0, axis=0, mode="interp")
    dxdt = savgol_filter(x, length, polyorder, deriv=1, delta=dt, axis=0, mode="interp")
    return smooth, dxdt


def _spline(x: np.ndarray, times: np.ndarray, lam: float | None) -> tuple[np.ndarray, np.ndarray]:
    if x.shape[0] < 5:
        raise InputError(f"the smoothing spline needs at least 5 samples; got {x.shape[0]}")
    spline = make_smoothing_spline(times, x, lam=lam, axis=0)
    return spline(times), spline.derivative()(times)


def _finite_difference(x: np.ndarray, times: np.ndarray, order: int) -> np.ndarray:
    from pysindy import FiniteDifference  # deferred: pysindy is slow to import

    if x.shape[0] <= order:
        raise InputError(f"finite differences of order {order} need more than {order} samples; got {x.shape[0]}")
    return np.asarray(FiniteDifference(order=order, axis=0)(x, times), dtype=float)


# ---------------------------------------------------------------------------
# Input checks


def _default(value, default):
    return default if value is None else value


def _check_nonnegative(name: str, value) -> None:
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise InputError(f"{name} must be a number >= 0; got {value!r}")
    if not (math.isfinite(value) and value >= 0):
        raise InputError(f"{name} must be a finite number >= 0; got {value!r}")


def _check_positive(name: str, value) -> None:
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise InputError(f"{name} must be a positive number; got {value!r}")
    if not (math.isfinite(value) and value > 0):
        raise InputError(f"{name} must be a finite number > 0; got {value!r}")


def _as_samples(x: np.ndarray, min_samples: int) -> np.ndarray:
    x = np.asarray(x, dtype=float)
    if x.ndim not in (1, 2):
        raise ValueError(f"x must have shape (n,) or (n, k); got shape {x.shape}")
    if x.shape[0] < min_samples:
        raise InputError(f"x needs at least {min_samples} samples along axis 0; got {x.shape[0]}")
    bad = ~np.isfinite(x)
    if bad.any():
        first = int(np.argwhere(bad)[0][0])
        raise ValueError(
            f"x contains {int(bad.sum())} NaN or infinite values (first at sample {first}); "
            "split the record at gaps and differentiate each finite piece"
        )
    return x


def _as_times(t: np.ndarray | float, n: int, *, uniform: bool) -> tuple[np.ndarray, float]:
    """Sample times and the (mean) step from an array of times or a step."""
    if np.ndim(t) == 0:
        dt = float(t)
        _check_positive("the sampling interval t", dt)
        return np.arange(n) * dt, dt
    times = np.asarray(t, dtype=float)
    if times.shape != (n,):
        raise ValueError(f"t must be a step or have shape ({n},) to match x; got shape {times.shape}")
    if not np.all(np.isfinite(times)):
        raise InputError("t contains NaN or infinite times")
    steps = np.diff(times)
    if np.any(steps <= 0):
        raise InputError("t must be strictly increasing")
    dt = (times[-1] - times[0]) / (n - 1)
    if uniform and np.max(np.abs(steps - dt)) > _UNIFORM_RTOL * dt:
        raise InputError(
            f"this method needs a uniform time grid; steps range from {steps.min()} s to {steps.max()} s "
            "(resample first or use method='spline' or 'finite_difference')"
        )
    return times, dt
