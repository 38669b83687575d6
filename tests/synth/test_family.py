"""The generator family (held-out split), the new yaw shapes and bell, and the smooth felt wind."""

from __future__ import annotations

import dataclasses
import json
from collections import Counter

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tests.helpers import assert_close
from vivbench.core.errors import InputError
from vivbench.synth import (AsymmetricBell, GeneratorConfig, StructureConfig, WindConfig, WindScript, YawFactor,
                            config_from_dict, config_to_dict, curve_from_data, mean_wind)
from vivbench.synth.event import EventSpec, simulate_event
from vivbench.synth.family import FAMILY_FILE, SPLITS, draw_bridge, family_seed, generate_family_campaign
from vivbench.synth.wind import measure_wind, wind_field

N_DRAWS = 200


@pytest.fixture(scope="module")
def draws():
    return {split: [draw_bridge(split, i) for i in range(N_DRAWS)] for split in SPLITS}


# ------------------------------------------------------------------------------------------ the family


def test_same_split_and_index_give_the_same_draw(draws):
    for split in SPLITS:
        again = draw_bridge(split, 7)
        assert again == draws[split][7]
        assert json.dumps(again.to_dict(), sort_keys=True) == json.dumps(draws[split][7].to_dict(), sort_keys=True)
    assert draws["development"][7] != draws["development"][8]


def test_the_splits_never_overlap(draws):
    dev = {d.campaign_seed for d in draws["development"]}
    ev = {d.campaign_seed for d in draws["evaluation"]}
    assert max(dev) < 2**62 <= min(ev), "the split code lives in the campaign seed's top bits"
    assert len(dev) == len(ev) == N_DRAWS
    dev_cfg = {json.dumps(config_to_dict(d.config), sort_keys=True) for d in draws["development"]}
    assert not dev_cfg & {json.dumps(config_to_dict(d.config), sort_keys=True) for d in draws["evaluation"]}
    dev, ev = family_seed("development", 3), family_seed("evaluation", 3)
    assert dev.generate_state(4).tolist() != ev.generate_state(4).tolist()


@settings(max_examples=60, deadline=None, derandomize=True)
@given(split=st.sampled_from(SPLITS), index=st.integers(0, 2**31 - 1))
def test_any_draw_is_valid_and_carries_its_split(split, index):
    d = draw_bridge(split, index)
    assert d.campaign_seed >> 62 == SPLITS.index(split)
    lo, hi = d.config.lock_in
    assert 3.0 <= lo < hi <= 25.0 and 3 <= d.n_events <= 60
    assert d.labels["n_sections"] == d.config.structure.n_sections
    assert (d.config.aero.yaw is None) == (d.labels["yaw_effect"] == "absent")
    assert d.config.wind.felt_wind == d.labels["eiv"]


@pytest.mark.parametrize("split, index", [("validation", 0), ("development", -1), ("evaluation", 1.5),
                                          ("development", True)])
def test_bad_split_or_index_is_refused(split, index):
    with pytest.raises(InputError, match="split|index"):
        draw_bridge(split, index)


def test_every_draw_is_a_valid_bridge_with_a_reachable_lock_in(draws):
    for d in draws["development"] + draws["evaluation"]:
        cfg = d.config
        assert config_from_dict(config_to_dict(cfg)) == cfg
        lock = cfg.lock_in
        assert lock is not None and 3.0 <= lock[0] < lock[1] <= 25.0
        assert 3 <= d.n_events <= 60 and 600.0 <= d.duration[0] <= d.duration[1] <= 5400.0
        s = cfg.structure
        U = np.arange(0.5, 40.0, 0.01)
        neg = np.max(s.air_density * U * s.depth * cfg.aero.Y1.at_wind(U, s.frequency, s.depth) / (2 * s.mass))
        zeta_w = s.damping_ratio * s.omega * min(1.0, cfg.changes.step_damping_factor)
        if d.labels["forced_only"]:
            assert neg < zeta_w, "forced-only: the aerodynamic negative damping stays below the structural damping"
        else:
            assert neg > 1.2 * s.damping_ratio * s.omega


