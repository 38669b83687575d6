"""The synthetic bridge: averaged truth vs full simulation, sensors, determinism, config."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from scipy.signal import welch

from tests.helpers import assert_close, relative_rms, run_cli
from vivbench.io.event import read_event
from vivbench.core.regime import classify_regime
from vivbench.synth import (
    CampaignConfig,
    DefectConfig,
    EventSpec,
    GeneratorConfig,
    SensorConfig,
    StructureConfig,
    TurbulenceConfig,
    WindScript,
    bell_polynomial,
    config_from_dict,
    config_to_dict,
    exact_coefficients,
    generate_campaign,
    load_config,
    order_contributions,
    simulate_event,
)
from vivbench.synth.config import Polynomial
from vivbench.core.terms import evaluate_library


def _quiet_config(mode: str = "realistic", **aero) -> GeneratorConfig:
    """No turbulence, no buffeting, no unlocked shedding: the averaging hypotheses hold (``mode``: docs/concepts.md (no inverse crime))."""
    return GeneratorConfig.from_mode(
        mode,
        aero=dict(cl_unlocked=0.0, buffeting_w=0.0, buffeting_u=0.0, **aero),
        wind=dict(turbulence=TurbulenceConfig(intensity=0.0), speed_wander=0.1, section_wander=0.005),
    )


def _pass_script(T: float, plateau: float) -> WindScript:
    return WindScript(times=(0.0, 0.1 * T, 0.25 * T, 0.7 * T, 0.85 * T, T),
                      speeds=(4.5, 4.5, plateau, plateau, 4.5, 4.5))


def _envelope_error(ev, omega: float, edge: float = 60.0) -> float:
    # The instantaneous amplitude of the oscillator is the envelope of q.
    Q_full = np.sqrt(ev.q**2 + (ev.qd / omega) ** 2)
    Q_avg = np.interp(ev.accel_time, ev.truth_time, ev.Q)
    keep = (ev.accel_time > edge) & (ev.accel_time < ev.accel_time[-1] - edge)
    return relative_rms(Q_full[keep], Q_avg[keep])


@settings(max_examples=8, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    peak=st.floats(12.0, 30.0),
    e1_scale=st.floats(0.5, 2.0),
    e2_scale=st.floats(0.5, 2.0),
    zeta=st.floats(0.002, 0.006),
    plateau=st.floats(7.0, 9.5),
    freq=st.floats(0.25, 0.45),
)
def test_averaged_model_reproduces_envelope(peak, e1_scale, e2_scale, zeta, plateau, freq):
    Y1 = bell_polynomial(peak, 8.0, 2.5)
    e1 = Polynomial(coefficients=tuple(c * 1.4 * e1_scale / peak for c in Y1.coefficients))
    e2 = Polynomial(coefficients=tuple(c * 20.0 * e2_scale / peak for c in Y1.coefficients))
    # polynomial curves drawn around the in_library ones: that mode (no yaw factor); the default's own
    # non-polynomial curves are checked below and in test_aero_curves
    cfg = _quiet_config("in_library", Y1=Y1, e1=e1, e2=e2)
    cfg = GeneratorConfig(structure=StructureConfig(frequency=freq, damping_ratio=zeta), aero=cfg.aero, wind=cfg.wind)
    T = 1500.0
    spec = EventSpec(event_id="T", start_time="2026-01-01T00:00:00Z", kind="test", script=_pass_script(T, plateau))
    ev = simulate_event(spec, cfg, 7)
    err = _envelope_error(ev, cfg.structure.omega)
    assert err < 0.02, f"averaged model misses the simulated envelope by {err:.2%} RMS (limit 2 %)"


@pytest.mark.parametrize("mode", ["realistic", "in_library"])
def test_averaged_model_envelope_with_default_parameters(mode):
    """The averaged model within 0.5 % of the simulated envelope for the default (realistic) bridge and in_library."""
    cfg = _quiet_config(mode)
    spec = EventSpec(event_id="T", start_time="2026-01-01T00:00:00Z", kind="test", script=_pass_script(2400.0, 8.8))
    ev = simulate_event(spec, cfg, 3)
    err = _envelope_error(ev, cfg.structure.omega)
    assert err < 0.005, f"default parameters: envelope error {err:.3%} RMS"
    assert ev.Q.max() > 0.1, "the default pass should reach a VIV plateau above 0.1 m"


def test_exact_coefficients_reproduce_truth(event1_in_library):
    # exact recovery needs the truth in the library: the in_library mode
    spec, ev = event1_in_library
    cfg = GeneratorConfig.in_library()
    Xi = exact_coefficients(cfg.structure, cfg.aero)
    assert Xi is not None and Xi.shape == (3, 69)
    A = ev.Q[:, None] * np.array(cfg.structure.mode_shape)[None, :]
    dA_library = evaluate_library(A, ev.U) @ Xi.T
    dA_truth = ev.r.sum(axis=-1)
    assert_close(dA_library, dA_truth, rtol=1e-9, atol=1e-12 * np.abs(dA_truth).max(),
                 reason="float64 sums of up to 69 products of different magnitude")
    # and dQ/dt of the averaged model agrees with the finite difference of its own trajectory
    dQ = np.gradient(ev.Q, ev.truth_time)
    r_modal = order_contributions(ev.Q, ev.U, cfg.structure, cfg.aero).sum(axis=1)
    assert relative_rms(dQ[5:-5], r_modal[5:-5]) < 0.02


def test_event1_visits_all_regimes_in_paper_order(event1):
    spec, ev = event1
    reg = ev.regime[:, 1]
    assert set(np.unique(reg)) == {1, 2, 3, 4}
    # growth (2) comes before the strongly self-excited plateau (4), which comes before the final decay (1)
    first2 = np.argmax(reg == 2)
    first4 = np.argmax(reg == 4)
    last4 = len(reg) - 1 - np.argmax(reg[::-1] == 4)
    assert first2 < first4 < last4
    assert np.all(reg[-60:] == 1), "the event should end damped after the wind left lock-in"


def test_truth_regime_is_the_shared_rule(event1):
    spec, ev = event1
    A = ev.Q[:, None] * np.array(StructureConfig().mode_shape)[None, :]
    again = classify_regime(ev.r[None], A[None], tau=0.2, axis=0)
    np.testing.assert_array_equal(again, ev.regime)


def test_default_campaign_visits_all_regimes(default_campaign_specs):
    cfg = CampaignConfig().generator
    kinds = {spec.kind for spec, _ in default_campaign_specs}
    assert kinds == {"pass_high", "pass_low", "brief", "outside"}
    durations = [spec.script.duration for spec, _ in default_campaign_specs]
    assert len(durations) == 31 and 1200 <= min(durations) and max(durations) <= 3600
    seen = set()
    for spec, seed in default_campaign_specs[:4]:
        ev = simulate_event(spec, cfg, seed)
        seen |= set(np.unique(ev.regime).tolist())
    assert seen == {1, 2, 3, 4}


def test_dominant_acceleration_frequency_is_modal(event1):
    spec, ev = event1
    f, p = welch(ev.acc.astype(float), fs=50.0, nperseg=2**14, axis=0)
    f_peak = f[np.argmax(p.mean(axis=1))]
    df = f[1] - f[0]
    assert abs(f_peak - StructureConfig().frequency) <= df, f"peak at {f_peak:.4f} Hz, mode at 0.327 Hz (bin {df:.4f} Hz)"


def test_acceleration_matches_displacement_and_mode_shape(event1):
    spec, ev = event1
    phi = np.array(StructureConfig().mode_shape)
    # noise-free acceleration is phi_k q'' and q'' ~ -w^2 q at the mode
    w = StructureConfig().omega
    big = np.abs(ev.q) > 0.05
    assert_close(ev.acc_true[big, 1] / (-(w**2) * ev.q[big]), 1.0, rtol=0.05,
                 reason="aerodynamic terms shift q'' from -w^2 q by a few per cent")
    assert_close(ev.acc_true[:, 0], phi[0] * ev.acc_true[:, 1], rtol=1e-12)
    # measured = true + noise floor + 16-bit quantisation
    lsb = 2 * 9.80665 / 2**16
    noise = ev.acc - ev.acc_true
    sigma = 30e-6 * 9.80665 * np.sqrt(25.0)
    assert_close(noise.std(), np.hypot(sigma, lsb / np.sqrt(12)), rtol=0.05,
                 reason="sample std of ~1e5 noise samples")


def test_anemometer_resolution_and_turbulence_intensity(event1):
    spec, ev = event1
    for comp in (ev.u, ev.v, ev.w):
        assert comp.dtype == np.float32
        steps = np.round(comp.astype(float) / 0.01)
        assert_close(comp, (steps * 0.01).astype(np.float32), rtol=0)
    w_std = float(ev.w.std())
    U_mean = float(ev.U.mean())
    # sigma_w = 0.5 * 0.08 * V: about 0.04 U (the direction is within 15 deg of perpendicular)
    assert 0.025 * U_mean < w_std < 0.06 * U_mean, f"sigma_w {w_std:.3f} m/s for U {U_mean:.2f} m/s"


def test_same_seed_same_bytes_different_seed_different(tmp_path):
    small = CampaignConfig(n_events=2, seed=4, duration=(150.0, 150.0))
    a = generate_campaign(small, tmp_path / "a", workers=1)
    b = generate_campaign(small, tmp_path / "b", workers=2)
    c = generate_campaign(CampaignConfig(n_events=2, seed=5, duration=(150.0, 150.0)), tmp_path / "c", workers=1)
    for fa, fb, fc in zip(a.files, b.files, c.files):
        assert fa.read_bytes() == fb.read_bytes(), f"{fa.name}: differs between 1 and 2 workers"
        assert fa.read_bytes() != fc.read_bytes(), f"{fa.name}: identical for different seeds"
    assert a.catalogue.read_bytes() == b.catalogue.read_bytes()


def test_written_files_read_back_identically(small_campaign):
    from vivbench.synth import campaign_specs, generate_event

    specs = campaign_specs(CampaignConfig(n_events=4, seed=11, duration=(360.0, 540.0)))
    spec, seed = specs[2]
    tree = generate_event(spec, CampaignConfig().generator, seed, campaign_seed=11)
    back = read_event(small_campaign.files[2])
    for group in ("wind", "accel", "truth"):
        assert back[group].ds.identical(tree[group].ds), f"/{group} differs after the round trip"
    assert dict(back.attrs) == dict(tree.attrs)
    meta = json.loads(back["truth"].attrs["config_json"])
    assert config_from_dict(meta["generator"]) == CampaignConfig().generator
    assert meta["event"]["event_id"] == spec.event_id


def test_catalogue_lists_every_event(small_campaign):
    text = small_campaign.catalogue.read_text().splitlines()
    assert text[0].startswith("event_id,file,start_time,scenario")
    assert [line.split(",")[0] for line in text[1:]] == ["E001", "E002", "E003", "E004"]


def test_defects_off_by_default_and_on_when_asked(event1):
    spec, ev = event1
    assert not np.isnan(ev.acc).any() and not np.isnan(ev.u).any()
    cfg = GeneratorConfig(sensors=SensorConfig(defects=DefectConfig(dropouts_per_hour=30.0, spikes_per_hour=30.0)))
    short = EventSpec(event_id="D", start_time="2026-01-01T00:00:00Z", kind="test", script=_pass_script(1800.0, 8.5))
    clean = simulate_event(short, GeneratorConfig(), 9)
    bad = simulate_event(short, cfg, 9)
    assert np.isnan(bad.acc).any() and np.isnan(bad.u).any()
    assert bad.defects["accel_spikes"] > 0
    # defects draw from their own stream: the structure's response is unchanged
    assert_close(bad.q, clean.q, rtol=0)


def test_clock_offset_shifts_acceleration():
    T = 600.0
    spec = EventSpec(event_id="C", start_time="2026-01-01T00:00:00Z", kind="test", script=_pass_script(T, 8.5))
    base = simulate_event(spec, GeneratorConfig(), 2)
    shifted = simulate_event(spec, GeneratorConfig(sensors=SensorConfig(defects=DefectConfig(clock_offset=2.0))), 2)
    # the accelerometer's sample k now shows the motion at true time k/50 + 2 s
    assert_close(shifted.q[: -100], base.q[100:], rtol=1e-9, atol=1e-12,
                 reason="the same RK4 steps; inputs interpolated at the same instants up to rounding of t")


def test_config_validation_messages():
    with pytest.raises(ValueError, match="damping_ratio must be in"):
        StructureConfig(damping_ratio=-0.1)
    with pytest.raises(ValueError, match="mode_shape values must be positive"):
        StructureConfig(mode_shape=(0.7, -1.0, 0.7))
    with pytest.raises(ValueError, match="integration_step"):
        GeneratorConfig(integration_step=1.0)
    with pytest.raises(ValueError, match="unknown configuration keys"):
        config_from_dict({"wnd": {}})
    with pytest.raises(ValueError, match=r"unknown keys \['zeta'\] in \[structure\]"):
        config_from_dict({"structure": {"zeta": 0.01}})


def test_config_toml_round_trip(tmp_path):
    toml = tmp_path / "bridge.toml"
    toml.write_text(
        "integration_step = 0.01\n"
        "[structure]\nfrequency = 0.2\nmode_shape = [0.5, 1.0, 0.5]\n"
        "[aero.Y1]\ncoefficients = [-10.0, 5.0, -0.3]\n"
        "[wind.turbulence]\nintensity = 0.1\n"
    )
    cfg = load_config(toml)
    assert cfg.structure.frequency == 0.2 and cfg.structure.mode_shape == (0.5, 1.0, 0.5)
    assert cfg.aero.Y1.coefficients == (-10.0, 5.0, -0.3)
    assert cfg.wind.turbulence.intensity == 0.1 and cfg.integration_step == 0.01
    assert config_from_dict(config_to_dict(cfg)) == cfg
    bad = tmp_path / "bad.toml"
    bad.write_text("[structure]\nfrequency = -1\n")
    with pytest.raises(ValueError, match=r"bad\.toml: frequency must be in"):
        load_config(bad)


def test_cli_synth_and_bad_config(tmp_path):
    out = tmp_path / "camp"
    run = subprocess.run([sys.executable, "-m", "vivbench.cli", "synth", "--events", "2", "--seed", "1",
                          "--duration", "3", "--out", str(out), "--workers", "1"], capture_output=True, text=True)
    assert run.returncode == 0, run.stderr
    assert sorted(p.name for p in out.iterdir()) == ["E001.nc", "E002.nc", "catalogue.csv"]
    bad = tmp_path / "bad.toml"
    bad.write_text("[structure]\nfrequency = 'fast'\n")
    run = run_cli("synth", "--events", "1", "--config", bad, "--out", tmp_path / "x")  # in this process
    assert run.returncode == 2
    lines = run.stderr.strip().splitlines()
    assert len(lines) == 1 and "bad.toml" in lines[0], run.stderr
    assert not (tmp_path / "x").exists() or not any((tmp_path / "x").glob("*.nc"))
