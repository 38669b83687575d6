"""One SINDy model for a whole campaign, and the regimes it gives every window.

Why: inside a 50 s window the orders of A cannot be told apart (docs/concepts.md (regimes)),
because U drifts smoothly and U^j then acts as a time basis. The aeroelastic
truth is, however, time-invariant as a function of (A, U): the coefficients of
A^i vary only through the wind, which the library's U^j already carries. Pooled
over a campaign, A and U range widely and the same 69-term library becomes
identifiable. The pooled model is fitted by the same STLSQ path and AICc as the
windows; each window's regime is the rule of docs/concepts.md (regimes) applied to the pooled
model's order contributions over that window's data.

Identifiability of a window's regime is judged by a moving-block bootstrap:
the samples are cut into contiguous blocks (default 300 s, longer than the
correlation time of derivative errors), blocks are resampled with replacement,
and the whole selection (threshold path and AICc) is rerun on every replicate.
A window counts as identifiable when at least ``agreement`` of the replicate
models give it the pooled model's regime (and, in :func:`pool_results`, when
its amplitude is above the accelerometers' noise floor by the identification's
``min_snr``, see :mod:`vivbench.preprocess.noise_floor`).

Each block is compressed once to the R factor of the QR decomposition of
[Theta_b | y_b]: a replicate is then a weighted stack of these small factors,
which gives exactly the least-squares (and ridge) problems of the resampled
data at a fraction of the cost, and the residual outside each block's column
space is added back so RSS and AICc are those of the full replicate.

What this does not show: a campaign model explains dynamics that are a fixed
function of (A, U); it cannot follow changes that are not carried by the wind
(deck modifications, ice, traffic). On field data that assumption is the
user's to check; the window models remain the paper's method.
"""

from __future__ import annotations

import json
from collections.abc import Sequence

import numpy as np

import xarray as xr

import vivbench
from vivbench.io.campaign_model import (CAMPAIGN_MODEL_FORMAT, CAMPAIGN_MODEL_VERSION, read_campaign_model,
                                       write_campaign_model)
from vivbench.regression.bootstrap import block_counts
from vivbench.regression.settings import DEFAULT_THRESHOLDS, StlsqSettings
from vivbench.regression.stlsq import aicc, stlsq_path
from vivbench.library.basis import window_library
from vivbench.core.record import Record
from vivbench.core.regime import DEFAULT_TAU
from vivbench.core.terms import evaluate_library, feature_exponents, feature_names
from vivbench.core.errors import InputError
from vivbench.models.protocol import (
    ModelBase,
    NotFittedError,
    as_record,
    coef_order_contributions,
    format_equations,
    section_names,
    simulate_windows,
)
from vivbench.models.campaign_verdicts import campaign_window_verdicts
from vivbench.models.simulate import Simulation
from vivbench.preprocess.wind_smoothing import smooth_wind

__all__ = ["PooledSINDy", "amplitude_ratios", "RATIO_LEVEL"]

#: Samples whose amplitude is below this share of the section's largest amplitude
#: do not enter the amplitude ratios (there A is mostly noise and ratios scatter).
RATIO_LEVEL = 0.1


def amplitude_ratios(A: np.ndarray, level: float = RATIO_LEVEL) -> np.ndarray:
    """Median amplitude ratios A_l / A_k over the samples where both sections vibrate.

    Parameters
    ----------
    A : ndarray, shape (n, S), m
        Amplitudes (NaN: no sample).
    level : float
        A sample counts for the pair (k, l) when A_k and A_l both exceed this
        share of their section's largest finite amplitude.

    Returns
    -------
    ratios : ndarray, shape (S, S)
        ratios[k, l] = median of A_l / A_k; 1 on the diagonal; NaN for a pair
        without such samples.
    """
    A = np.asarray(A, dtype=float)
    S = A.shape[1]
    finite = np.isfinite(A)
    top = np.array([np.max(A[finite[:, k], k], initial=0.0) for k in range(S)])
    big = finite & (A > level * top[None, :]) & (A > 0)
    both = big[:, :, None] & big[:, None, :]  # (n, k, l)
    with np.errstate(invalid="ignore", divide="ignore"):
        ratio = np.where(both, A[:, None, :] / np.where(big, A, 1.0)[:, :, None], np.nan)
    out = np.full((S, S), np.nan)
    has = both.any(axis=0)
    if has.any():
        # nanmedian only over pairs with samples (it warns on all-NaN columns)
        out[has] = np.nanmedian(ratio[:, has], axis=0)
    np.fill_diagonal(out, 1.0)
    return out


