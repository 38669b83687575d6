"""Tests of the window library basis and the fast windowed STLSQ engine.

Synthetic events: three sections, wind U_k slowly varying around 8 m/s with
section-specific low-passed fluctuations, amplitudes A_k from integrating a
sparse model in the library (per section: U, A, A U, A^3) with scipy, and
noisy derivatives. pysindy's STLSQ is the reference for the regressions.
"""

from __future__ import annotations

import functools
import warnings

import numpy as np
import pysindy as ps
import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st
from scipy.integrate import solve_ivp
from scipy.ndimage import gaussian_filter1d

from tests.helpers import assert_close
from vivbench.regression.settings import DEFAULT_THRESHOLDS, StlsqSettings
from vivbench.regression.stlsq import aicc, stlsq_path
from vivbench.models.window import EventWindowSINDy
from vivbench.preprocess.windows import window_bounds
from vivbench.library.basis import condition_number, library_cond, window_library
from vivbench.core.terms import evaluate_library, feature_exponents

DT = 0.25
EPS = np.finfo(float).eps
EXPONENTS = feature_exponents(3)


def _index(section: int, i: int, j: int) -> int:
    hit = (EXPONENTS[:, 0] == section) & (EXPONENTS[:, 1] == i) & (EXPONENTS[:, 2] == j)
    return int(np.flatnonzero(hit)[0])


def _true_coef() -> np.ndarray:
    """Sparse physical model, one equation per section, shape (3, 69)."""
    xi = np.zeros((3, 69))
    for k in range(3):
        xi[k, _index(k, 0, 1)] = 1e-3  # U: forcing
        xi[k, _index(k, 1, 1)] = 0.02  # A U: wind-dependent damping ...
        xi[k, _index(k, 1, 0)] = -0.15  # ... negative below 7.5 m/s
        xi[k, _index(k, 3, 0)] = -0.5  # A^3: amplitude limit
    return xi


@functools.lru_cache(maxsize=8)
def _clean_event(seed: int, duration: float):
    """Noise-free trajectory of the sparse model: t, A, U (read-only arrays)."""
    rng = np.random.default_rng(seed)
    n = int(round(duration / DT)) + 1
    t = np.arange(n) * DT
    phase = rng.uniform(0, 2 * np.pi, 3)
    gust = gaussian_filter1d(rng.standard_normal((n, 3)), sigma=10 / DT, axis=0)
    gust /= gust.std(axis=0)
    U = 8.0 + 0.8 * np.sin(2 * np.pi * t[:, None] / 900.0 + phase) + 0.25 * gust
    xi = _true_coef()

    def rhs(tt, a):
        u = np.array([np.interp(tt, t, U[:, k]) for k in range(3)])
        return (evaluate_library(a[None], u[None]) @ xi.T)[0]

    sol = solve_ivp(rhs, (0.0, t[-1]), rng.uniform(0.05, 0.2, 3), t_eval=t, rtol=1e-8, atol=1e-10, max_step=1.0)
    A = sol.y.T.copy()
    for arr in (t, A, U):
        arr.flags.writeable = False
    return t, A, U


def _noisy_event(seed: int, duration: float, *, noise_seed: int = 0, d_noise: float = 0.1, a_noise: float = 0.005):
    """Event with 10 % white noise on dA/dt and 0.5 % multiplicative noise on A."""
    t, A, U = _clean_event(seed, duration)
    dA = evaluate_library(A, U) @ _true_coef().T
    rng = np.random.default_rng(10_000 + noise_seed)
    dA = dA + d_noise * dA.std(axis=0) * rng.standard_normal(dA.shape)
    A = A * (1 + a_noise * rng.standard_normal(A.shape))
    return t, A, U, dA


def _window_design(model: EventWindowSINDy, t, A, U, dA, w: int):
    """The scaled design and targets the estimator regressed in window w."""
    first, stop = window_bounds(t, model.window, model.step)[2:]
    sl = slice(first[w], stop[w])
    lib = window_library(A[sl], U[sl], scaling=model.scaling)
    return lib, dA[sl] / model.y_scale_[w]


def _pysindy_path(theta, y, thresholds, *, alpha, max_iter, ridge_kw=None):
    """Coefficients (q, T, p) of pysindy's STLSQ along a threshold path."""
    coefs = []
    with warnings.catch_warnings():
        # pysindy warns when a threshold removes every term or max_iter is hit.
        warnings.simplefilter("ignore")
        for th in thresholds:
            opt = ps.STLSQ(threshold=th, alpha=alpha, max_iter=max_iter, ridge_kw=ridge_kw)
            coefs.append(opt.fit(theta, y).coef_)
    return np.stack(coefs, axis=1)


