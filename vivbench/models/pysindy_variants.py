"""The pysindy variants a SINDy researcher tries first, as campaign models: ensembles, SBR, the weak form.

:class:`PySINDyEnsemble` bags STLSQ with pysindy's ``EnsembleOptimizer``;
:class:`PySINDySBR` samples the coefficients' posterior with pysindy's
sparse Bayesian regression (``SBR``, a regularised-horseshoe prior, NUTS in
numpyro); both give a verdict from their coefficient draws. :class:`PySINDyWeak`
fits the weak (integral) form of dA/dt = f(A, U) with pysindy's
``WeakPDELibrary``, one library per run of valid samples. All three are
:class:`vivbench.models.PySINDyCampaign` models (the same scaling, term orders,
``predict``, ``simulate`` and ``curves``); :func:`ensemble`, :func:`sbr` and
:func:`weak` are their factories for ``vivbench leaderboard --methods
vivbench.models.pysindy_variants:ensemble,...``.

Verdict from draws. A draw is one coefficient matrix (a bag's fit, or a
posterior sample). A window's regime is flagged identifiable when at least
``agreement`` of the draws give, by the regime rule of docs/concepts.md
(regimes) on the window's samples, the regime of the model's own coefficients,
and the window's mean amplitude is at least ``min_snr`` times the record's
noise floor (``Record.noise_std``; unknown floors pass).
"""

from __future__ import annotations

import importlib.util
import warnings
from collections.abc import Sequence
from types import SimpleNamespace

import numpy as np

from vivbench.core.errors import InputError
from vivbench.core.record import Record
from vivbench.core.regime import DEFAULT_TAU, classify_regime
from vivbench.models.campaign import amplitude_ratios
from vivbench.models.protocol import ModelBase
from vivbench.models.pysindy_adapter import PySINDyCampaign, term_a_exponents
from vivbench.preprocess.noise_floor import window_amplitude_snr

__all__ = ["PySINDyEnsemble", "PySINDySBR", "PySINDyWeak", "ENSEMBLE_AGGREGATES", "ensemble", "ensemble_median", "sbr",
           "stlsq", "weak",
           "sbr_available"]

#: How the bags' coefficients become the ensemble model: their mean (bagging) or median (bragging).
ENSEMBLE_AGGREGATES = ("mean", "median")

_SBR_MISSING = ("pysindy's SBR needs numpyro (and jax), which is not installed: "
                "pip install numpyro (or pip install 'vivbench[bayes]')")


def sbr_available() -> bool:
    """Whether numpyro, which pysindy's ``SBR`` needs, can be imported."""
    return importlib.util.find_spec("numpyro") is not None


def _seeded(seed: int):
    """Context of a seeded global NumPy state (pysindy draws bags and test functions from it), restored after."""

    class _Seeded:
        def __enter__(self):
            self.saved = np.random.get_state()
            np.random.seed(int(seed))

        def __exit__(self, *exc):
            np.random.set_state(self.saved)
            return False

    return _Seeded()