def test_the_wind_scripts_pass_through_each_drawn_lock_in(draws):
    from vivbench.synth import campaign_specs

    for d in draws["development"][:60]:
        lo, hi = d.config.lock_in
        for spec, _seed in campaign_specs(d.campaign_config()):
            speeds = np.array(spec.script.speeds)
            if spec.kind == "outside":
                assert np.all((speeds < lo) | (speeds > hi)), (d.index, speeds, (lo, hi))
            else:  # the plateau or peak (third knot) in lock-in, the ends outside it
                assert lo < speeds[2] < hi, (d.index, spec.kind, speeds, (lo, hi))
                assert not lo < speeds[0] < hi and not lo < speeds[-1] < hi, (d.index, spec.kind, speeds, (lo, hi))


def test_the_priors_cover_every_variant(draws):
    seen = Counter()
    labels = [d.labels for d in draws["development"]]
    for lab in labels:
        for key in ("bell", "e_mix", "yaw_effect", "eiv", "forced_only", "change", "yaw_course", "n_sections"):
            seen[(key, lab[key])] += 1
    expected = {("bell", b) for b in ("gaussian", "lorentzian", "asymmetric")} \
        | {("e_mix", m) for m in ("both", "e1_only", "e2_only")} \
        | {("yaw_effect", y) for y in ("absent", "cosine", "gaussian", "sin2", "logistic")} \
        | {("eiv", e) for e in ("tributary", "smooth")} | {("forced_only", f) for f in (True, False)} \
        | {("change", c) for c in ("none", "damping_step")} | {("yaw_course", c) for c in ("shared", "per_event")} \
        | {("n_sections", n) for n in range(1, 7)}
    assert expected <= set(seen), sorted(expected - set(seen))
    freq = [lab["frequency_hz"] for lab in labels]
    assert min(freq) < 0.15 and max(freq) > 0.7
    n_events = [lab["n_events"] for lab in labels]
    assert min(n_events) <= 4 and max(n_events) >= 40
    assert np.median(n_events) < 20, "log-uniform sizes favour small campaigns"
    smooth = [lab for lab in labels if lab["eiv"] == "smooth"]
    assert all(0.05 <= lab["point_intensity"] <= 0.12 and 5.0 <= lab["point_timescale_s"] <= 60.0 for lab in smooth)
    steps = [d.config.changes.step_damping_factor for d in draws["development"] if d.labels["change"] == "damping_step"]
    assert all(0.3 <= abs(f - 1.0) <= 0.6 for f in steps) and min(steps) < 1 < max(steps)
    for d in draws["development"]:
        if d.labels["e_mix"] == "e1_only":
            assert d.config.aero.e2(np.linspace(1, 12, 5)).max() == 0.0


def test_capped_campaign_config_records_the_caps():
    d = draw_bridge("development", 0)
    full = d.campaign_config()
    assert (full.n_events, full.duration, full.seed) == (d.n_events, d.duration, d.campaign_seed)
    capped = d.campaign_config(max_events=2, max_duration=600.0)
    assert capped.n_events == min(2, d.n_events) and capped.duration == (600.0, 600.0)


def test_a_small_draw_end_to_end_is_reproducible(tmp_path):
    from vivbench.cli import main
    from vivbench.io.event import read_event

    result, path = generate_family_campaign("development", 1, tmp_path / "a", max_events=2, max_duration=600.0)
    assert not result.failures and len(result.files) == 2
    data = json.loads(path.read_text())
    assert path.name == FAMILY_FILE and data["split"] == "development" and data["index"] == 1
    assert data["caps"]["max_events"] == 2 and data["caps"]["n_events_generated"] == 2
    assert config_from_dict(data["generator"]) == draw_bridge("development", 1).config
    tree = read_event(result.files[0])
    truth = tree["truth"].ds
    assert np.all(np.isfinite(truth["A"].values)) and truth["A"].shape[1] == data["labels"]["n_sections"]
    assert main(["synth", "--family", "development", "--draw", "1", "--max-events", "2", "--max-duration", "10",
                 "--workers", "1", "--out", str(tmp_path / "b")]) == 0
    for name in ("E001.nc", "E002.nc", "catalogue.csv", FAMILY_FILE):
        assert (tmp_path / "a" / name).read_bytes() == (tmp_path / "b" / name).read_bytes(), name