def _aicc_select(theta, y, coefs, floor_rel):
    """AICc selection on a pysindy path with the engine's rules."""
    n = theta.shape[0]
    res = y.T[:, None, :] - np.einsum("np,qtp->qtn", theta, coefs)
    rss = np.sum(res**2, axis=2)
    k = np.count_nonzero(coefs, axis=2)
    floor = floor_rel**2 * np.sum(y**2, axis=0)[:, None]
    a = np.where(k > 0, aicc(rss, k, n, floor=floor), np.inf)
    return np.where(np.isfinite(a).any(axis=1), np.argmin(a, axis=1), -1)


# --------------------------------------------------------------------------
# Library basis
# --------------------------------------------------------------------------


def _windows(seed=0, duration=600.0, n=200, stride=100):
    t, A, U = _clean_event(seed, duration)
    idx = np.arange(0, t.size - n + 1, stride)[:, None] + np.arange(n)
    return A[idx], U[idx]


@pytest.mark.parametrize("scaling", ["scaled", "normalized", "raw"])
def test_basis_maps_exactly_to_physical_library(scaling):
    """(c) Basis prediction equals physical prediction of the mapped coefficients."""
    Aw, Uw = _windows()
    lib = window_library(Aw, Uw, scaling=scaling)
    rng = np.random.default_rng(1)
    xi = rng.standard_normal((Aw.shape[0], 3, 69))
    phys = lib.physical_coef(xi)
    X = evaluate_library(Aw.reshape(-1, 3), Uw.reshape(-1, 3)).reshape(Aw.shape[:2] + (69,))
    pred_basis = np.einsum("wnp,wqp->wnq", lib.theta, xi)
    pred_phys = np.einsum("wnp,wqp->wnq", X, phys)
    # Rounding bound of the two sums: physical coefficients are large and of
    # alternating sign (the binomial expansion of (U - c)^j), so the physical
    # sum cancels; the map itself is exact in exact arithmetic.
    bound = 64 * EPS * (
        np.einsum("wnp,wqp->wnq", np.abs(X), np.abs(phys)) + np.einsum("wnp,wqp->wnq", np.abs(lib.theta), np.abs(xi))
    )
    err = np.abs(pred_basis - pred_phys)
    assert np.all(err <= bound), f"{scaling}: worst error / rounding bound = {np.max(err / bound):.3g}"
    if scaling != "scaled":
        # Diagonal maps involve no cancellation at all.
        atol = 1e-12 * np.abs(pred_basis).max()
        assert_close(pred_phys, pred_basis, rtol=1e-12, atol=atol, reason="two summation orders")


@settings(max_examples=25, deadline=None, derandomize=True)
@given(
    c=st.floats(0.5, 30.0),
    s_rel=st.floats(1e-3, 0.3),
    a=st.floats(1e-3, 10.0),
    seed=st.integers(0, 2**16),
)
def test_basis_map_property(c, s_rel, a, seed):
    """(c) The map is exact for any wind centre, spread and amplitude scale."""
    rng = np.random.default_rng(seed)
    n = 120
    U = c * (1 + s_rel * np.cumsum(rng.standard_normal((n, 3)), axis=0) / np.sqrt(n))
    A = a * np.abs(1 + 0.3 * rng.standard_normal((n, 3)))
    lib = window_library(A, U, scaling="scaled")
    X = evaluate_library(A, U)
    xi = rng.standard_normal(69)
    phys = lib.to_physical @ xi
    err = np.abs(lib.theta @ xi - X @ phys)
    bound = 64 * EPS * (np.abs(X) @ np.abs(phys) + np.abs(lib.theta) @ np.abs(xi))
    assert np.all(err <= bound), f"worst error / rounding bound = {np.max(err / bound):.3g}"


def test_basis_spans_physical_space_without_constant():
    """The map is block-diagonal by section and A power, triangular in U power,
    with a non-zero diagonal: invertible, so both libraries span one space
    (which has no constant column)."""
    Aw, Uw = _windows()
    lib = window_library(Aw[0], Uw[0])
    M = lib.to_physical
    ex = EXPONENTS
    same_block = (ex[:, None, 0] == ex[None, :, 0]) & (ex[:, None, 1] == ex[None, :, 1])
    assert np.all(M[~same_block] == 0), "a basis term maps outside its section and power of A"
    # Physical row (i, k) receives basis columns (i, j) with j >= k only.
    lower = same_block & (ex[:, None, 2] > ex[None, :, 2])
    assert np.all(M[lower] == 0), "the map is not triangular in the power of U"
    assert np.all(np.diag(M) != 0), "the map is singular"