class _DrawsVerdict(PySINDyCampaign):
    """A PySINDyCampaign with coefficient draws ``coef_draws_`` (D, S, p) and the verdict of the module docstring."""

    # the parameters, not the SINDy they build (building SBR's needs numpyro)
    __repr__ = ModelBase.__repr__

    def _check_verdict_params(self) -> None:
        if not 0.5 < self.agreement <= 1.0:
            raise ValueError(f"agreement must lie in (0.5, 1]; got {self.agreement}")
        if self.min_snr is not None and not (np.isfinite(self.min_snr) and self.min_snr >= 0):
            raise ValueError(f"min_snr must be None or a finite number >= 0; got {self.min_snr}")

    def draw_contributions(self, record: Record) -> np.ndarray:
        """Order contributions of every draw, shape (n_samples, D, S, 4), m/s (NaN where A or U is missing)."""
        record = self._check_record(record)
        theta, _ok = self._theta(self.sindy_, record)
        draws = self.coef_draws_
        r = np.empty((record.n_samples, draws.shape[0], self.n_sections_, 4))
        for i in range(4):
            cols = self.term_orders_ == i
            r[..., i] = np.einsum("nc,dkc->ndk", theta[:, cols], draws[:, :, cols])
        return r * self.a_scale_

    def draw_agreement(self, record: Record, window_start, window_end, tau: float = DEFAULT_TAU) -> np.ndarray:
        """Share of the draws whose regime of each window is the model's own, shape (W, S); NaN without samples."""
        record = self._check_record(record)
        start = np.atleast_1d(np.asarray(window_start, dtype=float))
        end = np.atleast_1d(np.asarray(window_end, dtype=float))
        r_draws = self.draw_contributions(record)
        r_model = self.order_contributions(record)
        ok = np.all(np.isfinite(r_model), axis=(1, 2))
        out = np.full((start.size, self.n_sections_), np.nan)
        for w, (s, e) in enumerate(zip(start, end)):
            sel = ok & (record.t >= s) & (record.t < e)
            if not sel.any():
                continue
            A = record.A[sel]
            own = classify_regime(r_model[sel], A, tau=tau, axis=0)  # (S,)
            A_d = np.broadcast_to(A[:, None, :], r_draws[sel].shape[:-1])
            regs = classify_regime(r_draws[sel], A_d, tau=tau, axis=0)  # (D, S)
            out[w] = np.mean(regs == own[None, :], axis=0)
        return out

    def identifiable(self, record: Record, window_start, window_end) -> np.ndarray:
        """Bool (W, S): >= ``agreement`` of the draws give the model's regime, above the noise floor."""
        share = self.draw_agreement(record, window_start, window_end)
        ok = ~np.isnan(share) & (np.nan_to_num(share) >= self.agreement)
        if self.min_snr is not None and record.noise_std is not None:
            snr = window_amplitude_snr(record.t, record.A, np.atleast_1d(np.asarray(window_start, dtype=float)),
                                       np.atleast_1d(np.asarray(window_end, dtype=float)), record.noise_std)
            ok &= ~(snr < self.min_snr)  # NaN (unknown floor) passes
        return ok


class PySINDyEnsemble(_DrawsVerdict):
    """Bagged STLSQ (pysindy's ``EnsembleOptimizer``) on all records, with a verdict from the bags.

    ``SINDy(PolynomialLibrary(degree), EnsembleOptimizer(STLSQ(threshold), bagging=True,
    n_models))``: each bag is a bootstrap sample (with replacement, as many samples as the
    data) of the standardised samples of every record; the model's coefficients are the
    ``aggregate`` of the bags' coefficients (``"mean"`` by default: see docs/methods.md
    (pysindy variants) for why pysindy's default median misleads here).

    Parameters
    ----------
    threshold : float
        STLSQ threshold on the standardised coefficients (1/s with x = A / a_s).
    degree : int
        Degree of the polynomial library in A and U (<= 3 in A keeps every term's order).
    n_models : int
        Bags (>= 2); each is a draw of the verdict.
    aggregate : {"mean", "median"}
    seed : int
        Seeds pysindy's bootstrap samples (the global NumPy state, restored after fitting).
    agreement : float in (0.5, 1]
        Share of the bags that must give the model's regime of a window.
    min_snr : float or None
        Noise-floor test of the verdict (None: off).
    standardize, use_record_derivative, other_terms, min_samples
        As :class:`vivbench.models.PySINDyCampaign`.

    Attributes
    ----------
    coef_draws_ : ndarray, shape (n_models, S, p)
        Every bag's coefficients (pysindy's ``coef_list``), on the scaled variables.
    coef_, sindy_, feature_names_, term_orders_, a_scale_ : as :class:`vivbench.models.PySINDyCampaign`
    """

    def __init__(self, *, threshold: float = 1e-3, degree: int = 3, n_models: int = 20, aggregate: str = "mean",
                 seed: int = 0, agreement: float = 0.95, min_snr: float | None = 3.0, standardize: bool = True,
                 use_record_derivative: bool = True, other_terms: str = "refuse", min_samples: int = 10):
        self.threshold = threshold
        self.degree = degree
        self.n_models = n_models
        self.aggregate = aggregate
        self.seed = seed
        self.agreement = agreement
        self.min_snr = min_snr
        self.standardize = standardize
        self.use_record_derivative = use_record_derivative
        self.other_terms = other_terms
        self.min_samples = min_samples

    @property
    def sindy(self):
        """The (unfitted) pysindy.SINDy this model fits."""
        import pysindy as ps

        if self.aggregate not in ENSEMBLE_AGGREGATES:
            raise ValueError(f"aggregate must be one of {', '.join(ENSEMBLE_AGGREGATES)}; got {self.aggregate!r}")
        if not (isinstance(self.n_models, (int, np.integer)) and self.n_models >= 2):
            raise ValueError(f"n_models must be an integer >= 2; got {self.n_models!r}")
        agg = (lambda c: np.mean(c, axis=0)) if self.aggregate == "mean" else (lambda c: np.median(c, axis=0))
        opt = ps.EnsembleOptimizer(ps.STLSQ(threshold=self.threshold), bagging=True, n_models=int(self.n_models),
                                   ensemble_aggregator=agg)
        return ps.SINDy(feature_library=ps.PolynomialLibrary(degree=self.degree), optimizer=opt)

    def fit(self, records: Sequence[Record]) -> "PySINDyEnsemble":
        """Fit the bags to every run of valid samples of every record; returns self."""
        self._check_verdict_params()
        with _seeded(self.seed):
            super().fit(records)
        self.coef_draws_ = np.asarray(self.sindy_.optimizer.coef_list, dtype=float)
        return self