def _blocks(t: np.ndarray, ok: np.ndarray, block_s: float) -> np.ndarray:
    """Block id of each sample of one record (-1 where not used)."""
    ids = np.full(t.shape, -1, dtype=np.int64)
    if ok.any():
        rel = t - t[ok][0]
        ids[ok] = np.floor(rel[ok] / block_s).astype(np.int64)
        # Compact the ids so empty blocks (gaps) do not exist.
        _, ids[ok] = np.unique(ids[ok], return_inverse=True)
    return ids


def _block_factors(theta: np.ndarray, y: np.ndarray, block: np.ndarray, n_blocks: int):
    """R factors of [theta_b | y_b] of every block.

    Returns R (n_blocks, p, p), z (n_blocks, p, q), rss0 (n_blocks, q) and the
    sample count and sum of y^2 of each block.
    """
    n, p = theta.shape
    q = y.shape[1]
    R = np.zeros((n_blocks, p, p))
    z = np.zeros((n_blocks, p, q))
    rss0 = np.zeros((n_blocks, q))
    order = np.argsort(block, kind="stable")
    bounds = np.searchsorted(block[order], np.arange(n_blocks + 1))
    counts = np.diff(bounds)
    yy = np.zeros((n_blocks, q))
    # One QR per block (a few hundred per campaign), not per sample.
    for b in range(n_blocks):
        rows = order[bounds[b]:bounds[b + 1]]
        M = np.hstack([theta[rows], y[rows]])
        r = np.linalg.qr(M, mode="r")
        k = min(r.shape[0], p)
        R[b, :k] = r[:k, :p]
        z[b, :k] = r[:k, p:]
        rss0[b] = (r[p:, p:] ** 2).sum(axis=0) if r.shape[0] > p else 0.0
        yy[b] = (y[rows] ** 2).sum(axis=0)
    return R, z, rss0, counts, yy


def _select(path, rss_true, n_samples, floor):
    """Re-select along the path with the replicates' true RSS and N."""
    scores = aicc(rss_true, path.n_terms, n_samples[:, None, None], floor=floor[..., None])
    scores = np.where(np.isfinite(path.aicc), scores, np.inf)
    sel = np.argmin(scores, axis=2)
    has = np.isfinite(scores).any(axis=2)
    pick = np.take_along_axis(path.coef, sel[:, :, None, None], axis=2)[:, :, 0]
    best_rss = np.take_along_axis(rss_true, sel[:, :, None], axis=2)[:, :, 0]
    best_aicc = np.take_along_axis(scores, sel[:, :, None], axis=2)[:, :, 0]
    pick = np.where(has[..., None], pick, np.nan)
    return pick, sel, best_rss, best_aicc, has