def test_centring_improves_conditioning():
    """Per section, centring U lowers the condition number by orders of magnitude;
    a constant rescaling (normalized) does not help."""
    Aw, Uw = _windows()
    one = (Aw[..., :1], Uw[..., :1])
    c_scaled = library_cond(*one, scaling="scaled")
    c_norm = library_cond(*one, scaling="normalized")
    assert np.all(c_scaled * 1e3 < c_norm), f"scaled {c_scaled.max():.2e} vs normalized {c_norm.min():.2e}"
    assert np.all(c_norm > 1e10), "the normalized library was expected to stay ill-conditioned"
    assert_close(condition_number(window_library(*one).theta), c_scaled, rtol=1e-12, reason="same SVD")


def test_window_library_ignores_invalid_samples():
    Aw, Uw = _windows()
    A, U = Aw[0].copy(), Uw[0].copy()
    A[[3, 50]] = np.nan
    keep = np.isfinite(A).all(axis=1)
    with_nan = window_library(A, U)
    without = window_library(A[keep], U[keep])
    assert np.all(np.isnan(with_nan.theta[~keep])), "invalid rows must be NaN"
    assert_close(with_nan.theta[keep], without.theta, rtol=1e-12, reason="masked sums in a different order")
    assert_close(with_nan.to_physical, without.to_physical, rtol=1e-10, reason="masked sums in a different order")


# --------------------------------------------------------------------------
# Agreement with pysindy
# --------------------------------------------------------------------------


def _fit_and_compare(events, *, alpha, ridge_kw=None):
    sel_agree = path_agree = n_sel = n_path = 0
    coef_err = []
    pred_err = []
    for seed in events:
        t, A, U, dA = _noisy_event(seed, 600.0)
        model = EventWindowSINDy(alpha=alpha).fit(t, A, U, dA)
        for w in range(model.window_start_.size):
            lib, y = _window_design(model, t, A, U, dA, w)
            ref = _pysindy_path(lib.theta, y, model.thresholds_, alpha=alpha, max_iter=20, ridge_kw=ridge_kw)
            ref_support = ref != 0
            path_agree += np.sum(np.all(ref_support == model.path_support_[w], axis=2))
            n_path += ref_support.shape[0] * ref_support.shape[1]
            ref_sel = _aicc_select(lib.theta, y, ref, 1e-8)
            for e in range(3):
                n_sel += 1
                ours = model.support_[w, e]
                theirs = ref_support[e, ref_sel[e]]
                if ref_sel[e] != model.selected_[w, e] or not np.array_equal(ours, theirs):
                    continue
                sel_agree += 1
                c_ref = ref[e, ref_sel[e]]
                c_ours = model.coef_scaled_[w, e]
                cond_s = condition_number(lib.theta[:, ours])
                if cond_s < 1e5:
                    coef_err.append(np.max(np.abs(c_ours - c_ref)) / np.max(np.abs(c_ref)))
                pred_err.append(np.linalg.norm(lib.theta @ (c_ours - c_ref)) / np.linalg.norm(y[:, e]))
    return sel_agree / n_sel, path_agree / n_path, np.array(coef_err), np.array(pred_err), n_sel


def test_matches_pysindy_stlsq_default_solver():
    """(a) Same supports along the path and after AICc as pysindy's STLSQ on the
    same scaled design (alpha = 0.05, pysindy's default Cholesky ridge)."""
    sel, path, coef_err, pred_err, n = _fit_and_compare((0, 1), alpha=0.05)
    assert n >= 120, f"only {n} window-equations compared"
    assert sel >= 0.99, f"selected supports agree on {sel:.1%} of {n} window-equations"
    assert path >= 0.99, f"path supports agree on {path:.1%}"
    assert coef_err.size >= 0.25 * n, f"only {coef_err.size} well-conditioned selected models to compare"
    assert np.all(coef_err <= 1e-6), f"coefficients differ by up to {coef_err.max():.2e} (relative)"
    # Ill-conditioned supports: coefficients are not determined to 1e-6 by
    # any solver, but the fitted values are.
    assert np.all(pred_err <= 1e-8), f"fitted values differ by up to {pred_err.max():.2e} (relative)"