class PySINDySBR(_DrawsVerdict):
    """pysindy's sparse Bayesian regression (``SBR``) on all records, with a verdict from its posterior draws.

    ``SINDy(PolynomialLibrary(degree), SBR(...))`` fitted by NUTS (numpyro) to at most
    ``max_samples`` samples of the records (every k-th sample of each run, k the same for
    all): the posterior's cost grows with the samples, and samples 0.25 s apart carry little
    more than every k-th. The model's coefficients are the posterior mean (pysindy's);
    ``n_draws`` posterior samples, evenly spaced in the chain, are the verdict's draws.

    Parameters
    ----------
    degree : int
        Degree of the polynomial library in A and U.
    sparsity : float
        ``sparsity_coef_tau0`` of SBR (scale of the horseshoe's global shrinkage; lower: sparser).
    num_warmup, num_samples : int
        NUTS warm-up and kept samples.
    n_draws : int
        Posterior samples used by the verdict (<= num_samples).
    max_samples : int
        Most samples fitted.
    seed : int
        Seed of the NUTS chain.
    agreement, min_snr, standardize, use_record_derivative, other_terms, min_samples
        As :class:`PySINDyEnsemble`.

    Attributes
    ----------
    coef_draws_ : ndarray, shape (n_draws, S, p)
        Posterior samples of the coefficients on the scaled variables.
    thinning_ : int
        The step between the fitted samples of each run (every k-th sample, k this value).

    Raises
    ------
    InputError
        At fit when numpyro is not installed (one line saying how to install it).
    """

    def __init__(self, *, degree: int = 3, sparsity: float = 0.1, num_warmup: int = 300, num_samples: int = 300,
                 n_draws: int = 100, max_samples: int = 2000, seed: int = 0, agreement: float = 0.95,
                 min_snr: float | None = 3.0, standardize: bool = True, use_record_derivative: bool = True,
                 other_terms: str = "refuse", min_samples: int = 10):
        self.degree = degree
        self.sparsity = sparsity
        self.num_warmup = num_warmup
        self.num_samples = num_samples
        self.n_draws = n_draws
        self.max_samples = max_samples
        self.seed = seed
        self.agreement = agreement
        self.min_snr = min_snr
        self.standardize = standardize
        self.use_record_derivative = use_record_derivative
        self.other_terms = other_terms
        self.min_samples = min_samples

    @property
    def sindy(self):
        """The (unfitted) pysindy.SINDy this model fits (InputError without numpyro)."""
        if not sbr_available():
            raise InputError(_SBR_MISSING)
        import pysindy as ps

        opt = ps.SBR(sparsity_coef_tau0=self.sparsity, num_warmup=int(self.num_warmup),
                     num_samples=int(self.num_samples), mcmc_kwargs={"seed": int(self.seed), "progress_bar": False})
        return ps.SINDy(feature_library=ps.PolynomialLibrary(degree=self.degree), optimizer=opt)

    def _prediction_library(self):
        import pysindy as ps

        return ps.PolynomialLibrary(degree=self.degree)  # the SINDy's own (building the SINDy needs numpyro)

    def _pieces(self, records: list[Record]) -> list[tuple]:
        pieces = super()._pieces(records)
        total = sum(p[0].size for p in pieces)
        k = max(1, int(np.ceil(total / self.max_samples)))
        self.thinning_ = k
        thinned = [tuple(None if x is None else x[::k] for x in p) for p in pieces]
        return [p for p in thinned if p[0].size >= 2]

    def fit(self, records: Sequence[Record]) -> "PySINDySBR":
        """Sample the posterior on (a thinning of) every run of valid samples of every record; returns self."""
        self._check_verdict_params()
        if not 1 <= self.n_draws <= self.num_samples:
            raise ValueError(f"n_draws must be in 1..num_samples ({self.num_samples}); got {self.n_draws}")
        if not sbr_available():  # refuse before any work
            raise InputError(_SBR_MISSING)
        super().fit(records)
        beta = np.asarray(self.sindy_.optimizer.mcmc_.get_samples()["beta"], dtype=float)  # (num_samples, S, p)
        pick = np.linspace(0, beta.shape[0] - 1, self.n_draws).round().astype(int)
        self.coef_draws_ = beta[pick]
        return self