def _integrated_correlation(resid: np.ndarray) -> np.ndarray:
    """Integrated autocorrelation time (in samples) of each residual column.

    1 + 2 sum_k rho_k, summed up to the first lag where rho turns non-positive:
    the factor by which correlated residuals inflate the variance of a
    least-squares estimate relative to independent ones.
    """
    n, q = resid.shape
    r = resid - resid.mean(axis=0)
    size = 1 << int(np.ceil(np.log2(2 * n)))
    spec = np.fft.rfft(r, size, axis=0)
    acf = np.fft.irfft(spec * np.conj(spec), size, axis=0)[: n // 10 + 2]
    rho = acf / np.where(acf[0] > 0, acf[0], 1.0)
    out = np.ones(q)
    for k in range(q):  # a handful of equations
        neg = np.flatnonzero(rho[1:, k] <= 0)
        stop = neg[0] + 1 if neg.size else rho.shape[0]
        out[k] = max(1.0, 1.0 + 2.0 * rho[1:stop, k].sum())
    return out


def _replicate_fits(factors, mult: np.ndarray, settings: StlsqSettings, chunk_size: int):
    """Threshold path and AICc selection of every replicate.

    Parameters
    ----------
    factors : output of :func:`_block_factors`
    mult : ndarray, shape (n_replicates, n_blocks)
        How many times each block occurs in each replicate.

    Returns
    -------
    coef (n_replicates, q, p) in the regression basis (NaN without a model),
    selected path index, RSS and AICc (n_replicates, q) of the standardised targets.
    """
    R, z, rss0, counts, yy = factors
    n_blocks, p, _ = R.shape
    q = z.shape[2]
    out = []
    for c0 in range(0, mult.shape[0], chunk_size):
        m = mult[c0:c0 + chunk_size]
        w = np.sqrt(m)[:, :, None, None]
        X = (w * R[None]).reshape(m.shape[0], n_blocks * p, p)
        Y = (w * z[None]).reshape(m.shape[0], n_blocks * p, q)
        path = stlsq_path(X, Y, settings)
        N = (m * counts[None]).sum(axis=1)
        rss_true = path.rss + (m @ rss0)[:, :, None]
        floor = settings.residual_floor**2 * (m @ yy)
        pick, sel, best_rss, best_aicc, _has = _select(path, rss_true, N, floor)
        out.append((pick, sel, best_rss, best_aicc))
    return tuple(np.concatenate([o[k] for o in out]) for k in range(4))


class PooledSINDy(ModelBase):
    """STLSQ + AICc on all samples of a campaign, with a block bootstrap of the selection.

    The pooled model (method ``pooled``, ``vivbench pool --model pooled``): one
    sparse model of the 69-term library for the whole campaign, a model of the
    protocol (:mod:`vivbench.models.protocol`): ``fit(records)``, ``predict``,
    ``order_contributions``, ``simulate``, ``curves`` (docs/concepts.md
    (coefficient curves)), ``save``/``load`` (NetCDF), ``equations``/``print``.

    Parameters
    ----------
    thresholds : sequence of float
        Threshold path on the standardised coefficients (as the window engine).
    alpha : float
        Ridge parameter (as the window engine's default).
    scaling : {"scaled", "normalized", "raw"}
        Regression basis (``vivbench.library.basis``), fixed from all samples.
    n_bootstrap : int
        Bootstrap replicates (0: no identifiability verdict; every window flagged not identifiable).
    block_s : float
        Block length of the moving-block bootstrap, s.
    agreement : float
        Share of replicates that must give a window the pooled model's regime
        for the window to count as identifiable.
    min_blocks : int
        Fewer bootstrap blocks than this (too little data: the resamples
        cannot show how the selection varies) and no window is flagged
        identifiable; ``enough_data_`` says so.
    confidence : float
        Level of the joint confidence region of the coefficients (chi-square
        in p dimensions, residual variance inflated by the residuals'
        integrated correlation time); the near-null-space test asks whether
        any model in that region gives a window another regime.
    tau : float
        Regime threshold of docs/concepts.md (regimes).
    seed : int
        Seed of the bootstrap.
    chunk_size : int
        Replicates solved together (memory: chunk_size x n_blocks x 69^2 floats).
    wind_smoothing_s : float or None, s, >= 0
        Gaussian smoothing of the measured U and yaw before the fit, applied again by
        :meth:`measured_wind` when the model is evaluated on measured records (as
        :class:`vivbench.models.VaryingCoefficientSINDy` does; a candidate of a model selection
        then sees the wind as the others do). None: the model takes a record's wind as given and
        has no ``measured_wind`` (the caller smooths, e.g. ``vivbench pool --wind-smoothing``).

    Attributes
    ----------
    coef_ : ndarray, shape (S, 23 S)
        Physical coefficients on ``vivbench.core.terms.evaluate_library``; dA_k/dt in m/s.
    coef_bootstrap_ : ndarray, shape (n_bootstrap, S, 23 S)
    support_, threshold_, n_terms_, rss_, aicc_ : the selected model per equation
    n_samples_, n_blocks_ : int
    cond_ : float
        Condition number of the scaled pooled library.
    feature_names_ : list of str
    n_sections_ : int
    amplitude_ratios_ : ndarray, shape (S, S)
        Median A_l / A_k of the fitted data (:func:`amplitude_ratios`), which
        fold the other sections into the curves.
    event_ids_ : list of str
        Records fitted.
    """

    def __init__(self, *, thresholds: Sequence[float] = DEFAULT_THRESHOLDS, alpha: float = 0.05,
                 scaling: str = "scaled", n_bootstrap: int = 100, block_s: float = 300.0,
                 agreement: float = 0.9, confidence: float = 0.95, min_blocks: int = 20, tau: float = DEFAULT_TAU, seed: int = 0,
                 chunk_size: int = 16, wind_smoothing_s: float | None = None):
        self.thresholds = thresholds
        self.wind_smoothing_s = wind_smoothing_s
        self.alpha = alpha
        self.scaling = scaling
        self.n_bootstrap = n_bootstrap
        self.block_s = block_s
        self.agreement = agreement
        self.confidence = confidence
        self.min_blocks = min_blocks
        self.tau = tau
        self.seed = seed
        self.chunk_size = chunk_size

    def to_json(self) -> str:
        """The parameters as a JSON object (sorted keys; thresholds as a list)."""
        params = self.get_params()
        params["thresholds"] = [float(x) for x in params["thresholds"]]
        return json.dumps(params, sort_keys=True)

    def _validate(self) -> None:
        if isinstance(self.n_bootstrap, bool) or not isinstance(self.n_bootstrap, (int, np.integer)) or self.n_bootstrap < 0:
            raise InputError(f"n_bootstrap must be an integer >= 0; got {self.n_bootstrap!r}")
        if not (np.isfinite(self.block_s) and self.block_s > 0):
            raise InputError(f"block_s must be a positive number of seconds; got {self.block_s!r}")
        if not 0.0 < self.agreement <= 1.0:
            raise InputError(f"agreement must lie in (0, 1]; got {self.agreement!r}")
        if isinstance(self.min_blocks, bool) or not isinstance(self.min_blocks, (int, np.integer)) or self.min_blocks < 1:
            raise InputError(f"min_blocks must be an integer >= 1; got {self.min_blocks!r}")
        if not 0.0 < self.confidence < 1.0:
            raise InputError(f"confidence must lie strictly between 0 and 1; got {self.confidence!r}")
        if not 0.0 < self.tau < 1.0:
            raise InputError(f"tau must lie strictly between 0 and 1; got {self.tau!r}")
        if isinstance(self.chunk_size, bool) or not isinstance(self.chunk_size, (int, np.integer)) or self.chunk_size < 1:
            raise InputError(f"chunk_size must be an integer >= 1; got {self.chunk_size!r}")
        w = self.wind_smoothing_s
        if w is not None and not (isinstance(w, (int, float, np.floating)) and not isinstance(w, bool)
                                  and np.isfinite(w) and w >= 0):
            raise InputError("wind_smoothing_s must be None (the wind as given) or a number of seconds >= 0; "
                             f"got {w!r}")

    def fit(self, records: Sequence[Record | tuple]) -> "PooledSINDy":
        """Fit the campaign model.

        Parameters
        ----------
        records : sequence of Record (or of legacy (t, A, U, dA) tuples)
            One per event (or segment): t shape (n,), s; A, U, dA shape (n, S)
            in m, m/s and m/s. Samples with a non-finite value are ignored.

        Returns
        -------
        self
        """
        self._validate()
        settings = StlsqSettings(thresholds=tuple(self.thresholds), alpha=self.alpha)
        records = [as_record(r, k) for k, r in enumerate(records)]
        if self.wind_smoothing_s is not None:
            records = [smooth_wind(r, float(self.wind_smoothing_s)) for r in records]
        As, Us, dAs, blocks = [], [], [], []
        offset = 0
        for rec in records:
            if rec.dA is None:
                raise ValueError(f"record {rec.event_id!r} has no dA: the campaign model is fitted to dA/dt")
            if As and rec.n_sections != As[0].shape[1]:
                raise ValueError(f"record {rec.event_id!r} has {rec.n_sections} sections, the others {As[0].shape[1]}")
            t, A, U, dA = rec.t, rec.A, rec.U, rec.dA
            ok = rec.valid(need_dA=True)
            b = _blocks(t, ok, self.block_s)
            As.append(A[ok]), Us.append(U[ok]), dAs.append(dA[ok]), blocks.append(b[ok] + offset)
            offset += int(b.max()) + 1 if ok.any() else 0
        if not As or sum(a.shape[0] for a in As) == 0:
            raise InputError("no valid samples to fit a pooled model")
        A, U, dA = np.concatenate(As), np.concatenate(Us), np.concatenate(dAs)
        block = np.concatenate(blocks)
        n, S = A.shape
        p = 23 * S
        if n < p + 2:
            raise InputError(f"{n} valid samples are too few for the {p}-term library")
        lib = window_library(A[None], U[None], scaling=self.scaling)
        ys = np.sqrt(np.mean(dA**2, axis=0))
        ys = np.where(ys > 0, ys, 1.0)
        y = dA / ys

        rng = np.random.default_rng(self.seed)
        # Replicate 0 is the data itself; the others resample blocks with replacement.
        mult = np.ones((1 + self.n_bootstrap, offset))
        if self.n_bootstrap:
            mult[1:] = block_counts(offset, self.n_bootstrap, rng, draw="indices")
        factors = _block_factors(lib.theta[0], y, block, offset)
        coef_scaled, sel, best_rss, best_aicc = _replicate_fits(factors, mult, settings, self.chunk_size)
        phys = lib.physical_coef(np.nan_to_num(coef_scaled)) * ys[None, :, None]
        phys = np.where(np.isfinite(coef_scaled).all(axis=-1, keepdims=True), phys, np.nan)

        th = np.asarray(settings.thresholds)
        self.coef_ = phys[0]
        self.coef_scaled_ = coef_scaled[0]
        self.coef_bootstrap_ = phys[1:]
        self.support_ = coef_scaled[0] != 0
        self.threshold_ = th[sel[0]]
        self.n_terms_ = self.support_.sum(axis=1)
        self.rss_ = best_rss[0] * ys**2
        self.aicc_ = best_aicc[0] + n * np.log(ys**2)
        self.n_samples_ = int(n)
        self.n_blocks_ = int(offset)
        self.enough_data_ = bool(offset >= self.min_blocks)
        R = factors[0]
        # The stacked block factors have the singular values of the whole library.
        self.cond_ = float(np.linalg.cond(R.reshape(-1, p)))
        self.y_scale_ = ys
        gram = np.einsum("bki,bkj->ij", R, R) + self.alpha * np.eye(p)
        self.gram_inv_ = np.linalg.inv(gram)
        self.to_physical_ = lib.to_physical[0]
        self.rss_scaled_ = best_rss[0]
        resid = y - lib.theta[0] @ np.nan_to_num(coef_scaled[0]).T
        self.correlation_samples_ = _integrated_correlation(resid)
        self.feature_names_ = feature_names(S)
        self.n_sections_ = S
        self.amplitude_ratios_ = amplitude_ratios(A)
        self.event_ids_ = [r.event_id for r in records]
        return self

    # -- the model protocol -------------------------------------------------------------------------

    @property
    def measured_wind(self):
        """``measured_wind(record)``: the record with its U and yaw smoothed as at fit (``wind_smoothing_s``);
        AttributeError when ``wind_smoothing_s`` is None (the model takes a record's wind as given)."""
        if self.wind_smoothing_s is None:
            raise AttributeError("measured_wind: this PooledSINDy takes a record's wind as given "
                                 "(wind_smoothing_s None)")
        sigma = float(self.wind_smoothing_s)
        return lambda record: smooth_wind(as_record(record), sigma)

    def fitted_wind_smoothing(self) -> float:
        """The smoothing of the measured wind at fit, s (0 when ``wind_smoothing_s`` is None)."""
        return 0.0 if self.wind_smoothing_s is None else float(self.wind_smoothing_s)

    def order_contributions(self, record: Record) -> np.ndarray:
        """Contributions of the orders of A to dA/dt.

        Parameters
        ----------
        record : Record (``dA`` not needed)

        Returns
        -------
        r : ndarray, shape (n_samples, n_sections, 4), m/s
            r[:, k, i] = sum_j of the order-i terms of equation k; NaN where A or U is missing.
        """
        record = self._check_record(record)
        return coef_order_contributions(record.A, record.U, self.coef_)

    def predict(self, record: Record) -> np.ndarray:
        """dA/dt of the model, shape (n_samples, n_sections), m/s (``evaluate_library(A, U) @ coef_.T``)."""
        record = self._check_record(record)
        return evaluate_library(record.A, record.U) @ self.coef_.T

    def simulate(self, record: Record, t0: float | None = None, t1: float | None = None, A0=None,
                 **kwargs) -> Simulation:
        """Integrate the model from A0 at t0 to t1 with the record's wind (RK4 of :mod:`vivbench.models.simulate`).

        Parameters
        ----------
        record : Record
        t0, t1 : float, s, optional
            Span, snapped to the record's samples (default: the whole record).
        A0 : array_like, shape (S,), m, optional
            Initial amplitudes (default: the record's A at t0).
        **kwargs
            ``u_interp``, ``bound_factor``, ``negative_tolerance`` of
            :func:`vivbench.models.simulate.simulate_identified`.

        Returns
        -------
        Simulation
        """
        record = self._check_record(record)
        t = record.t
        span = (t[0], t[-1] + 1.0)
        t0 = float(t[0]) if t0 is None else float(t0)
        t1 = float(t[-1]) if t1 is None else float(t1)
        return simulate_windows(record, self.coef_[None], np.array([span[0]]), np.array([span[1]]),
                                t0=t0, t1=t1, A0=A0, **kwargs)

    def curves(self, wind, level: float = 0.95) -> xr.Dataset:
        """Coefficient curves a_ki(U) of docs/concepts.md (coefficient curves) with bootstrap bands.

        With every section at the mean wind U and A_l = rho_kl A_k
        (``amplitude_ratios_``), equation k reads dA_k/dt = sum_i a_ki(U) A_k^i with
        a_ki(U) = sum_l sum_j xi_k,lij rho_kl^i U^j.

        Parameters
        ----------
        wind : array_like, shape (n_wind,), m/s
        level : float
            Level of the band: the (1 - level)/2 and (1 + level)/2 percentiles of
            the bootstrap replicates' curves, widened where needed to contain the
            point curve (a percentile band need not contain a biased estimate).

        Returns
        -------
        xarray.Dataset
            ``curves``, ``curves_lower``, ``curves_upper`` (equation, order, wind) in
            m^(1-i)/s; coordinates ``equation``, ``order`` (0..3), ``wind`` (m/s).
            Without bootstrap replicates the bands are NaN.
        """
        self._check_fitted()
        if not 0.0 < level < 1.0:
            raise ValueError(f"level must lie strictly between 0 and 1; got {level!r}")
        wind = np.atleast_1d(np.asarray(wind, dtype=float))
        if wind.ndim != 1 or not np.all(np.isfinite(wind)):
            raise ValueError("wind must be a 1-D array of finite speeds in m/s")
        point = self._curves(self.coef_[None], wind)[0]
        if self.coef_bootstrap_.shape[0]:
            boot = self._curves(self.coef_bootstrap_, wind)
            q = 50.0 * np.array([1.0 - level, 1.0 + level])
            with np.errstate(invalid="ignore"):
                lo, hi = np.nanpercentile(boot, q, axis=0)
            lower, upper = np.fmin(lo, point), np.fmax(hi, point)
        else:
            lower = upper = np.full_like(point, np.nan)
        dims = ("equation", "order", "wind")
        attrs = {"units": "m^(1-order) s-1", "long_name": "coefficient of A_k^order at mean wind U (docs/concepts.md (coefficient curves))"}
        return xr.Dataset(
            {"curves": (dims, point, attrs),
             "curves_lower": (dims, lower, {"units": attrs["units"], "long_name": f"lower {level:g} bootstrap band"}),
             "curves_upper": (dims, upper, {"units": attrs["units"], "long_name": f"upper {level:g} bootstrap band"})},
            coords={"equation": section_names(self.n_sections_), "order": np.arange(4),
                    "wind": ("wind", wind, {"units": "m/s"})},
            attrs={"model": type(self).__name__, "amplitude_ratios": json.dumps(self.amplitude_ratios_.tolist())},
        )

    def window_verdicts(self, record: Record, window_start, window_end) -> dict:
        """Regime of every window and its identifiability verdict (:func:`vivbench.regimes.campaign_window_verdicts`).

        Returns the dict of that function: ``regime``, ``identifiable``, ``agreement``, ``robust``,
        ``order_rms``, ``order_rms_margin`` (W windows, S sections).
        """
        record = as_record(record)
        return campaign_window_verdicts(self, record.t, record.A, record.U, np.asarray(window_start, dtype=float),
                                        np.asarray(window_end, dtype=float))

    def report_description(self, regimes) -> dict:
        """The report's paragraph on this model and its verdict (:func:`vivbench.models.model_description`).

        Parameters
        ----------
        regimes : xarray.Dataset, the model's ``campaign.regimes.nc``
        """
        text = ("One sparse model dA/dt = Theta(A, U) xi for the whole campaign, fitted by the same STLSQ path and "
                "AICc on all samples of all events (`vivbench.models.campaign`). A window's regime is the rule of "
                "docs/concepts.md (regimes) applied to this model's order contributions over the window's data; it "
                "counts as identifiable when (i) no model inside the coefficients' joint 95 % confidence region "
                "(residual variance inflated by the residuals' correlation time) gives the window another regime, "
                f"and (ii) at least {json.loads(regimes.attrs['model_config_json'])['agreement']:.0%} of "
                "block-bootstrap replicates of the whole selection agree. "
                f"Terms per equation: {', '.join(str(int(k)) for k in regimes['n_terms'].values)}; "
                f"{int(regimes.attrs['n_samples'])} samples in {int(regimes.attrs['n_blocks'])} blocks; "
                f"coverage {float(regimes.attrs['coverage']):.3f}."
                + (f" **{regimes.attrs['note']}**" if regimes.attrs.get("note") else ""))
        return {"text": text, "pool_options": ""}

    def terms_per_equation(self) -> list[int]:
        """Active library terms of each equation (``n_terms_``)."""
        self._check_fitted()
        return [int(k) for k in self.n_terms_]

    def settings_text(self) -> str:
        """One line on the fitted settings (:func:`vivbench.models.model_settings_text`)."""
        self._check_fitted()
        return (f"PooledSINDy, terms per equation {', '.join(str(int(k)) for k in self.n_terms_)} "
                f"(wind smoothing {self.fitted_wind_smoothing():g} s)")

    def campaign_summary(self) -> dict:
        """What ``vivbench pool`` writes of this model into ``campaign.regimes.nc`` (:func:`vivbench.models.model_summary`).

        The library coefficients and their bootstrap replicates, the selected thresholds and fit
        statistics; the file has no ``model`` attribute (as before other campaign models existed).
        """
        self._check_fitted()
        enough = bool(self.enough_data_)
        return {
            "variables": {
                "coef": (("equation", "feature"), self.coef_, {"units": "m/s per unit of the feature", "long_name": "pooled campaign model"}),
                "coef_bootstrap": (("bootstrap", "equation", "feature"), self.coef_bootstrap_, {"long_name": "block-bootstrap replicate models"}),
                "n_terms": (("equation",), self.n_terms_.astype(np.int32), {"units": "1"}),
                "threshold": (("equation",), self.threshold_, {"units": "1", "long_name": "selected STLSQ threshold (standardised)"}),
                "rss": (("equation",), self.rss_, {"units": "m2 s-2"}),
                "aicc": (("equation",), self.aicc_, {"units": "1"}),
            },
            "coords": {"feature": self.feature_names_, "bootstrap": np.arange(self.coef_bootstrap_.shape[0])},
            "attrs": {
                "n_samples": self.n_samples_, "n_blocks": self.n_blocks_, "cond": self.cond_,
                "enough_data": int(self.enough_data_),
                "note": ("" if enough else
                         f"only {self.n_blocks_} bootstrap blocks of {self.block_s:g} s (fewer than {self.min_blocks}): "
                         "too little data for an identifiability verdict, no window is flagged identifiable"),
                "model_config_json": self.to_json(),
            },
            "verdicts": {
                "identifiable": ("bootstrap agreement on the regime reaches the agreement level, the "
                                 "near-null-space test passes and the amplitude is above the noise floor"),
                "robust": "no model within the fit tolerance gives the window another regime (near-null-space test)",
            },
        }

    def _curves(self, models: np.ndarray, wind: np.ndarray) -> np.ndarray:
        """Curves (M, S, 4, n_wind) of models (M, S, 23 S)."""
        S = self.n_sections_
        ex = feature_exponents(S)
        P = np.zeros((models.shape[0], S, S, 4, 6))
        P[:, :, ex[:, 0], ex[:, 1], ex[:, 2]] = models
        rho = self.amplitude_ratios_[:, :, None] ** np.arange(4)  # (k, l, i); rho^0 = 1 even where rho is NaN
        rho[..., 0] = 1.0
        Upow = wind[:, None] ** np.arange(6)
        return np.einsum("mklij,kli,wj->mkiw", P, rho, Upow)

    def equations(self, precision: int = 3) -> list[str]:
        """pysindy-like equations, e.g. ``"dA1/dt = 1.20e-3 A1 - 4.00e-2 A1 U1^2"`` (physical units)."""
        self._check_fitted()
        lhs = [f"dA{k + 1}/dt" for k in range(self.n_sections_)]
        return format_equations(self.coef_, self.feature_names_, lhs, precision)

    def to_dataset(self) -> xr.Dataset:
        """The fitted model as the Dataset of a campaign model file (``vivbench.io.campaign_model``) with its format."""
        self._check_fitted()
        S = self.n_sections_
        eq, feat, boot = ("equation",), ("equation", "feature"), ("bootstrap", "equation", "feature")
        data = {
            "coef": (feat, self.coef_, {"units": "m/s per unit of the feature"}),
            "coef_scaled": (feat, self.coef_scaled_, {"units": "1"}),
            "coef_bootstrap": (boot, self.coef_bootstrap_, {"units": "m/s per unit of the feature"}),
            "threshold": (eq, self.threshold_), "n_terms": (eq, self.n_terms_.astype(np.int32)),
            "rss": (eq, self.rss_, {"units": "m2 s-2"}), "aicc": (eq, self.aicc_),
            "y_scale": (eq, self.y_scale_, {"units": "m/s"}),
            "correlation_samples": (eq, self.correlation_samples_), "rss_scaled": (eq, self.rss_scaled_),
            "amplitude_ratios": (("equation", "section"), self.amplitude_ratios_, {"units": "1"}),
            "gram_inv": (("basis", "basis_"), self.gram_inv_), "to_physical": (("basis", "basis_"), self.to_physical_),
        }
        coords = {"equation": section_names(S), "feature": self.feature_names_, "section": section_names(S),
                  "bootstrap": np.arange(self.coef_bootstrap_.shape[0])}
        attrs = {"model": type(self).__name__, "params_json": self.to_json(), "n_samples": self.n_samples_,
                 "n_blocks": self.n_blocks_, "enough_data": int(self.enough_data_), "cond": self.cond_,
                 "events": json.dumps(self.event_ids_), "vivbench_version": vivbench.__version__,
                 "format": CAMPAIGN_MODEL_FORMAT, "format_version": CAMPAIGN_MODEL_VERSION}
        return xr.Dataset(data, coords=coords, attrs=attrs)

    def save(self, path):
        """Write the fitted model as a NetCDF campaign model file; returns the path."""
        return write_campaign_model(self.to_dataset(), path)

    @classmethod
    def load(cls, path) -> "PooledSINDy":
        """A fitted model from a campaign model file (checked by ``read_campaign_model``)."""
        ds = read_campaign_model(path)
        params = json.loads(ds.attrs["params_json"])
        params["thresholds"] = tuple(params["thresholds"])
        model = cls(**params)
        g = {k: np.asarray(ds[k].values) for k in ds.data_vars}
        model.coef_, model.coef_scaled_, model.coef_bootstrap_ = g["coef"], g["coef_scaled"], g["coef_bootstrap"]
        model.support_ = model.coef_scaled_ != 0
        model.threshold_, model.n_terms_ = g["threshold"], g["n_terms"].astype(int)
        model.rss_, model.aicc_, model.y_scale_ = g["rss"], g["aicc"], g["y_scale"]
        model.correlation_samples_, model.rss_scaled_ = g["correlation_samples"], g["rss_scaled"]
        model.gram_inv_, model.to_physical_ = g["gram_inv"], g["to_physical"]
        model.amplitude_ratios_ = g["amplitude_ratios"]
        model.n_samples_, model.n_blocks_ = int(ds.attrs["n_samples"]), int(ds.attrs["n_blocks"])
        model.enough_data_, model.cond_ = bool(int(ds.attrs["enough_data"])), float(ds.attrs["cond"])
        model.n_sections_ = int(ds.sizes["equation"])
        model.feature_names_ = [str(x) for x in ds["feature"].values]
        model.event_ids_ = json.loads(ds.attrs.get("events", "[]"))
        return model

    @classmethod
    def from_regimes(cls, ds: xr.Dataset) -> "PooledSINDy":
        """The campaign model of a campaign regimes file (``campaign.regimes.nc``), for outputs without a model file.

        ``vivbench pool`` saves the fitted model as ``campaign.model.nc``
        (:meth:`save`); directories written before it hold only the regimes
        file, whose ``coef`` is the same model. This rebuilds what
        :meth:`predict`, :meth:`order_contributions`, :meth:`simulate` and
        :meth:`equations` need (and the selection summaries: ``coef_bootstrap_``,
        ``n_terms_``, ``threshold_``, ``rss_``, ``aicc_``, ``n_samples_``,
        ``n_blocks_``, ``cond_``, ``enough_data_``, ``event_ids_``).

        Parameters
        ----------
        ds : xarray.Dataset
            A regimes file read by :func:`vivbench.io.campaign_model.read_campaign_regimes`:
            ``coef`` (equation, feature) in physical units (dA/dt in m/s),
            ``coef_bootstrap``, ``n_terms``, ``threshold``, ``rss``, ``aicc`` and
            the attributes ``model_config_json``, ``n_samples``, ``n_blocks``,
            ``enough_data``, ``cond``, ``events``.

        Returns
        -------
        PooledSINDy
            Fitted for evaluation only: ``curves``, ``save`` and ``to_dataset``
            raise :class:`~vivbench.core.errors.InputError`
            naming the file, because the regimes file holds neither the
            amplitude ratios of the curves nor the regression basis (the
            windows' identifiability verdicts are in the regimes file itself).
        """
        source = ds.encoding.get("source", "the campaign regimes")
        try:
            params = json.loads(ds.attrs["model_config_json"])
            params["thresholds"] = tuple(params["thresholds"])
            model = cls(**params)
            model.coef_ = np.asarray(ds["coef"].values, dtype=float)
            model.coef_bootstrap_ = np.asarray(ds["coef_bootstrap"].values, dtype=float)
            model.threshold_ = np.asarray(ds["threshold"].values, dtype=float)
            model.n_terms_ = np.asarray(ds["n_terms"].values).astype(int)
            model.rss_, model.aicc_ = np.asarray(ds["rss"].values), np.asarray(ds["aicc"].values)
            model.n_samples_, model.n_blocks_ = int(ds.attrs["n_samples"]), int(ds.attrs["n_blocks"])
            model.enough_data_, model.cond_ = bool(int(ds.attrs["enough_data"])), float(ds.attrs["cond"])
            model.event_ids_ = json.loads(ds.attrs.get("events", "[]"))
        except (KeyError, TypeError, ValueError) as exc:
            raise InputError(f"{source}: not a campaign regimes file of vivbench pool ({type(exc).__name__}: {exc})") from None
        model.support_ = model.coef_ != 0
        model.n_sections_ = int(ds.sizes["equation"])
        model.feature_names_ = [str(x) for x in ds["feature"].values]

        def unavailable(*_args, **_kwargs):
            raise _RebuiltModelError(f"{source}: a campaign model rebuilt from the regimes file has no amplitude ratios "
                             "or regression basis (no curves, window verdicts or save); re-run vivbench pool to "
                             "write campaign.model.nc")

        for name in ("curves", "save", "to_dataset"):
            setattr(model, name, unavailable)
        return model


class _RebuiltModelError(InputError, NotFittedError):
    """A campaign model rebuilt from a regimes file cannot do this (no curves, window verdicts or save)."""