def test_matches_pysindy_svd_ridge_without_regularisation():
    """(a) With alpha = 0 the first solve is a least-squares fit on a design with
    cond ~1e15; against pysindy with its accurate (SVD) ridge solver the paths
    still agree where the arithmetic allows (one event; pysindy is slow)."""
    sel, path, _, pred_err, n = _fit_and_compare((2,), alpha=0.0, ridge_kw={"solver": "svd"})
    assert path >= 0.97, f"path supports agree on {path:.1%}"
    assert sel >= 0.85, f"selected supports agree on {sel:.1%} of {n}"


def test_stlsq_path_is_not_monotone_and_pysindy_agrees():
    """(b) A larger threshold can select MORE terms: STLSQ refits after each
    thresholding, so its path is not monotone. pysindy shows the same."""
    found = None
    for seed in (0, 1, 2, 3):
        t, A, U, dA = _noisy_event(seed, 600.0)
        model = EventWindowSINDy().fit(t, A, U, dA)
        up = np.argwhere(np.any(np.diff(model.path_n_terms_, axis=2) > 0, axis=2))
        if up.size:
            found = (t, A, U, dA, model, *up[0])
            break
    assert found is not None, "no non-monotone path in the test events"
    t, A, U, dA, model, w, e = found
    lib, y = _window_design(model, t, A, U, dA, w)
    ref = _pysindy_path(lib.theta, y, model.thresholds_, alpha=model.alpha, max_iter=model.max_iter)
    assert np.array_equal(np.count_nonzero(ref[e], axis=1), model.path_n_terms_[w, e]), "pysindy path differs"


# --------------------------------------------------------------------------
# Properties
# --------------------------------------------------------------------------


@settings(max_examples=8, deadline=None, derandomize=True, suppress_health_check=[HealthCheck.too_slow])
@given(seed=st.integers(0, 3), noise_seed=st.integers(0, 1000), alpha=st.sampled_from([0.0, 0.05, 1.0]))
def test_single_iteration_path_is_nested(seed, noise_seed, alpha):
    """(b) With max_iter = 1 (threshold the first ridge solution once) a larger
    threshold never keeps more terms, and the supports are nested."""
    t, A, U, dA = _noisy_event(seed, 300.0, noise_seed=noise_seed)
    model = EventWindowSINDy(alpha=alpha, max_iter=1).fit(t, A, U, dA)
    s = model.path_support_
    assert not np.any(s[:, :, 1:] & ~s[:, :, :-1]), "a larger threshold kept a term a smaller one dropped"
    assert np.all(np.diff(model.path_n_terms_, axis=2) <= 0), "a larger threshold kept more terms"


@settings(max_examples=8, deadline=None, derandomize=True, suppress_health_check=[HealthCheck.too_slow])
@given(seed=st.integers(0, 3), noise_seed=st.integers(0, 1000), factor=st.sampled_from([1e3, 1e-3, 2.5]))
def test_units_do_not_change_supports(seed, noise_seed, factor):
    """(b) A and dA in mm instead of m (or any factor): identical supports and
    selections; the RSS carries the unit."""
    t, A, U, dA = _noisy_event(seed, 300.0, noise_seed=noise_seed)
    m1 = EventWindowSINDy().fit(t, A, U, dA)
    m2 = EventWindowSINDy().fit(t, A * factor, U, dA * factor)
    assert np.array_equal(m1.path_support_, m2.path_support_), "path supports changed with the unit of A"
    assert np.array_equal(m1.selected_, m2.selected_), "selected models changed with the unit of A"
    assert_close(m2.a_scale_, factor * m1.a_scale_, rtol=1e-12, reason="RMS of rescaled data")
    assert_close(m2.y_scale_, factor * m1.y_scale_, rtol=1e-12, reason="RMS of rescaled data")
    # Fitted values are well determined even where (ill-conditioned) basis
    # coefficients are not, so the RSS carries the unit exactly.
    assert_close(m2.rss_, factor**2 * m1.rss_, rtol=1e-8, reason="rounding of rescaled data")


@settings(max_examples=8, deadline=None, derandomize=True, suppress_health_check=[HealthCheck.too_slow])
@given(seed=st.integers(0, 3), shift=st.floats(-1e5, 1e5))
def test_time_shift_does_not_change_supports(seed, shift):
    t, A, U, dA = _noisy_event(seed, 300.0)
    m1 = EventWindowSINDy().fit(t, A, U, dA)
    m2 = EventWindowSINDy().fit(t + shift, A, U, dA)
    assert np.array_equal(m1.path_support_, m2.path_support_), "supports changed with a time shift"
    atol = 1e-9 * max(1.0, abs(shift))
    assert_close(m2.window_start_ - shift, m1.window_start_, rtol=0, atol=atol, reason="float shift")
    assert np.array_equal(m1.coef_scaled_, m2.coef_scaled_), "the same samples must give the same numbers"