def test_family_options_are_checked_on_the_command_line(tmp_path, capsys):
    from vivbench.cli import main

    assert main(["synth", "--family", "development", "--out", str(tmp_path)]) == 2
    assert "--draw" in capsys.readouterr().err
    assert main(["synth", "--family", "evaluation", "--draw", "0", "--seed", "3", "--out", str(tmp_path)]) == 2
    assert "--seed" in capsys.readouterr().err
    assert main(["synth", "--draw", "0", "--out", str(tmp_path)]) == 2


# ---------------------------------------------------------------------------- the new shapes


def test_new_yaw_shapes():
    psi = np.linspace(-80.0, 80.0, 161)
    sin2 = YawFactor(shape="sin2", strength=0.7)
    assert_close(sin2(psi), 1.0 - 0.7 * np.sin(np.radians(psi)) ** 2, what="1 - c sin^2")
    assert_close(sin2(90.0), 0.3, rtol=1e-12, reason="floating point sin(pi/2)")
    cut = YawFactor(shape="logistic", cutoff_deg=15.0, width_deg=3.0)
    f = cut(psi)
    assert f[80] == 1.0 and np.all(f <= 1.0) and np.all(f >= 0.0)
    assert np.all(np.diff(f[80:]) <= 0) and f[80 + 30] < 0.01
    assert_close(cut(15.0), (1 + np.exp(-5.0)) / 2, what="half way at the cut-off")
    assert_close(cut(psi), cut(-psi), what="even in the yaw")
    for shape in ("cosine", "gaussian", "sin2", "logistic"):
        factor = YawFactor(shape=shape)
        assert factor(0.0) == 1.0 and 0.0 <= factor(40.0) < 1.0


@pytest.mark.parametrize("kwargs, match", [(dict(shape="linear"), "shape"),
                                           (dict(shape="sin2", strength=1.5), "strength"),
                                           (dict(shape="logistic", cutoff_deg=0.0), "cutoff_deg"),
                                           (dict(width_deg=float("nan")), "width_deg")])
def test_bad_yaw_factor_is_refused(kwargs, match):
    with pytest.raises(InputError, match=match):
        YawFactor(**kwargs)


def test_new_options_save_only_when_used():
    default = config_to_dict(GeneratorConfig())
    assert "strength" not in default["aero"]["yaw"] and "point_intensity" not in default["wind"]
    cfg = GeneratorConfig(aero={"yaw": {"shape": "logistic", "cutoff_deg": 12.0, "width_deg": 3.0}},
                          wind=WindConfig(felt_wind="smooth", point_intensity=0.1, shared_yaw_deg=4.0))
    saved = config_to_dict(cfg)
    assert saved["aero"]["yaw"]["cutoff_deg"] == 12.0 and saved["wind"]["shared_yaw_deg"] == 4.0
    assert config_from_dict(json.loads(json.dumps(saved))) == cfg


def test_asymmetric_bell():
    bell = AsymmetricBell(peak=10.0, center=7.0, width_low=2.0, width_high=0.5, baseline=-2.0)
    assert bell(7.0) == 10.0
    assert_close(bell(5.0), -2.0 + 12.0 * np.exp(-0.5), what="one width below")
    assert_close(bell(7.5), -2.0 + 12.0 * np.exp(-0.5), what="one width above")
    assert curve_from_data({"kind": "asymmetric", "peak": 10.0, "center": 7.0, "width_low": 2.0, "width_high": 0.5,
                            "baseline": -2.0}) == bell
    with pytest.raises(InputError, match="width_low"):
        AsymmetricBell(peak=1.0, center=7.0, width_low=0.0, width_high=1.0)


# ------------------------------------------------------------------- wind: smooth mode, shared course


def _smooth_anemometer_turbulence(timescale: float, seed: int):
    S = 6
    structure = StructureConfig(mode_shape=(1.0,) * S, tributary_lengths=(200.0,) * S)
    wind = WindConfig(felt_wind="smooth", point_intensity=0.08, point_timescale=timescale, noise=0.0, resolution=0.0)
    t = np.arange(3600 * 32) / 32.0
    rng = np.random.default_rng(seed)
    mw = mean_wind(WindScript(times=(0.0, 3600.0), speeds=(8.0, 9.0)), t, wind, rng, S)
    u, v, _w = measure_wind(mw, wind_field(mw, structure, wind, rng).anemometer, wind, rng)
    d = np.radians(mw.direction)[:, None]
    along = u * -np.sin(d) + v * -np.cos(d)  # the measured speed along the mean wind
    return (along - mw.V) / mw.V


