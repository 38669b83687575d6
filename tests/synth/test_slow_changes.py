"""Slow changes the wind does not carry (docs/concepts.md (no inverse crime)): damping drift, steps between events, retrofit."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest

from tests.helpers import REPO, assert_close, is_close, relative_rms
from vivbench.core.errors import InputError
from vivbench.io.event import EventFormatError, read_event, validate_event
from vivbench.synth import (
    CampaignConfig,
    EventSpec,
    GeneratorConfig,
    StructureConfig,
    TurbulenceConfig,
    WindScript,
    amplitude_coefficients,
    campaign_specs,
    config_from_dict,
    config_to_dict,
    generate_campaign,
    load_config,
    simulate_event,
)
from vivbench.synth.config import ChangesConfig


def _quiet(changes: ChangesConfig = ChangesConfig(), **kw) -> GeneratorConfig:
    """No turbulence, no buffeting, no unlocked shedding: the averaging hypotheses hold.

    The in_library mode (docs/concepts.md (no inverse crime)): these tests check the truth's coefficient matrix under
    the changes (scaled exactly, or absent when the damping drifts), which needs the truth in
    the library.
    """
    return GeneratorConfig.in_library(
        aero=dict(cl_unlocked=0.0, buffeting_w=0.0, buffeting_u=0.0),
        wind=dict(turbulence=TurbulenceConfig(intensity=0.0), speed_wander=0.1, section_wander=0.005),
        changes=changes, **kw,
    )


def _spec(script: WindScript, number: int = 1, campaign_time: float = 0.0) -> EventSpec:
    return EventSpec(event_id="T", start_time="2026-01-01T00:00:00Z", kind="test", script=script,
                     number=number, campaign_time=campaign_time)


def _pass_script(T: float, plateau: float) -> WindScript:
    return WindScript(times=(0.0, 0.1 * T, 0.25 * T, 0.7 * T, 0.85 * T, T),
                      speeds=(4.5, 4.5, plateau, plateau, 4.5, 4.5))


# ------------------------------------------------------------------ configuration


def test_config_validation_messages():
    for kwargs, message in (
        ({"drift_amplitude": 1.0}, "drift_amplitude must be in"),
        ({"drift_period": 60.0}, "drift_period must be >= 600"),
        ({"step_event": 3, "step_mass_factor": 3.0}, "step_mass_factor must be in"),
        ({"step_event": 3, "step_damping_factor": 0.0}, "step_damping_factor must be positive"),
        ({"step_damping_factor": 2.0}, "need step_event >= 1"),
        ({"retrofit_Y1_factor": 0.5}, "need retrofit_event >= 1"),
        ({"retrofit_event": 2, "retrofit_CL_factor": -1.0}, "retrofit_CL_factor must be >= 0"),
        ({"step_event": -1}, "step_event must be an event number"),
        ({"retrofit_event": 1.5}, "retrofit_event must be an event number"),
        ({"drift_phase_deg": float("nan")}, "drift_phase_deg must be a finite number"),
    ):
        with pytest.raises(InputError, match=message):
            ChangesConfig(**kwargs)
    with pytest.raises(InputError, match="changed damping ratio must stay below 0.2"):
        GeneratorConfig(structure=StructureConfig(damping_ratio=0.1),
                        changes=ChangesConfig(step_event=2, step_damping_factor=2.5))
    with pytest.raises(InputError, match="integration_step"):
        GeneratorConfig(integration_step=0.15, changes=ChangesConfig(step_event=2, step_mass_factor=0.5))
    with pytest.raises(InputError, match=r"unknown keys \['zeta_drift'\] in \[changes\]"):
        config_from_dict({"changes": {"zeta_drift": 0.1}})
    assert not ChangesConfig().any and ChangesConfig(drift_amplitude=0.1).any


def test_config_dict_and_toml_round_trip(tmp_path):
    assert "changes" not in config_to_dict(GeneratorConfig()), "no changes: the stored configuration is as before"
    toml = tmp_path / "drift.toml"
    toml.write_text(
        "[changes]\ndrift_amplitude = 0.25\ndrift_period = 43200.0\ndrift_phase_deg = 90.0\n"
        "step_event = 3\nstep_damping_factor = 1.5\nstep_mass_factor = 1.1\n"
        "retrofit_event = 16\nretrofit_Y1_factor = 0.6\nretrofit_CL_factor = 0.8\n"
    )
    cfg = load_config(toml)
    ch = cfg.changes
    assert (ch.drift_amplitude, ch.drift_period, ch.step_event, ch.retrofit_event) == (0.25, 43200.0, 3, 16)
    assert config_from_dict(config_to_dict(cfg)) == cfg
    assert config_to_dict(cfg)["changes"]["retrofit_Y1_factor"] == 0.6
    assert ch.damping_factor(2) == 1.0 and ch.damping_factor(3) == 1.5
    assert ch.mass_factor(2) == 1.0 and ch.mass_factor(30) == 1.1
    assert_close(ch.aero_factors(15), np.ones(4))
    assert_close(ch.aero_factors(16), [0.8, 0.6, 0.6, 0.6])
    bad = tmp_path / "bad.toml"
    bad.write_text("[changes]\ndrift_amplitude = 2.0\n")
    with pytest.raises(InputError, match=r"bad\.toml: drift_amplitude must be in"):
        load_config(bad)


def test_example_drift_configuration_loads():
    
    cfg = load_config(REPO / "examples" / "drift.toml")
    assert cfg.changes.drift_amplitude > 0 and cfg.changes.retrofit_event == 16


# ------------------------------------------------------------------ exactness of the truth


def test_averaged_model_reproduces_envelope_with_drift_step_and_retrofit():
    """Full simulation and averaged truth share zeta(t), m, w1 and the aero factors: envelope within 2 %."""
    changes = ChangesConfig(drift_amplitude=0.5, drift_period=1800.0, drift_phase_deg=30.0,
                            step_event=2, step_damping_factor=1.3, step_mass_factor=1.2,
                            retrofit_event=2, retrofit_Y1_factor=0.9, retrofit_e1_factor=1.2, retrofit_CL_factor=0.9)
    cfg = _quiet(changes)
    T = 1500.0
    spec = _spec(_pass_script(T, 8.8), number=2, campaign_time=5000.0)
    ev = simulate_event(spec, cfg, 7)
    omega = cfg.structure.omega / np.sqrt(1.2)
    Q_full = np.sqrt(ev.q**2 + (ev.qd / omega) ** 2)
    Q_avg = np.interp(ev.accel_time, ev.truth_time, ev.Q)
    keep = (ev.accel_time > 60.0) & (ev.accel_time < T - 60.0)
    err = relative_rms(Q_full[keep], Q_avg[keep])
    assert err < 0.02, f"averaged model misses the simulated envelope by {err:.2%} RMS (limit 2 %)"
    # the truth records the time-varying damping; it changes by tens of per cent within the event
    zeta = cfg.structure.damping_ratio * 1.3 * (1 + 0.5 * np.sin(2 * np.pi * (5000.0 + ev.truth_time) / 1800.0 + np.pi / 6))
    assert_close(ev.damping_ratio, zeta, rtol=1e-12, reason="the same formula evaluated in another order")
    assert ev.damping_ratio.max() / ev.damping_ratio.min() > 2.0
    assert_close(ev.mass_factor, np.full(ev.truth_time.size, 1.2))
    assert_close(ev.aero_factor[0], [0.9, 0.9, 0.9 * 1.2, 0.9])
    assert ev.coef is None, "a damping that drifts within the event has no constant coefficient matrix"
    # the drift is felt by the full simulation: without it the response differs
    still = simulate_event(spec, _quiet(replace(changes, drift_amplitude=0.0)), 7)
    assert relative_rms(still.Q, ev.Q) > 0.01
    assert still.coef is not None


def test_changes_before_the_step_reproduce_the_default_bit_for_bit():
    """The changed code path with neutral parameters gives exactly the default event."""
    script = _pass_script(400.0, 8.8)
    base = simulate_event(_spec(script), GeneratorConfig(), 3)
    cfg = GeneratorConfig(changes=ChangesConfig(step_event=5, step_damping_factor=2.0, retrofit_event=5, retrofit_Y1_factor=0.5))
    ev = simulate_event(_spec(script, number=1, campaign_time=7200.0), cfg, 3)
    for name in ("acc", "q", "Q", "r", "regime", "U", "coef"):
        np.testing.assert_array_equal(getattr(ev, name), getattr(base, name), err_msg=name)
    assert base.damping_ratio is None
    assert np.all(ev.damping_ratio == GeneratorConfig().structure.damping_ratio)


def test_step_between_events_changes_the_truths_damping():
    """Outside lock-in: r1/A = p1 = aero damping - zeta w1; a step of zeta and m moves it by the expected amount."""
    T = 300.0
    script = WindScript(times=(0.0, T), speeds=(4.0, 4.0))
    zeta0, f_d, f_m = 0.003, 2.0, 1.15
    changes = ChangesConfig(step_event=2, step_damping_factor=f_d, step_mass_factor=f_m)
    cfg = _quiet(changes, initial_amplitude=0.1)
    before = simulate_event(_spec(script, number=1, campaign_time=0.0), cfg, 5)
    after = simulate_event(_spec(script, number=2, campaign_time=86400.0), cfg, 5)
    s = cfg.structure
    assert_close(before.damping_ratio, np.full(before.truth_time.size, zeta0))
    assert_close(after.damping_ratio, np.full(after.truth_time.size, f_d * zeta0))
    assert_close(after.mass_factor, np.full(after.truth_time.size, f_m))
    # the truth's linear coefficient r1/A (section by section, as the identification sees it)
    A_b = before.Q[:, None] * np.array(s.mode_shape)
    A_a = after.Q[:, None] * np.array(s.mode_shape)
    c_b = before.r[:, :, 1] / A_b
    c_a = after.r[:, :, 1] / A_a
    aero_b = amplitude_coefficients(before.U, replace(s, damping_ratio=0.0), cfg.aero)[:, 1]
    aero_a = amplitude_coefficients(after.U, replace(s, damping_ratio=0.0), cfg.aero)[:, 1] / f_m
    # phi_k dQ'/dt over A_k = phi_k Q: r1/A is p1 at every section
    assert_close(c_b, np.repeat((aero_b - zeta0 * s.omega)[:, None], 3, axis=1), rtol=1e-12,
                 reason="r1 / A recomputes p1 Q / Q")
    expected_a = aero_a - f_d * zeta0 * s.omega / np.sqrt(f_m)
    assert_close(c_a, np.repeat(expected_a[:, None], 3, axis=1), rtol=1e-9, atol=1e-15,
                 reason="the aero part is divided by the mass factor after the amplitude coefficients are summed")
    # same seed: the same wind, so the change of r1/A is the change of the damping and of the mass
    assert_close(before.U, after.U)
    shift = np.mean(c_a - c_b)
    assert shift < -0.5 * zeta0 * s.omega, f"r1/A moved by {shift:.4g} 1/s; the step more than doubles the decay"
    # the full simulation's decay rate (log-envelope slope over its first 60 s) changes as the truth's does
    def slope(t, Q):
        keep = (t > 5.0) & (t < 65.0)
        return np.polyfit(t[keep], np.log(Q[keep]), 1)[0]
    measured = (slope(after.accel_time, np.sqrt(after.q**2 + (after.qd * np.sqrt(f_m) / s.omega) ** 2))
                - slope(before.accel_time, np.sqrt(before.q**2 + (before.qd / s.omega) ** 2)))
    truth = slope(after.truth_time, after.Q) - slope(before.truth_time, before.Q)
    assert abs(measured / truth - 1) < 0.02, f"decay rate changed by {measured:.4g} 1/s, the truth's by {truth:.4g}"
    linear = float(np.mean(expected_a - (aero_b - zeta0 * s.omega)))
    assert abs(truth / linear - 1) < 0.3, f"the truth's decay rate changed by {truth:.4g} 1/s, its linear part by {linear:.4g}"
    # a step of constant parameters keeps an exact coefficient matrix, with the new damping on its diagonal
    assert after.coef is not None and not is_close(after.coef, before.coef)


# ------------------------------------------------------------------ files and campaigns


def test_default_event_file_has_no_change_variables(short_event):
    truth = short_event["truth"].ds
    assert not {"damping_ratio", "mass_factor", "aero_factor"} & set(truth.data_vars)
    meta = json.loads(truth.attrs["config_json"])
    assert "changes" not in meta["generator"] and "number" not in meta["event"] and "campaign_time" not in meta["event"]


def test_campaign_with_changes_same_bytes_for_1_and_2_workers(tmp_path):
    gen = GeneratorConfig(changes=ChangesConfig(drift_amplitude=0.3, step_event=2, step_damping_factor=1.5,
                                                retrofit_event=2, retrofit_Y1_factor=0.7))
    camp = CampaignConfig(n_events=2, seed=4, duration=(150.0, 150.0), generator=gen)
    a = generate_campaign(camp, tmp_path / "a", workers=1)
    b = generate_campaign(camp, tmp_path / "b", workers=2)
    assert not a.failures and len(a.files) == 2
    for fa, fb in zip(a.files, b.files):
        assert fa.read_bytes() == fb.read_bytes(), f"{fa.name}: differs between 1 and 2 workers"
    assert a.catalogue.read_bytes() == b.catalogue.read_bytes()
    header = a.catalogue.read_text().splitlines()[0].split(",")
    assert {"damping_ratio_min", "damping_ratio_max", "mass_factor", "aero_factor_r1"} <= set(header)
    specs = campaign_specs(camp)
    trees = [read_event(f) for f in a.files]
    for (spec, _), tree in zip(specs, trees):
        truth = tree["truth"].ds
        t_c = spec.campaign_time + truth["time"].values
        zeta = 0.003 * (1.5 if spec.number >= 2 else 1.0) * (1 + 0.3 * np.sin(2 * np.pi * t_c / 86400.0))
        assert_close(truth["damping_ratio"].values, zeta, rtol=1e-12, reason="the same formula evaluated in another order")
        assert truth["damping_ratio"].attrs["units"] == "1" and truth["aero_factor"].dims == ("time", "order")
        meta = json.loads(truth.attrs["config_json"])
        assert meta["event"]["number"] == spec.number and config_from_dict(meta["generator"]) == gen
    assert_close(trees[1]["truth"]["aero_factor"].values[0], [1.0, 0.7, 0.7, 0.7])
    # the file format refuses broken change variables
    bad = trees[0].copy()
    bad["truth"]["damping_ratio"].attrs["units"] = "s"
    with pytest.raises(EventFormatError, match="damping_ratio has units"):
        validate_event(bad)
    partial = trees[0].copy()
    partial["truth"] = partial["truth"].to_dataset().drop_vars("mass_factor")
    with pytest.raises(EventFormatError, match="slow changes need all of"):
        validate_event(partial)