_CANDIDATES = [(1, 0), (1, 1), (2, 0), (3, 0), (0, 1), (0, 2), (1, 2)]


@settings(max_examples=15, deadline=None, derandomize=True, suppress_health_check=[HealthCheck.too_slow])
@given(
    seed=st.integers(0, 3),
    section=st.integers(0, 2),
    terms=st.lists(st.sampled_from(_CANDIDATES), min_size=1, max_size=4, unique=True),
    signs=st.lists(st.sampled_from([-1.0, 1.0]), min_size=4, max_size=4),
    mags=st.lists(st.floats(0.3, 3.0), min_size=4, max_size=4),
)
def test_exact_sparse_model_is_recovered(seed, section, terms, signs, mags):
    """(b) Noise-free data with the exact derivative of a sparse library model:
    support and coefficients recovered to rounding level.

    One section (23 terms): with three, each section's U q(U) approximates
    a constant to ~1e-15 within a window, so the first least-squares solve
    carries errors of cond * eps ~ 0.1 in any float64 solver and spurious
    terms survive the threshold. alpha = 0 (a ridge resolves the
    non-identifiable directions by minimum norm instead of sparsity) and a
    plain least-squares refit (pysindy's refit truncates singular values
    below 1e-6 of the largest, which is not exact on ill-conditioned
    supports).
    """
    t, A3, U3 = _clean_event(seed, 300.0)
    A, U = A3[:, section : section + 1], U3[:, section : section + 1]
    xi = np.zeros((1, 23))
    for (i, j), sgn, mag in zip(terms, signs, mags):
        col = _index(0, i, j)
        x = A[:, 0] ** i * U[:, 0] ** j
        # Each term carries a comparable share of dA/dt (0.3-3 x 1e-3 m/s).
        xi[0, col] = sgn * mag * 1e-3 / np.sqrt(np.mean(x**2))
    dA = evaluate_library(A, U) @ xi.T
    model = EventWindowSINDy(alpha=0.0, refit_rcond=None)
    first, stop = window_bounds(t, model.window, model.step)[2:]
    # The model's exact coefficients on each window's basis (standardised):
    # their non-zeros are the support STLSQ must find. Terms that nearly
    # cancel in a window's basis (below the smallest non-zero threshold)
    # cannot be found by any threshold path; such draws are skipped.
    libs = [window_library(A[a:b], U[a:b]) for a, b in zip(first, stop)]
    ys = np.array([np.sqrt(np.mean(dA[a:b] ** 2, axis=0)) for a, b in zip(first, stop)])
    expected = np.array([np.linalg.solve(lib.to_physical, xi[0]) for lib in libs]) / ys
    structural = np.abs(expected) > 1e-9 * np.abs(expected).max(axis=1, keepdims=True)
    assume(np.all(np.abs(expected)[structural] >= 1e-2))
    model.fit(t, A, U, dA)
    assert np.array_equal(model.support_[:, 0], structural), "wrong support on the window basis"
    for w, lib in enumerate(libs):
        sup = structural[w]
        cond_s = condition_number(lib.theta[:, sup])
        # Backward-stable least squares on consistent data: basis errors of
        # cond * eps, mapped to physical units through |to_physical|.
        size = (np.abs(lib.to_physical) @ np.abs(model.coef_scaled_[w, 0])) * ys[w, 0]
        tol = 1e3 * EPS * cond_s * size + 1e-12 * np.abs(xi[0]).max()
        err = np.abs(model.coef_[w, 0] - xi[0])
        assert np.all(err <= tol), f"window {w}: coefficient error / bound = {np.max(err / tol):.3g}"
    assert np.all(model.rss_ <= 1e-20 * np.sum(dA**2)), "an exact model must fit exactly"


# --------------------------------------------------------------------------
# Engine details
# --------------------------------------------------------------------------


def _one_window(seed=0, noise_seed=0):
    t, A, U, dA = _noisy_event(seed, 300.0, noise_seed=noise_seed)
    sl = slice(400, 600)
    lib = window_library(A[sl], U[sl])
    y = dA[sl] / np.sqrt(np.mean(dA[sl] ** 2, axis=0))
    return lib.theta, y