class PySINDyWeak(PySINDyCampaign):
    """The weak form of dA/dt = f(A, U): pysindy's ``WeakPDELibrary`` per run of valid samples, one sparse fit.

    For a test function phi vanishing at both ends of its support, integration by parts gives
    -int phi' A dt = sum_j xi_j int phi theta_j(A, U) dt: no derivative of A is needed, and U (the
    control input) only enters the integrand. pysindy's library holds one time grid, so each
    run of valid samples of each record gets its own ``WeakPDELibrary`` (its grid, ``K`` test
    functions per ``H`` of run, support 2 ``H``); their rows are stacked and one ``STLSQ``
    fits them. The coefficients are those of the pointwise library (``PolynomialLibrary(degree)``
    in A and U), which gives the order contributions.

    Parameters
    ----------
    degree : int
        Degree of the polynomial library in A and U.
    threshold : float
        STLSQ threshold on the standardised coefficients.
    H : float, s
        Half-width of a test function's support (runs shorter than 4 H are not fitted).
    per_H : float
        Test functions per H of run (random centres, pysindy's).
    p : int
        Power of pysindy's test function (1 - t^2)^p.
    seed : int
        Seeds the test functions' centres (global NumPy state, restored after fitting).
    standardize, other_terms, min_samples
        As :class:`vivbench.models.PySINDyCampaign` (the records' dA is not used).

    Attributes
    ----------
    n_test_functions_ : int
        Rows of the stacked weak system.
    coef_, feature_names_, term_orders_, a_scale_ : as :class:`vivbench.models.PySINDyCampaign`
    """

    def __init__(self, *, degree: int = 3, threshold: float = 1e-3, H: float = 10.0, per_H: float = 1.0,
                 p: int = 4, seed: int = 0, standardize: bool = True, other_terms: str = "refuse",
                 min_samples: int = 10):
        self.degree = degree
        self.threshold = threshold
        self.H = H
        self.per_H = per_H
        self.p = p
        self.seed = seed
        self.standardize = standardize
        self.other_terms = other_terms
        self.min_samples = min_samples

    sindy = None
    use_record_derivative = False  # the weak form needs no dA/dt
    __repr__ = ModelBase.__repr__

    def _prediction_library(self):
        import pysindy as ps

        return ps.PolynomialLibrary(degree=self.degree)  # the pointwise library of the fitted coefficients

    def fit(self, records: Sequence[Record]) -> "PySINDyWeak":
        """Fit the stacked weak system of every run of valid samples of every record; returns self."""
        import pysindy as ps

        self._check_params()
        if not (np.isfinite(self.H) and self.H > 0 and self.per_H > 0):
            raise ValueError(f"H (s) and per_H must be positive; got H={self.H}, per_H={self.per_H}")
        records = self._records(records)
        self._set_scales(records)
        pieces = [q for q in self._pieces(records) if q[0][-1] - q[0][0] >= 4 * self.H]
        if not pieces:
            raise ValueError(f"no run of valid samples lasts 4 H = {4 * self.H:g} s, the weak form's shortest")
        rows, lhs = [], []
        with _seeded(self.seed), warnings.catch_warnings():
            # pysindy 2.1's WeakPDELibrary.fit labels a one-sample slice with two axes and warns about it
            warnings.filterwarnings("ignore", message=r"\d+ axes labeled for array with \d+ axes")
            for t, A, U, _dA in pieces:
                x, u = self._inputs(A, U)
                K = max(1, int(round((t[-1] - t[0]) / self.H * self.per_H)))
                lib = ps.WeakPDELibrary(function_library=ps.PolynomialLibrary(degree=self.degree),
                                        spatiotemporal_grid=t - t[0], K=K, H_xt=self.H, p=self.p)
                xu = ps.AxesArray(np.hstack([x, u]), {"ax_time": 0, "ax_coord": 1})
                lib.fit([xu])
                rows.append(np.asarray(lib.transform([xu])[0], dtype=float))
                lhs.append(np.asarray(lib.convert_u_dot_integral(ps.AxesArray(x, {"ax_time": 0, "ax_coord": 1})),
                                      dtype=float))
        theta, y = np.vstack(rows), np.vstack(lhs)
        opt = ps.STLSQ(threshold=self.threshold).fit(theta, y)
        pointwise = ps.PolynomialLibrary(degree=self.degree).fit(np.zeros((1, 2 * self.n_sections_)))
        holder = SimpleNamespace(feature_library=pointwise, optimizer=opt,
                                 get_feature_names=lambda: pointwise.get_feature_names(self.state_names_
                                                                                       + self.input_names_),
                                 coefficients=lambda: opt.coef_)
        names, coef, orders = self._term_info(holder)
        self.sindy_ = holder
        self.feature_names_ = names
        self.term_orders_ = orders
        self.a_exponents_ = term_a_exponents(names, self.state_names_, self.input_names_)
        self.n_trajectories_ = len(pieces)
        self.n_test_functions_ = int(theta.shape[0])
        self.coef_ = coef
        self.other_share_ = self._other_share(records)
        self.amplitude_ratios_ = amplitude_ratios(np.concatenate([r.A for r in records]))
        return self


def ensemble() -> PySINDyEnsemble:
    """``PySINDyEnsemble()`` with its defaults (the ``--methods`` factory)."""
    return PySINDyEnsemble()


def sbr() -> PySINDySBR:
    """``PySINDySBR()`` with its defaults (the ``--methods`` factory); InputError at once without numpyro."""
    if not sbr_available():
        raise InputError(_SBR_MISSING)
    return PySINDySBR()


def weak() -> PySINDyWeak:
    """``PySINDyWeak()`` with its defaults (the ``--methods`` factory)."""
    return PySINDyWeak()


def ensemble_median() -> PySINDyEnsemble:
    """``PySINDyEnsemble(aggregate="median")``: pysindy's default aggregation, for comparison (the ``--methods`` factory)."""
    return PySINDyEnsemble(aggregate="median")


def stlsq() -> PySINDyCampaign:
    """``PySINDyCampaign()``: plain STLSQ on the same library, the baseline of the variants (the ``--methods`` factory)."""
    return PySINDyCampaign()
