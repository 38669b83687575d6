"""Tests of the turbulence field (vivbench.synth.turbulence, docs/concepts.md (the bridge and the wind))."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import integrate, signal

from tests.helpers import assert_close, assert_not_close
from vivbench.synth.turbulence import (
    KAIMAL_LENGTH_FACTORS,
    TurbulenceConfig,
    _full_factor,
    davenport_coherence,
    kaimal_psd,
    simulate_turbulence,
    target_sigmas,
)

U = 8.0  # m/s, inside the lock-in range of the default bridge
FS = 32.0  # Hz, the anemometer rate
SECTIONS = np.array([0.0, 10.0, 20.0])  # m: close enough that the coherence is measurable
CONFIG = TurbulenceConfig()


def _simulate(seed: int, *, duration: float = 600.0, positions=SECTIONS, config: TurbulenceConfig = CONFIG, mean_speed: float = U) -> np.ndarray:
    return simulate_turbulence(positions, mean_speed, duration, FS, config, np.random.default_rng(seed))


@pytest.fixture(scope="module")
def long_records() -> list[np.ndarray]:
    """Two 2 h records: enough Welch segments for few-per-cent spectral estimates."""
    return [_simulate(seed, duration=7200.0) for seed in (11, 12)]


# ---------------------------------------------------------------- model formulas


@pytest.mark.parametrize("L", [340.2, 113.4, 27.72])
def test_kaimal_cumulative_matches_closed_form(L):
    # Integrating S from 0 to F gives sigma^2 (1 - (1 + 6 F L / U)^(-2/3)); a
    # wrong exponent or factor in kaimal_psd breaks this at every F.
    sigma = 0.7
    for F in (0.01, 0.1, 1.0, 10.0):
        numeric = integrate.quad(lambda f: kaimal_psd(f, U, sigma, L), 0.0, F, limit=200)[0]
        exact = sigma**2 * (1.0 - (1.0 + 6.0 * F * L / U) ** (-2.0 / 3.0))
        assert_close(numeric, exact, rtol=1e-7, reason="quad accuracy", what=f"cumulative Kaimal to {F} Hz")
    total = integrate.quad(lambda f: kaimal_psd(f, U, sigma, L), 0.0, np.inf, limit=200)[0]
    assert_close(total, sigma**2, rtol=1e-6, reason="quad accuracy on an infinite interval", what="Kaimal variance")


def test_kaimal_broadcasts_and_validates():
    out = kaimal_psd(np.array([[0.0], [1.0]]), U, np.array([1.0, 2.0]), 100.0)
    assert out.shape == (2, 2), f"broadcast shape {out.shape}"
    assert_close(out[0], 4.0 * 100.0 / U * np.array([1.0, 4.0]), what="S(0) = 4 sigma^2 L / U")
    for args in [(-1.0, U, 1.0, 10.0), (1.0, 0.0, 1.0, 10.0), (1.0, U, -1.0, 10.0), (1.0, U, 1.0, 0.0)]:
        with pytest.raises(ValueError):
            kaimal_psd(*args)


def test_davenport_coherence_values():
    f = np.array([0.0, 0.1, 0.5])
    assert_close(davenport_coherence(f, 0.0, U, 10.0), np.ones(3), what="zero separation is fully coherent")
    assert_close(davenport_coherence(f, -20.0, U, 10.0), davenport_coherence(f, 20.0, U, 10.0), what="sign of the separation")
    # At f dx / U = 1 / C the coherence is 1/e.
    assert_close(davenport_coherence(U / (10.0 * 25.0), 25.0, U, 10.0), np.exp(-1.0), rtol=1e-15, reason="rounding", what="e-folding")
    with pytest.raises(ValueError):
        davenport_coherence(0.1, 1.0, -U, 10.0)
    with pytest.raises(ValueError):
        davenport_coherence(0.1, 1.0, U, -1.0)


def test_closed_form_cholesky_matches_numpy():
    # The Markov closed form must be the Cholesky factor of the Davenport
    # coherence matrix of the sorted points (checked where numpy's is stable).
    xs = np.array([0.0, 3.0, 10.0, 31.0, 32.5])
    f = np.array([0.02, 0.2, 2.0])
    a = 7.0 * f / U
    ours = np.moveaxis(_full_factor(a, xs), -1, 0)
    coh = davenport_coherence(f[:, None, None], xs[:, None] - xs[None, :], U, 7.0)
    assert_close(ours, np.linalg.cholesky(coh), atol=1e-12, reason="LAPACK rounding", what="Cholesky factor")


# ---------------------------------------------------------------- configuration


def test_config_defaults_and_lengths():
    assert CONFIG.intensity == 0.08 and CONFIG.length_scale == 42.0, "defaults changed"
    assert_close(CONFIG.integral_lengths, 42.0 * np.array(KAIMAL_LENGTH_FACTORS), what="IEC integral lengths")
    assert_close(target_sigmas(10.0, CONFIG), np.array([0.8, 0.64, 0.4]), rtol=1e-15, reason="rounding", what="sigmas")


def test_config_round_trips_through_json():
    data = json.loads(json.dumps(dataclasses.asdict(CONFIG)))
    assert TurbulenceConfig(**data) == CONFIG, "a JSON round trip (lists for tuples) must give the same config"


@pytest.mark.parametrize(
    "kwargs",
    [
        {"intensity": -0.01},
        {"intensity": 0.5},
        {"intensity": float("nan")},
        {"ratio_v": -0.1},
        {"ratio_w": 3.0},
        {"length_scale": 0.0},
        {"length_scale": "long"},
        {"coherence_decay": (10.0, 7.0)},
        {"coherence_decay": (10.0, -7.0, 4.0)},
        {"coherence_decay": 10.0},
        {"double_indexing": "yes"},
        {"rescale_to_sigma": 1},
    ],
)
def test_config_rejects_bad_values(kwargs):
    with pytest.raises(ValueError, match=next(iter(kwargs)).split("_")[0]):
        TurbulenceConfig(**kwargs)


# ---------------------------------------------------------------- simulation: interface


def test_shape_zero_mean_and_single_point():
    out = simulate_turbulence([5.0], U, 10.01, FS, CONFIG, np.random.default_rng(0))
    assert out.shape == (320, 1, 3), f"round(10.01 * 32) = 320 samples; got {out.shape}"
    odd = _simulate(1, duration=601 / FS)
    assert odd.shape == (601, 3, 3), f"odd length; got {odd.shape}"
    assert_close(odd.mean(axis=0), np.zeros((3, 3)), atol=1e-14, reason="rounding; the mean bin is zero", what="record means")


def test_same_seed_same_bytes_different_seed_differs():
    a, b, c = _simulate(3), _simulate(3), _simulate(4)
    assert a.tobytes() == b.tobytes(), "same rng state must give identical bytes"
    assert_not_close(a, c, what="different seeds must give different records")


def test_zero_intensity_returns_zeros_and_advances_rng_alike():
    rng0, rng1 = np.random.default_rng(5), np.random.default_rng(5)
    zero = simulate_turbulence(SECTIONS, U, 60.0, FS, TurbulenceConfig(intensity=0.0), rng0)
    simulate_turbulence(SECTIONS, U, 60.0, FS, CONFIG, rng1)
    assert zero.shape == (1920, 3, 3) and not np.any(zero), "zero intensity must give exact zeros"
    assert rng0.random() == rng1.random(), "the rng must advance the same whatever the intensity"


def test_short_record_needs_single_indexing():
    cfg = TurbulenceConfig(double_indexing=False)
    out = simulate_turbulence(SECTIONS, U, 6 / FS, FS, cfg, np.random.default_rng(0))
    # Single indexing has no minimum length beyond one bin (here 2 bins).
    assert out.shape == (6, 3, 3) and np.all(np.isfinite(out)) and np.all(out.std(axis=0) > 0), "short single-indexed record"
    with pytest.raises(ValueError, match="double_indexing=False"):
        simulate_turbulence(SECTIONS, U, 6 / FS, FS, CONFIG, np.random.default_rng(0))


def test_equal_positions_give_identical_records():
    out = _simulate(2, positions=[0.0, 50.0, 0.0])
    assert np.array_equal(out[:, 0], out[:, 2]), "coincident points are fully coherent"


@pytest.mark.parametrize(
    ("kwargs", "error"),
    [
        ({"positions": [[0.0, 1.0]]}, ValueError),
        ({"positions": []}, ValueError),
        ({"positions": [0.0, np.nan]}, ValueError),
        ({"mean_speed": 0.0}, ValueError),
        ({"mean_speed": np.inf}, ValueError),
        ({"duration": -1.0}, ValueError),
        ({"fs": 0.0}, ValueError),
        ({"duration": 0.05}, ValueError),  # rounds to 2 samples
        ({"duration": 6 / FS}, ValueError),  # 3 points need 7 samples for a bin each
        ({"rng": 42}, TypeError),
        ({"config": {"intensity": 0.1}}, TypeError),
    ],
)
def test_simulate_rejects_bad_input(kwargs, error):
    args = {"positions": SECTIONS, "mean_speed": U, "duration": 60.0, "fs": FS, "config": CONFIG, "rng": np.random.default_rng(0)}
    args.update(kwargs)
    with pytest.raises(error):
        simulate_turbulence(**args)


# ---------------------------------------------------------------- simulation: statistics


def test_standard_deviations_are_the_targets():
    # With rescaling and double indexing every record's variance is exact
    # (each bin has one phase, so the variance does not depend on the seed).
    out = _simulate(6, duration=3600.0)
    std = out.std(axis=0)
    assert_close(std, np.broadcast_to(target_sigmas(U, CONFIG), (3, 3)), rtol=1e-12, reason="rounding in a 115200-sample sum", what="sigma")
    assert_close(std[:, 0] / U, np.full(3, CONFIG.intensity), rtol=1e-12, reason="rounding", what="turbulence intensity")


def test_standard_deviations_without_rescaling():
    # Unscaled Kaimal ordinates miss the spectrum below ~1/T and above fs/2
    # and the low-frequency Riemann sum on the n/T grid is coarse: a few
    # per cent in sigma for a 1 h record at 32 Hz (w loses ~2 % of its
    # variance above 16 Hz).
    out = _simulate(6, duration=3600.0, config=TurbulenceConfig(rescale_to_sigma=False))
    assert_close(out.std(axis=0), np.broadcast_to(target_sigmas(U, CONFIG), (3, 3)), rtol=0.03, reason="spectrum truncated at 1/T and fs/2", what="sigma")


def test_single_indexing_standard_deviations():
    # Single-indexed records are not ergodic: the sample variance of one
    # 2 h record scatters by a few per cent around the target (u, whose
    # integral time ~40 s gives ~90 independent samples, scatters most).
    out = _simulate(8, duration=7200.0, config=TurbulenceConfig(double_indexing=False))
    assert_close(out.std(axis=0), np.broadcast_to(target_sigmas(U, CONFIG), (3, 3)), rtol=0.06, reason="non-ergodic sample variance of a 2 h record", what="sigma")


def test_psd_matches_kaimal(long_records):
    # Welch (8192-sample Hann segments, 0.0039 Hz) over 2 records x 2 h,
    # averaged over the 3 points in 9 log bands 0.01-5 Hz. The lowest band
    # holds ~3 bins x ~55 segments x 2 records of which the 3 points are
    # strongly correlated: ~5 % one-sigma, hence 10 % per band; the mean over
    # all bands must be within 3 %. The rescaling to sigma lifts the w PSD by
    # ~2 % (its variance above 16 Hz is put back into the simulated band).
    sig, L = target_sigmas(U, CONFIG), CONFIG.integral_lengths
    f, P = signal.welch(np.stack(long_records), fs=FS, nperseg=8192, axis=1)
    P = P.mean(axis=(0, 2))  # (n_f, 3): mean over records and points
    edges = np.geomspace(0.01, 5.0, 10)
    for k in range(3):
        S = kaimal_psd(f, U, sig[k], L[k])
        ratio = np.array([P[(f >= lo) & (f < hi), k].mean() / S[(f >= lo) & (f < hi)].mean() for lo, hi in zip(edges[:-1], edges[1:])])
        assert_close(ratio, np.ones_like(ratio), rtol=0.10, reason="Welch estimate, lowest band ~5 % one-sigma", what=f"PSD/Kaimal per band, component {'uvw'[k]}")
        assert_close(ratio.mean(), 1.0, rtol=0.03, reason="band-averaged Welch estimate", what=f"mean PSD/Kaimal, component {'uvw'[k]}")


def test_coherence_matches_davenport(long_records):
    # Co-coherence Re(S_xy) / sqrt(S_xx S_yy) (Davenport's is real) from
    # Welch with 4096-sample segments (0.0078 Hz), 2 records x 2 h, for the
    # pairs 10 m (0-1, 1-2) and 20 m (0-2) apart, in log bands from 0.01 Hz
    # up to where Davenport falls to 0.2. Estimator scatter with ~110
    # segments per record and a few bins per band: ~0.02, hence 0.05.
    x = np.stack(long_records)
    kw = {"fs": FS, "nperseg": 4096, "axis": 1}
    for i, j in [(0, 1), (1, 2), (0, 2)]:
        f, Pxy = signal.csd(x[:, :, i], x[:, :, j], **kw)
        _, Pxx = signal.welch(x[:, :, i], **kw)
        _, Pyy = signal.welch(x[:, :, j], **kw)
        co = Pxy.real.mean(axis=0) / np.sqrt(Pxx.mean(axis=0) * Pyy.mean(axis=0))  # (n_f, 3)
        dx = SECTIONS[j] - SECTIONS[i]
        for k, C in enumerate(CONFIG.coherence_decay):
            f_max = np.log(5.0) * U / (C * dx)
            edges = np.geomspace(0.01, f_max, 5)
            est = np.array([co[(f >= lo) & (f < hi), k].mean() for lo, hi in zip(edges[:-1], edges[1:])])
            target = np.array([davenport_coherence(f[(f >= lo) & (f < hi)], dx, U, C).mean() for lo, hi in zip(edges[:-1], edges[1:])])
            assert_close(est, target, atol=0.05, reason="Welch coherence estimator scatter", what=f"co-coherence {'uvw'[k]}, points {i}-{j}")


def test_double_indexing_is_ergodic():
    # With double indexing every bin carries one phase, so the cross-spectrum
    # of the whole record (hence every circular cross-covariance) is the same
    # for every seed, while the records themselves differ.
    recs = [_simulate(seed, duration=3600.0) for seed in (21, 22, 23)]
    spectra = [np.fft.rfft(r, axis=0) for r in recs]
    cross = [s[:, 0, :] * np.conj(s[:, 2, :]) for s in spectra]
    scale = np.abs(cross[0]).max()
    for other in cross[1:]:
        assert_close(other, cross[0], atol=1e-10 * scale, reason="FFT rounding", what="whole-record cross-spectrum across seeds")
    # The zero-lag correlation of u at 10 m equals the target
    # int S coh df / int S df (0.78); 2 % for the Riemann sum on the n/T
    # grid near the u spectral peak (0.004 Hz) of a 1 h record (0.6 % seen;
    # 2.4 % for a 10 min record, where 3/T = 0.005 Hz).
    L, C = CONFIG.integral_lengths[0], CONFIG.coherence_decay[0]
    num = integrate.quad(lambda f: kaimal_psd(f, U, 1.0, L) * davenport_coherence(f, 10.0, U, C), 0.0, np.inf, limit=200)[0]
    rho = np.corrcoef(recs[0][:, 0, 0], recs[0][:, 1, 0])[0, 1]
    assert_close(rho, num, rtol=0.02, reason="Riemann sum on the n/T frequency grid", what="u correlation at 10 m")


def test_single_indexing_is_not_ergodic():
    # Contrast: independent phases per source and bin make the zero-lag
    # covariance a random quantity (the reason double indexing is the default).
    cfg = TurbulenceConfig(double_indexing=False)
    covs = [np.cov(_simulate(seed, config=cfg)[:, :, 0].T)[0, 2] for seed in (21, 22)]
    assert abs(covs[0] - covs[1]) > 1e-3 * target_sigmas(U, CONFIG)[0] ** 2, f"covariances {covs} should differ between seeds"


# ---------------------------------------------------------------- properties


@settings(max_examples=15, deadline=None, derandomize=True)
@given(intensity=st.floats(0.01, 0.49), seed=st.integers(0, 2**32 - 1))
def test_output_is_proportional_to_intensity(intensity, seed):
    base = simulate_turbulence(SECTIONS, U, 30.0, FS, CONFIG, np.random.default_rng(seed))
    scaled = simulate_turbulence(SECTIONS, U, 30.0, FS, dataclasses.replace(CONFIG, intensity=intensity), np.random.default_rng(seed))
    assert_close(scaled, base * (intensity / CONFIG.intensity), rtol=1e-12, atol=1e-15, reason="rounding", what="linearity in the intensity")
    assert_close(scaled.var(axis=0), base.var(axis=0) * (intensity / CONFIG.intensity) ** 2, rtol=1e-12, reason="rounding", what="variance ~ I^2")


@settings(max_examples=20, deadline=None, derandomize=True)
@given(
    positions=st.lists(st.floats(-500.0, 500.0), min_size=1, max_size=5),
    n_samples=st.integers(11, 300),  # double indexing needs 2 n + 1 samples
    double=st.booleans(),
    data=st.data(),
)
def test_shape_and_permutation_equivariance(positions, n_samples, double, data):
    cfg = TurbulenceConfig(double_indexing=double)
    out = simulate_turbulence(positions, U, n_samples / FS, FS, cfg, np.random.default_rng(1))
    assert out.shape == (n_samples, len(positions), 3), f"shape {out.shape}"
    assert np.all(np.isfinite(out)), "non-finite output"
    perm = data.draw(st.permutations(range(len(positions))))
    permuted = simulate_turbulence([positions[p] for p in perm], U, n_samples / FS, FS, cfg, np.random.default_rng(1))
    assert np.array_equal(permuted, out[:, perm]), "permuting the positions must permute the records, nothing else"