def test_nan_samples_are_dropped():
    theta, y = _one_window()
    theta_nan = theta.copy()
    y_nan = y.copy()
    theta_nan[[5, 77]] = np.nan
    y_nan[120, 1] = np.nan
    keep = np.ones(theta.shape[0], dtype=bool)
    keep[[5, 77, 120]] = False
    a = stlsq_path(theta_nan, y_nan)
    b = stlsq_path(theta[keep], y[keep])
    assert a.n_samples[0] == keep.sum()
    assert np.array_equal(a.support, b.support), "NaN rows changed the supports"
    assert np.array_equal(a.selected, b.selected), "NaN rows changed the selection"
    # Fitted values (not the coefficients of ill-conditioned supports) are
    # insensitive to the rounding differences zero rows bring into the QR,
    # except plain least squares on numerically singular supports (kept as
    # lower bounds, cond ~1e15), where they move by ~cond * eps.
    assert np.array_equal(a.lower_bound, b.lower_bound)
    exact = ~a.lower_bound
    assert exact.sum() >= 20, "too few exactly refitted models to compare"
    assert_close(a.rss[exact], b.rss[exact], rtol=1e-9, reason="zero rows reorder the QR")
    assert_close(a.rss, b.rss, rtol=1e-4, reason="least squares on numerically singular supports")


@pytest.mark.parametrize("alpha, solver", [(0.05, "auto"), (1.0, "auto"), (1.0, "gram")])
def test_cholesky_shortcut_matches_qr(alpha, solver):
    """'auto' solves ridge iterations by Cholesky only where provably accurate
    (here everywhere, so 'gram' does the same): it must reproduce the
    all-QR path."""
    t, A, U, dA = _noisy_event(1, 600.0)
    m_chol = EventWindowSINDy(alpha=alpha, solver=solver).fit(t, A, U, dA)
    m_qr = EventWindowSINDy(alpha=alpha, solver="qr").fit(t, A, U, dA)
    assert m_chol.solves_["cholesky"] > 0, "the Cholesky shortcut was not used"
    assert m_qr.solves_["cholesky"] == 0, "solver='qr' must not use normal equations"
    assert np.array_equal(m_chol.path_support_, m_qr.path_support_), "supports differ between solvers"
    assert_close(m_chol.path_rss_, m_qr.path_rss_, rtol=1e-8, reason="different solvers of the same problems")


def test_aicc_formula_and_exclusions():
    rss = np.array([2.0, 2.0, 1.0, 1e-30])
    k = np.array([0, 3, 199, 2])
    n = 200
    got = aicc(rss, k, n, floor=1e-20)
    expect0 = n * np.log(2.0 / n)
    expect1 = n * np.log(2.0 / n) + 6 + 2 * 3 * 4 / (n - 4)
    assert_close(got[:2], [expect0, expect1], rtol=1e-14, reason="log and division")
    assert got[2] == np.inf, "N - k - 1 <= 0 must be excluded"
    assert_close(got[3], n * np.log(1e-20 / n) + 4 + 12 / 197, rtol=1e-14, reason="log and division")


def test_empty_model_excluded_unless_allowed():
    theta, y = _one_window()
    y = y + 0.0
    big = StlsqSettings(thresholds=(1e6,))
    p1 = stlsq_path(theta, y, big)
    assert np.all(p1.n_terms == 0) and np.all(p1.selected == -1), "the empty model must not be selected"
    p2 = stlsq_path(theta, y, StlsqSettings(thresholds=(1e6,), allow_empty=True))
    assert np.all(p2.selected == 0), "allow_empty must admit the empty model"
    assert_close(p2.best_rss, np.sum(y**2, axis=0)[None], rtol=1e-12, reason="QR reconstruction of |y|^2")


@pytest.mark.parametrize(
    "kwargs, message",
    [
        (dict(thresholds=(0.1, 0.01)), "strictly increasing"),
        (dict(thresholds=(-1.0,)), ">= 0"),
        (dict(alpha=-0.1), "alpha"),
        (dict(max_iter=0), "max_iter"),
        (dict(solver="lu"), "solver"),
        (dict(residual_floor=2.0), "residual_floor"),
    ],
)
def test_settings_are_validated(kwargs, message):
    with pytest.raises(ValueError, match=message):
        StlsqSettings(**kwargs)


def test_window_bounds_on_a_regular_grid():
    t = np.arange(4 * 600 + 1) * DT
    start, end, first, stop = window_bounds(t, 50.0, 25.0)
    assert start.size == 23, f"expected 23 complete windows, got {start.size}"
    assert np.all(stop - first == 200), "each 50 s window holds 200 samples at 4 Hz"
    assert_close(end - start, np.full(23, 50.0), rtol=0.0, atol=1e-12, reason="float addition")


