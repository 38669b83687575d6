"""The wind the deck feels vs the wind the anemometers measure (WindConfig.felt_wind, docs/concepts.md (no inverse crime))."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest
from scipy import integrate

from tests.helpers import REPO, assert_close, relative_rms
from vivbench.preprocess.wind import mean_wind as identified_mean_wind
from vivbench.synth import (
    AeroConfig,
    EventSpec,
    GeneratorConfig,
    StructureConfig,
    TurbulenceConfig,
    WindConfig,
    WindScript,
    config_from_dict,
    config_to_dict,
    davenport_coherence,
    kaimal_psd,
    load_config,
    simulate_event,
    simulate_turbulence,
)
from vivbench.synth.wind import MeanWind, anemometer_positions, tributary_points, wind_field

U = 8.0  # m/s, inside lock-in
FS = 32.0  # Hz, the anemometer rate
STRUCTURE = StructureConfig()
TRIBUTARY = WindConfig(felt_wind="tributary", points_per_section=5, anemometer_offset=8.0)
TURB = TurbulenceConfig()


def _constant_wind(duration: float, n_sections: int = 3) -> MeanWind:
    n = int(round(duration * FS))
    full = np.full((n, n_sections), U)
    return MeanWind(t=np.arange(n) / FS, U=full, V=full, direction=np.full(n, 120.0))


def _point_correlation(separation, component: int) -> np.ndarray:
    """Ensemble zero-lag correlation of one component at ``separation`` (m): int S coh df / int S df."""
    L, C = TURB.integral_lengths[component], TURB.coherence_decay[component]
    f = np.geomspace(1e-7, 1e6, 8000)
    S = kaimal_psd(f, U, 1.0, L)
    sep = np.asarray(separation, dtype=float)
    coh = davenport_coherence(f, sep[..., None], U, C)
    # S integrates to 1 over (0, inf); the part beyond 1e6 Hz is below 1e-4.
    return integrate.trapezoid(S * coh, f, axis=-1)


@pytest.fixture(scope="module")
def hour_fields():
    """Two 1 h tributary fields at constant wind: (positions (18,), [records (n, 18, 3)] for seeds 1, 2).

    Points: 3 anemometers, then 3 sections x 5 tributary points. ``wind_field``
    is checked to be exactly this simulation (anemometers) and its average (deck).
    """
    xs = wind_field(_constant_wind(60.0), STRUCTURE, TRIBUTARY, np.random.default_rng(0)).positions
    single = dataclasses.replace(TURB, double_indexing=False)
    raws = [simulate_turbulence(xs, U, 3600.0, FS, single, np.random.default_rng(seed)) for seed in (1, 2)]
    field = wind_field(_constant_wind(3600.0), STRUCTURE, TRIBUTARY, np.random.default_rng(1))
    assert np.array_equal(field.anemometer, raws[0][:, :3]), "anemometers: the first points of one coherent field"
    assert_close(field.deck, raws[0][:, 3:].reshape(-1, 3, 5, 3).mean(axis=2), rtol=1e-12, atol=1e-15, reason="rounding",
                 what="deck turbulence is the average over each section's points")
    return xs, raws


# ---------------------------------------------------------------- geometry


def test_points_spread_evenly_over_each_tributary_length():
    pts = tributary_points(STRUCTURE, TRIBUTARY)
    assert pts.shape == (3, 5), f"shape {pts.shape}"
    assert_close(pts.mean(axis=1), STRUCTURE.positions, rtol=1e-14, reason="rounding", what="points centred on the section")
    assert_close(np.diff(pts, axis=1), np.full((3, 4), 110.0), rtol=1e-12, reason="rounding", what="550 m / 5 spacing")
    # Midpoints of equal strips: the strips of neighbouring sections tile the span.
    assert_close(pts[:, 0] - 55.0, STRUCTURE.positions - 275.0, rtol=1e-14, reason="rounding", what="first strip edge")
    assert_close(anemometer_positions(STRUCTURE, TRIBUTARY), STRUCTURE.positions + 8.0, rtol=1e-14, reason="rounding",
                 what="anemometer offset")
    assert np.array_equal(anemometer_positions(STRUCTURE, WindConfig(felt_wind="anemometer")), STRUCTURE.positions), \
        "in_library anemometers sit at the sections"


def test_anemometer_mode_deck_is_the_anemometer():
    mw = _constant_wind(120.0)
    f = wind_field(mw, STRUCTURE, WindConfig(felt_wind="anemometer"), np.random.default_rng(0))
    assert f.deck is f.anemometer and f.positions.size == 3, "in_library: the deck feels the anemometer's own turbulence"
    ref = simulate_turbulence(STRUCTURE.positions, U, 120.0, FS, TURB, np.random.default_rng(0))
    assert np.array_equal(f.anemometer, ref), "in_library field is today's 3-point simulation, unchanged"


def test_one_point_at_the_anemometer_gives_the_anemometer_wind():
    # One tributary point at the section's position and no offset: the deck and
    # the anemometer are the same point, so their turbulence is identical.
    cfg = WindConfig(felt_wind="tributary", points_per_section=1, anemometer_offset=0.0)
    f = wind_field(_constant_wind(120.0), STRUCTURE, cfg, np.random.default_rng(0))
    assert np.array_equal(f.deck, f.anemometer), "coincident points are fully coherent"


# ---------------------------------------------------------------- statistics


def test_field_correlations_match_davenport(hour_fields):
    # Zero-lag correlations of all 18 x 18 pairs (separations 8 m to 1.4 km)
    # against int S coh df / int S df. The single-indexed field's sample
    # correlations scatter like a natural record's: over 2 x 1 h, u and v
    # (integral times ~40 s and ~14 s, strong low-frequency content) scatter
    # by ~0.04 rms, w by ~0.015; bounds are about 3 sigma on the max.
    xs, raws = hour_fields
    target_sep = np.abs(xs[:, None] - xs[None, :])
    for c, (max_tol, rms_tol) in enumerate([(0.15, 0.06), (0.15, 0.06), (0.06, 0.025)]):
        R = np.mean([np.corrcoef(r[:, :, c].T) for r in raws], axis=0)
        err = R - _point_correlation(target_sep, c)
        assert np.abs(err).max() < max_tol, f"{'uvw'[c]}: max correlation error {np.abs(err).max():.3f} (limit {max_tol})"
        assert np.sqrt(np.mean(err**2)) < rms_tol, f"{'uvw'[c]}: rms correlation error {np.sqrt(np.mean(err**2)):.3f}"


def test_double_indexing_would_miss_the_tributary_coherence():
    # Why the tributary field is single-indexed: with 18 points each source is
    # resolved every 18 / T Hz, coarser than the u coherence over hundreds of
    # metres varies (U / (C dx) ~ 0.001 Hz), and the correlations come out far too high.
    xs = wind_field(_constant_wind(60.0), STRUCTURE, TRIBUTARY, np.random.default_rng(0)).positions
    R = np.corrcoef(simulate_turbulence(xs, U, 3600.0, FS, TURB, np.random.default_rng(0))[:, :, 0].T)
    err = R - _point_correlation(np.abs(xs[:, None] - xs[None, :]), 0)
    assert err.max() > 0.2, f"double indexing should overestimate far correlations of u; max error {err.max():.3f}"


def test_tributary_average_reduces_variance_by_the_davenport_factor(hour_fields):
    # Var(mean of P points) / Var(point) = (1/P^2) sum_ij rho(x_i - x_j), with rho
    # the zero-lag correlation int S coh df / int S df: 0.45 for u, 0.29 for w
    # over 5 points 110 m apart. Over 2 records x 3 sections (1 h each) the
    # sample ratio scatters by ~5 % (u, v) and ~2 % (w): bounds 12 % and 6 %.
    xs, raws = hour_fields
    pts = tributary_points(STRUCTURE, TRIBUTARY)[0]
    sep = np.abs(pts[:, None] - pts[None, :])
    sigmas = TURB.intensity * U * np.array([1.0, TURB.ratio_v, TURB.ratio_w])
    for c, tol in [(0, 0.12), (1, 0.12), (2, 0.06)]:
        predicted = float(_point_correlation(sep, c).mean())
        assert predicted < 0.6, f"{'uvw'[c]}: the averaging should remove a large part of the variance ({predicted:.3f})"
        deck = np.mean([r[:, 3:, c].reshape(-1, 3, 5).mean(axis=2).var(axis=0) for r in raws]) / sigmas[c] ** 2
        point = np.mean([r[:, :3, c].var(axis=0) for r in raws]) / sigmas[c] ** 2
        assert_close(point, 1.0, rtol=tol, reason="sample variance of single-indexed records", what=f"point variance {'uvw'[c]}")
        assert deck < 0.75 * point, f"{'uvw'[c]}: averaging must reduce the variance ({deck:.3f} vs {point:.3f})"
        assert_close(deck, predicted, rtol=tol, reason="sample variance of single-indexed records",
                     what=f"variance reduction of {'uvw'[c]} over the tributary length")


# ---------------------------------------------------------------- events: truth and errors-in-variables


def _pass_spec(T: float, plateau: float) -> EventSpec:
    script = WindScript(times=(0.0, 0.1 * T, 0.25 * T, 0.7 * T, 0.85 * T, T), speeds=(4.5, 4.5, plateau, plateau, 4.5, 4.5))
    return EventSpec(event_id="T", start_time="2026-01-01T00:00:00Z", kind="test", script=script)


def _noise_free(mode: str) -> GeneratorConfig:
    """Turbulence on (it moves U_k), but no buffeting, unlocked shedding or sensor errors."""
    return GeneratorConfig(aero=AeroConfig(cl_unlocked=0.0, buffeting_w=0.0, buffeting_u=0.0),
                           wind=WindConfig(felt_wind=mode, noise=0.0, resolution=0.0))


@pytest.mark.parametrize("plateau", [7.5, 8.8])
def test_averaged_model_reproduces_envelope_in_tributary_mode(plateau):
    # The 2 % test of tests/synth/test_bridge.py with the tributary felt wind: the truth
    # integrates the same U_k as the simulation's aeroelastic force (0.1 % seen).
    cfg = _noise_free("tributary")
    ev = simulate_event(_pass_spec(1500.0, plateau), cfg, 7)
    omega = cfg.structure.omega
    Q_full = np.sqrt(ev.q**2 + (ev.qd / omega) ** 2)
    keep = (ev.accel_time > 60.0) & (ev.accel_time < ev.accel_time[-1] - 60.0)
    err = relative_rms(Q_full[keep], np.interp(ev.accel_time, ev.truth_time, ev.Q)[keep])
    assert err < 0.02, f"averaged model misses the simulated envelope by {err:.2%} RMS (limit 2 %)"
    assert ev.Q.max() > 0.05, "the pass should reach a VIV plateau"


def test_identified_wind_differs_from_the_felt_wind_only_in_tributary_mode():
    # Diagnostic of the errors-in-variables: RMS over an event (2 min of filter
    # edges dropped) of the identification's U (the anemometer's low-passed
    # perpendicular wind, vivbench.preprocess) minus the felt U_k of the truth.
    # In the in_library mode only the 1 % sensor noise (~0.003 m/s after the
    # low-pass) and rounding remain; in tributary mode the point's slow
    # turbulence differs from the tributary average's: ~0.3 m/s.
    T = 900.0
    rms = {}
    for mode in ("anemometer", "tributary"):
        cfg = GeneratorConfig(wind=WindConfig(felt_wind=mode))
        ev = simulate_event(_pass_spec(T, 8.5), cfg, 11)
        U_id = identified_mean_wind(ev.wind_time, ev.u, ev.v, cfg.wind.span_azimuth_deg)
        U_felt = np.stack([np.interp(ev.wind_time, ev.truth_time, ev.U[:, k]) for k in range(ev.U.shape[1])], axis=1)
        keep = (ev.wind_time > 120.0) & (ev.wind_time < T - 120.0)
        rms[mode] = float(np.sqrt(np.mean((U_id[keep] - U_felt[keep]) ** 2)))
    assert rms["anemometer"] < 0.01, f"in_library: identified U vs felt U rms {rms['anemometer']:.4f} m/s"
    assert rms["tributary"] > 0.05 and rms["tributary"] > 10 * rms["anemometer"], f"tributary: rms {rms}"


def test_same_seed_same_bytes_in_tributary_mode():
    cfg = GeneratorConfig(wind=TRIBUTARY)
    a, b = (simulate_event(_pass_spec(120.0, 8.0), cfg, np.random.SeedSequence(5)) for _ in range(2))
    for name in ("u", "v", "w", "acc", "U", "Q"):
        assert getattr(a, name).tobytes() == getattr(b, name).tobytes(), f"{name} differs between runs of the same seed"


# ---------------------------------------------------------------- configuration


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"felt_wind": "deck"}, r"felt_wind must be one of 'anemometer', 'tributary', 'smooth'; got 'deck'"),
        ({"felt_wind": None}, r"felt_wind must be one of"),
        ({"points_per_section": 0}, r"points_per_section must be an integer from 1 to 64; got 0"),
        ({"points_per_section": 65}, r"points_per_section must be an integer from 1 to 64"),
        ({"points_per_section": 2.5}, r"points_per_section must be an integer"),
        ({"points_per_section": True}, r"points_per_section must be an integer"),
        ({"anemometer_offset": float("nan")}, r"anemometer_offset must be a finite distance \(m\)"),
        ({"anemometer_offset": "mast"}, r"anemometer_offset must be a finite distance"),
    ],
)
def test_config_validation_messages(kwargs, message):
    with pytest.raises(ValueError, match=message):
        WindConfig(**kwargs)


def test_config_round_trip_and_legacy_form(tmp_path):
    example = load_config(REPO / "examples" / "wind_tributary.toml")
    assert example.wind.felt_wind == "tributary" and example.wind.points_per_section == 5
    assert example.wind.anemometer_offset == 8.0
    data = config_to_dict(example)
    assert data["wind"]["felt_wind"] == "tributary", "a non-default felt wind is stored"
    assert config_from_dict(data) == example, "round trip of the tributary configuration"
    # The default is the realistic mode: WindConfig() is the tributary-averaged felt wind.
    assert WindConfig() == WindConfig(felt_wind="tributary") == GeneratorConfig().wind
    # Every key is stored, so both modes read back as themselves whatever the defaults.
    for cfg in (GeneratorConfig(), GeneratorConfig.in_library()):
        data = json.loads(json.dumps(config_to_dict(cfg)))
        assert {"felt_wind", "points_per_section", "anemometer_offset"} <= set(data["wind"])
        assert config_from_dict(data) == cfg and config_from_dict(data).mode == cfg.mode
    odd = GeneratorConfig.in_library(wind={"points_per_section": 3})  # unused in anemometer mode, but kept
    assert config_from_dict(config_to_dict(odd)) == odd
    toml = tmp_path / "w.toml"
    toml.write_text('[wind]\nfelt_wind = "tributary"\npoints_per_section = 7\n')
    cfg = load_config(toml)
    assert cfg.wind.points_per_section == 7 and cfg.wind.anemometer_offset == 0.0
    bad = tmp_path / "bad.toml"
    bad.write_text('[wind]\nfelt_wind = "tributory"\n')
    with pytest.raises(ValueError, match=r"bad\.toml: felt_wind must be one of"):
        load_config(bad)


def test_old_saved_form_without_the_felt_wind_keys_reads_back_as_in_library():
    # Event files written before the realistic default left out the felt-wind keys
    # (and a None yaw factor) of an in_library configuration: config_from_dict
    # restores those values for a saved form (every top-level key present).
    old = config_to_dict(GeneratorConfig.in_library())
    for key in ("felt_wind", "points_per_section", "anemometer_offset"):
        del old["wind"][key]
    del old["aero"]["yaw"]
    back = config_from_dict(json.loads(json.dumps(old)))
    assert back == GeneratorConfig.in_library() and back.mode == "in_library"
    # the same for a saved form with only the wind keys missing (a realistic aero with its yaw kept)
    mixed = config_to_dict(GeneratorConfig.realistic(wind=WindConfig(felt_wind="anemometer")))
    for key in ("felt_wind", "points_per_section", "anemometer_offset"):
        del mixed["wind"][key]
    assert config_from_dict(mixed) == GeneratorConfig.realistic(wind=WindConfig(felt_wind="anemometer"))
    # a partial (hand-written) dict takes the realistic defaults for what it leaves out
    partial = config_from_dict({"structure": {"frequency": 0.3}, "wind": {"noise": 0.02}})
    assert partial.mode == "realistic" and partial.wind.felt_wind == "tributary" and partial.aero.yaw is not None