def test_smooth_mode_anemometers_see_the_stated_point_turbulence():
    x = _smooth_anemometer_turbulence(20.0, seed=1)
    # 6 independent hour-long records of a 20 s process: about 540 independent samples, so the rms
    # scatters by about 3 %; 8 % is more than two and a half standard errors.
    assert_close(np.sqrt(np.mean(x**2)), 0.08, rtol=0.08, reason="rms of 540 independent samples")
    lag = 10 * 32
    rho = np.mean(x[:-lag] * x[lag:]) / np.mean(x**2)
    # the lag-10 s autocorrelation of an exponential process is exp(-10 / 20); its estimate from
    # 540 independent samples scatters by about 5 % of the time scale.
    assert_close(-10.0 / np.log(rho), 20.0, rtol=0.15, reason="integral time scale from one lag, finite record")


def test_smooth_mode_truth_does_not_see_the_anemometers_turbulence():
    spec = EventSpec(event_id="E001", start_time="2026-01-01T00:00:00Z", kind="pass_high",
                     script=WindScript(times=(0.0, 100.0, 200.0, 300.0), speeds=(6.0, 8.5, 8.5, 6.0)))

    def run(**wind):
        return simulate_event(spec, GeneratorConfig(wind=WindConfig(felt_wind="smooth", **wind)), 5)

    a, b = run(point_intensity=0.05, point_timescale=5.0), run(point_intensity=0.12, point_timescale=60.0)
    for name in ("U", "Q", "r", "acc", "q"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name), err_msg=name)
    assert not np.array_equal(a.u, b.u)
    # the deck feels the smooth scripted wind: the U of a deck in a wind without turbulence
    from vivbench.synth import TurbulenceConfig

    calm = simulate_event(spec, GeneratorConfig(wind=WindConfig(felt_wind="anemometer",
                                                                turbulence=TurbulenceConfig(intensity=0.0))), 5)
    assert_close(a.U, calm.U, rtol=1e-12, reason="the slow wind vector recomposed in floating point")
    felt = simulate_event(spec, GeneratorConfig(wind=WindConfig(felt_wind="anemometer")), 5)
    assert np.max(np.abs(felt.U - calm.U)) > 0.05


def test_bad_smooth_mode_options_are_refused():
    with pytest.raises(InputError, match="point_intensity"):
        WindConfig(felt_wind="smooth", point_intensity=0.7)
    with pytest.raises(InputError, match="point_timescale"):
        WindConfig(point_timescale=0.1)
    with pytest.raises(InputError, match="shared_yaw_deg"):
        WindConfig(shared_yaw_deg=50.0)
    with pytest.raises(InputError, match="felt_wind"):
        WindConfig(felt_wind="calm")


def test_shared_yaw_course_is_the_same_in_every_event():
    wind = WindConfig(shared_yaw_deg=5.0, yaw_swing_deg=6.0, yaw_swing_period=900.0, direction_wander_deg=0.0)
    t = np.arange(0.0, 1800.0, 1.0)
    yaws = [mean_wind(WindScript(times=(0.0, 1800.0), speeds=(7.0, 9.0), yaw_deg=y), t, wind,
                      np.random.default_rng(k)).yaw[:, 0] for k, y in enumerate((-10.0, 3.0))]
    np.testing.assert_array_equal(yaws[0], yaws[1])
    assert_close(yaws[0], np.abs(5.0 + 6.0 * np.sin(2 * np.pi * t / 900.0)), rtol=1e-12, reason="float rounding")
    scaled = dataclasses.replace(WindConfig(direction_wander_deg=0.0), event_yaw_scale=2.5)
    y = mean_wind(WindScript(times=(0.0, 600.0), speeds=(8.0, 8.0), yaw_deg=-8.0), t[:600], scaled,
                  np.random.default_rng(0)).yaw
    assert_close(y, 20.0, rtol=1e-12, reason="float rounding")