def test_estimator_outputs_and_short_windows():
    t, A, U, dA = _noisy_event(0, 300.0)
    A = A.copy()
    A[40:190] = np.nan  # the first window keeps only 50 valid samples
    model = EventWindowSINDy(thresholds=DEFAULT_THRESHOLDS[:10]).fit(t, A, U, dA)
    W = model.window_start_.size
    assert model.coef_.shape == (W, 3, 69) and model.path_support_.shape == (W, 3, 10, 69)
    assert model.n_samples_[0] == 50
    assert np.all(np.isnan(model.coef_[0])) and np.all(model.selected_[0] == -1), "too few samples must give no model"
    assert np.all(np.isfinite(model.coef_[1:])), "complete windows must give models"
    assert model.get_params()["alpha"] == 0.05
    assert model.set_params(alpha=0.1).alpha == 0.1
    with pytest.raises(ValueError, match="shorter than one window"):
        EventWindowSINDy(window=1e4).fit(t, A, U, dA)
    with pytest.raises(ValueError, match="scaling"):
        EventWindowSINDy(scaling="log").fit(t, A, U, dA)


@pytest.mark.parametrize("scaling", ["normalized", "raw"])
def test_other_bases_fit(scaling):
    """The comparison bases fit too; targets are scaled only with a basis."""
    t, A, U, dA = _noisy_event(0, 300.0)
    model = EventWindowSINDy(scaling=scaling, keep_path=False, raw_cond=True).fit(t, A, U, dA)
    assert not hasattr(model, "path_support_")
    assert np.all(np.isfinite(model.coef_)), f"{scaling}: every window must give a model"
    assert np.all(model.cond_raw_ >= 1e10), "the physical library is expected to be ill-conditioned"
    if scaling == "raw":
        assert np.all(model.y_scale_ == 1.0) and np.all(model.col_scale_ == 1.0)
        assert np.array_equal(model.coef_, model.coef_scaled_), "raw coefficients are physical"


# --------------------------------------------------------------------------
# Optimisers for the comparison: pysindy's SR3 path and bagged STLSQ
# --------------------------------------------------------------------------


def _exact_single_section_windows(seed=0):
    """Window designs (W, n, 23) and standardised targets of an exactly sparse one-section model,
    and each window's true support on its basis."""
    t, A3, U3 = _clean_event(seed, 300.0)
    A, U = A3[:, :1], U3[:, :1]
    xi = np.zeros(23)
    for (i, j), c in zip([(0, 1), (1, 1), (3, 0)], [1.0, -2.0, 1.5]):
        x = A[:, 0] ** i * U[:, 0] ** j
        xi[_index(0, i, j)] = c * 1e-3 / np.sqrt(np.mean(x**2))
    dA = evaluate_library(A, U) @ xi[:, None]
    first, stop = window_bounds(t, 50.0, 25.0)[2:]
    idx = first[:, None] + np.arange(int((stop - first).min()))
    lib = window_library(A[idx], U[idx])
    ys = np.sqrt(np.mean(dA[idx] ** 2, axis=1, keepdims=True))
    y = dA[idx] / ys
    expected = np.linalg.solve(lib.to_physical, np.broadcast_to(xi, (idx.shape[0], 23))[..., None])[..., 0] / ys[:, 0]
    structural = np.abs(expected) > 1e-9 * np.abs(expected).max(axis=1, keepdims=True)
    return lib.theta, y, structural, expected


def test_sr3_recovers_exact_sparse_support():
    """Noise-free data with the exact derivative of a sparse one-section model: the SR3 path with
    AICc selection finds the model's support on every window's basis (exact data make the true
    model a fixed point of SR3 for every threshold below its smallest coefficient)."""
    from vivbench.regression.optimizers import sr3_path

    theta, y, structural, expected = _exact_single_section_windows()
    assert np.abs(expected)[structural].min() >= 1e-2, "the test model needs coefficients above the path's first thresholds"
    path = sr3_path(theta, y, StlsqSettings(alpha=0.0, refit_rcond=None))
    assert np.all(path.selected >= 0)
    assert np.array_equal(path.best_support[:, 0], structural), "SR3 + AICc missed the sparse support"
    assert np.all(path.best_rss <= 1e-18 * np.sum(y**2, axis=1)), "an exact model must fit exactly"


def test_ensemble_on_exact_sparse_model_includes_exactly_its_terms():
    """Every bootstrap sample of exact data holds the same model: inclusion is 1 on its support, 0 elsewhere."""
    from vivbench.regression.optimizers import ensemble_path

    theta, y, structural, _ = _exact_single_section_windows()
    path, inclusion, threshold = ensemble_path(theta, y, StlsqSettings(alpha=0.0, refit_rcond=None), seed=3)
    assert np.array_equal(inclusion[:, 0], structural.astype(float)), "inclusion must be the support's indicator"
    assert np.all(path.selected == len(DEFAULT_THRESHOLDS)), "the ensemble model (last entry) must be selected"
    assert np.array_equal(path.best_support[:, 0], structural)
    assert np.all(np.isfinite(threshold))


def test_ensemble_is_deterministic_for_a_seed_and_leaves_global_state():
    from vivbench.regression.optimizers import OptimizerOptions

    t, A, U, dA = _noisy_event(2, 100.0)
    np.random.seed(123)
    before = np.random.get_state()[1].copy()
    kw = dict(optimizer="ensemble", keep_path=False, thresholds=DEFAULT_THRESHOLDS[::2],
              optimizer_options=OptimizerOptions(n_models=8))
    m1 = EventWindowSINDy(random_state=5, **kw).fit(t, A, U, dA)
    assert np.array_equal(np.random.get_state()[1], before), "the global random state must be restored"
    m2 = EventWindowSINDy(random_state=5, chunk_size=1, **kw).fit(t, A, U, dA)
    m3 = EventWindowSINDy(random_state=6, **kw).fit(t, A, U, dA)
    assert np.array_equal(m1.inclusion_, m2.inclusion_, equal_nan=True), "same seed, other chunking: same inclusion"
    assert np.array_equal(m1.coef_, m2.coef_, equal_nan=True)
    assert not np.array_equal(m1.inclusion_, m3.inclusion_), "another seed must draw other bootstrap samples"
    W = m1.window_start_.size
    assert m1.inclusion_.shape == (W, 3, 69)
    assert np.all((m1.inclusion_ >= 0) & (m1.inclusion_ <= 1))
    # 8 bootstrap models: probabilities are multiples of 1/8
    assert_close(m1.inclusion_ * 8, np.round(m1.inclusion_ * 8), rtol=0, atol=1e-12, reason="float division")
    kept = m1.support_ & (m1.inclusion_ < 0.5)
    assert not kept.any(), "a term below the inclusion cut must not be in the chosen model"


def test_optimizer_is_validated():
    from vivbench.regression.optimizers import OptimizerOptions

    t, A, U, dA = _noisy_event(0, 150.0)
    with pytest.raises(ValueError, match="optimizer must be one of"):
        EventWindowSINDy(optimizer="lasso").fit(t, A, U, dA)
    with pytest.raises(ValueError, match="inclusion_cut"):
        OptimizerOptions(inclusion_cut=0.0)
    with pytest.raises(ValueError, match="coef_rule"):
        OptimizerOptions(coef_rule="mean")


@pytest.mark.parametrize("optimizer", ["sr3", "ensemble"])
def test_pysindy_optimizers_through_identify_event(small_campaign, optimizer):
    """The pysindy-based optimisers give complete, valid result files on a campaign event."""
    from vivbench.analysis.identify import IdentifyConfig, identify_event
    from vivbench.io.event import read_event

    tree = read_event(small_campaign.files[1])
    ds = identify_event(tree, IdentifyConfig(optimizer=optimizer, window=60.0, step=120.0))
    W = ds.sizes["window"]
    assert W >= 3 and ds["coef"].shape == (W, 3, 69)
    regime = ds["regime"].values
    fitted = np.isfinite(ds["coef"].values).all(axis=2)
    assert fitted.any(), "no window got a model"
    assert np.all((regime[fitted] >= 1) & (regime[fitted] <= 4)), "regimes of fitted windows must be 1..4"
    assert np.all(regime[~fitted] == 0)
    assert set(np.unique(ds["identifiable"].values)) <= {0, 1}
    assert np.all(ds["identifiable"].values[~fitted] == 0)
    assert '"optimizer": "' + optimizer + '"' in ds.attrs["identify_config_json"]
    if optimizer == "ensemble":
        inc = ds["inclusion"].values
        assert inc.shape == (W, 3, 69)
        assert np.all((inc[fitted] >= 0) & (inc[fitted] <= 1))
    else:
        assert "inclusion" not in ds
