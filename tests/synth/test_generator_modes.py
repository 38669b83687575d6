"""The named generator modes (docs/concepts.md (no inverse crime)), the second realistic bridge, the forced-only bridge,
and the realism factors of `vivbench compare` and `vivbench sweep`."""

from __future__ import annotations

import json

import numpy as np
import pytest

from vivbench.cli import main
from vivbench.io.event import read_event
from vivbench.synth import (
    AeroConfig,
    CampaignConfig,
    ChangesConfig,
    GeneratorConfig,
    WindConfig,
    campaign_specs,
    config_from_dict,
    config_to_dict,
    draw_script,
    load_config,
    simulate_event,
)
from vivbench.synth.campaign import script_lock_in
from vivbench.synth.config import DEFAULT_LOCK_IN
from vivbench.validate import CompareConfig, compare_cells, compare_config_from_dict, plan, run_comparison
from vivbench.validate import sweep_config_from_dict, sweep_tasks
from vivbench.validate.compare import _campaign_config
from tests.helpers import REPO, assert_close


# ---------------------------------------------------------------- the modes


def test_named_modes_and_their_overrides():
    # the default is the realistic mode (docs/concepts.md (no inverse crime)), its fields their classes' defaults
    assert GeneratorConfig.realistic() == GeneratorConfig() == CampaignConfig().generator
    assert GeneratorConfig() == GeneratorConfig(aero=AeroConfig(), wind=WindConfig())
    lib = GeneratorConfig.in_library()
    assert lib.aero == AeroConfig.in_library() and lib.wind == WindConfig(felt_wind="anemometer")
    real = GeneratorConfig.realistic()
    assert real.aero == AeroConfig.realistic() and real.wind == WindConfig(felt_wind="tributary")
    assert not real.changes.any, "slow changes are a separate option, off in both modes"
    assert (lib.mode, real.mode, GeneratorConfig().mode) == ("in_library", "realistic", "realistic")
    # dicts override the mode's values key by key, instances replace them
    assert GeneratorConfig.realistic(wind={"points_per_section": 3}).wind == WindConfig(felt_wind="tributary",
                                                                                         points_per_section=3)
    assert GeneratorConfig.realistic(wind=WindConfig(felt_wind="anemometer")).mode == "mixed"
    assert GeneratorConfig.in_library(wind=WindConfig()).mode == "mixed"
    assert GeneratorConfig.in_library(wind={"points_per_section": 3}).wind.felt_wind == "anemometer"
    assert GeneratorConfig.realistic(aero={"mode": "in_library"}).mode == "mixed"
    assert GeneratorConfig.realistic(changes=ChangesConfig(drift_amplitude=0.2)).mode == "realistic"
    with pytest.raises(ValueError, match="mode must be one of"):
        GeneratorConfig.from_mode("field")


def test_toml_mode_key_explicit_keys_win_and_mode_is_recovered(tmp_path):
    path = tmp_path / "g.toml"
    path.write_text('mode = "realistic"\n[wind]\npoints_per_section = 3\n[aero.Y1]\nkind = "gaussian"\n'
                    'peak = 15.0\ncenter = 7.0\nwidth = 1.1\nbaseline = -4.0\n')
    cfg = load_config(path)
    assert cfg.wind.felt_wind == "tributary" and cfg.wind.points_per_section == 3
    assert cfg.aero.Y1.peak == 15.0 and cfg.aero.e1 == AeroConfig.realistic().e1 and cfg.aero.yaw is not None
    assert load_config(path, mode="in_library").wind.felt_wind == "anemometer"
    # the saved JSON has no mode key: the mode is implied by the saved functions and wind
    back = config_from_dict(json.loads(json.dumps(config_to_dict(cfg))))
    assert back == cfg and back.mode == "realistic"
    assert "mode" not in config_to_dict(GeneratorConfig.realistic())
    # a file without `mode` starts from the realistic default
    path.write_text('[wind]\npoints_per_section = 3\n')
    assert load_config(path) == GeneratorConfig.realistic(wind={"points_per_section": 3})
    path.write_text('mode = "fancy"\n')
    with pytest.raises(ValueError, match=r"g\.toml: mode must be one of \['in_library', 'realistic'\]"):
        load_config(path)


@pytest.mark.parametrize("mode", [None, "realistic", "in_library"])
def test_cli_synth_mode_records_the_mode(tmp_path, mode):
    out = tmp_path / "c"
    argv = ["synth", "--events", "1", "--duration", "3", "--workers", "1", "--out", str(out)]
    assert main(argv + ([] if mode is None else ["--mode", mode])) == 0
    tree = read_event(out / "E001.nc")
    saved = config_from_dict(json.loads(tree["truth"].attrs["config_json"])["generator"])
    # without --mode: the realistic default; --mode in_library: the campaign generated before the default changed
    want = GeneratorConfig.from_mode(mode or "realistic")
    assert saved == want and saved.mode == (mode or "realistic")


def test_realistic_campaign_visits_all_four_regimes():
    campaign = CampaignConfig(n_events=8, duration=(1200.0, 1800.0), generator=GeneratorConfig.realistic())
    seen = set()
    for spec, seed in campaign_specs(campaign):
        seen |= set(np.unique(simulate_event(spec, campaign.generator, seed).regime).tolist())
    assert seen == {1, 2, 3, 4}


# ------------------------------------------------------- other bridges


def test_default_and_realistic_scripts_are_unchanged():
    assert_close(GeneratorConfig.in_library().lock_in, DEFAULT_LOCK_IN)
    assert script_lock_in(GeneratorConfig.in_library()) is None and script_lock_in(GeneratorConfig()) is None
    specs = campaign_specs(CampaignConfig(n_events=8, duration=(1200.0, 1200.0)))
    plateaus = [spec.script.speeds[2] for spec, _ in specs if spec.kind == "pass_high"]
    assert all(8.4 <= p <= 9.4 for p in plateaus)


def test_scripts_follow_another_bridges_lock_in():
    rng = lambda: np.random.default_rng(3)  # noqa: E731
    plain = draw_script("pass_high", 1200.0, rng())
    moved = draw_script("pass_high", 1200.0, rng(), lock_in=(7.0, 12.0))
    assert_close(np.array(moved.speeds) - np.array(plain.speeds), 1.5)
    assert moved.times == plain.times
    with pytest.raises(ValueError, match="lock_in must be"):
        draw_script("pass_low", 1200.0, rng(), lock_in=(9.0, 8.0))


def test_bridge_b_is_another_realistic_bridge_whose_campaign_reaches_regimes_2_to_4():
    cfg = load_config(REPO / "examples" / "bridge_b_realistic.toml")
    default = GeneratorConfig()
    assert cfg.mode == "realistic" and cfg.structure.n_sections == 4
    for name in ("frequency", "depth", "mass", "mode_shape"):
        assert getattr(cfg.structure, name) != getattr(default.structure, name), name
    lo, hi = cfg.lock_in
    assert script_lock_in(cfg) == (lo, hi) and lo > DEFAULT_LOCK_IN[0] + 0.5
    specs = campaign_specs(CampaignConfig(n_events=4, seed=7, duration=(1200.0, 1200.0), generator=cfg))
    high = [spec.script.speeds[2] for spec, _ in specs if spec.kind == "pass_high"]
    assert high and all(lo < u < hi for u in high), "the plateaus lie in this bridge's lock-in"
    spec, seed = specs[0]
    seen = set(np.unique(simulate_event(spec, cfg, seed).regime).tolist())
    assert {2, 3, 4} <= seen


def test_forced_only_bridge_is_regime_1_everywhere():
    cfg = load_config(REPO / "examples" / "forced_only.toml")
    assert cfg.lock_in is None and cfg.mode == "realistic"
    U = np.linspace(0.5, 40.0, 2000)
    f, D = cfg.structure.frequency, cfg.structure.depth
    assert np.all(cfg.aero.Y1.at_wind(U, f, D) <= 0) and np.all(cfg.aero.C_L.at_wind(U, f, D) > 0)
    campaign = CampaignConfig(n_events=4, duration=(600.0, 600.0), generator=cfg)
    peak = 0.0
    for spec, seed in campaign_specs(campaign):
        ev = simulate_event(spec, cfg, seed)
        assert np.all(ev.regime == 1), spec.event_id
        peak = max(peak, float(ev.Q.max()))
    assert peak > 2 * cfg.initial_amplitude, "the locked shedding force must still drive a visible response"


# --------------------------------------------------- compare and sweep


def test_compare_realism_factors_make_their_own_campaigns():
    cfg = CompareConfig(grid={"aero": ["in_library", "realistic"], "felt_wind": ["tributary"], "drift": [0.3]},
                        duration=(600.0, 600.0))
    cells = compare_cells(cfg)
    assert [c["varied"] for c in cells] == ["base", "aero", "felt_wind", "drift"]
    assert plan(cfg) == (4, 4)
    gens = {c["varied"]: _campaign_config(cfg, tuple(c[k] for k in ("accel_noise", "anemometer_noise",
                                                                      "turbulence_intensity", "aero", "felt_wind",
                                                                      "drift"))).generator for c in cells}
    assert gens["base"] == GeneratorConfig.in_library(), "compare's base cell is the in_library generator's"
    assert gens["aero"].aero == AeroConfig.realistic() and gens["aero"].wind.felt_wind == "anemometer"
    assert gens["felt_wind"].wind.felt_wind == "tributary" and gens["felt_wind"].mode == "mixed"
    assert gens["drift"].changes.drift_amplitude == 0.3


@pytest.mark.parametrize("grid, message", [
    ({"aero": ["in_library", "fancy"]}, "aero level 'fancy' is not one of"),
    ({"felt_wind": ["mast"]}, "felt_wind level 'mast' is not one of"),
    ({"drift": [1.5]}, "drift must be in [0, 1)"),
])
def test_compare_realism_levels_are_checked(grid, message):
    with pytest.raises(ValueError) as info:
        compare_config_from_dict({"grid": grid})
    assert message in str(info.value)


def test_two_cell_comparison_over_a_realism_factor_runs(tmp_path):
    cfg = compare_config_from_dict({"campaign": {"events": 2, "duration": [600.0, 600.0], "seed": 1},
                                    "base": {"window": 40.0}, "grid": {"felt_wind": ["anemometer", "tributary"]}})
    result = run_comparison(cfg, tmp_path / "out", workers=1)
    assert not result.failures, result.failures
    assert [r["felt_wind"] for r in result.rows] == ["anemometer", "tributary"]
    assert all(r["n_scored"] > 0 for r in result.rows)
    assert (tmp_path / "out" / "compare_felt_wind.png").stat().st_size > 0


def test_sweep_realism_parameters_reach_the_generator():
    cfg = sweep_config_from_dict({"duration": [600.0, 600.0], "grid": {"aero_realistic": [0, 1],
                                                                       "felt_wind_tributary": [1],
                                                                       "drift_amplitude": [0.25]}})
    gens = [t.campaign.generator for t in sweep_tasks(cfg)]
    assert [g.mode for g in gens] == ["mixed", "realistic"]
    assert gens[1].aero == AeroConfig.realistic() and all(g.changes.drift_amplitude == 0.25 for g in gens)
    assert [dict(t.params)["aero_realistic"] for t in sweep_tasks(cfg)] == [0.0, 1.0]
    # a base generator already in the mode keeps its own functions
    base = {"mode": "realistic", "aero": {"strouhal": 0.12}}
    (task,) = sweep_tasks(sweep_config_from_dict({"duration": [600.0, 600.0], "generator": base,
                                                  "grid": {"aero_realistic": [1]}}))
    assert task.campaign.generator.aero.strouhal == 0.12


@pytest.mark.parametrize("change, message", [
    ({"grid": {"aero_realistic": [0.5]}}, "aero_realistic must be 0 (in_library polynomials) or 1"),
    ({"grid": {"felt_wind_tributary": [2]}}, "felt_wind_tributary must be 0"),
    ({"ranges": {"aero_realistic": [0, 1]}}, "is a 0/1 switch: give it under [grid]"),
    ({"grid": {"drift_amplitude": [1.0]}}, "drift_amplitude must be in (-1, 1)"),
])
def test_sweep_realism_values_are_checked(change, message):
    with pytest.raises(ValueError) as info:
        sweep_config_from_dict({"duration": [600.0, 600.0], **change})
    assert message in str(info.value)


def test_two_point_sweep_over_a_realism_switch_runs(tmp_path):
    from vivbench.validate import run_sweep

    cfg = sweep_config_from_dict({"seed": 2, "n_events": 1, "duration": [300.0, 300.0], "campaign_model": "pooled",
                                  "grid": {"aero_realistic": [0, 1]}})
    result = run_sweep(cfg, tmp_path / "s", workers=1)
    assert not result.failures, result.failures
    rows = (tmp_path / "s" / "sweep.csv").read_text().splitlines()
    header = rows[0].split(",")
    assert {"aero_realistic", "felt_wind_tributary", "drift_amplitude"} <= set(header)
    assert [r.split(",")[header.index("aero_realistic")] for r in rows[1:]] == ["0", "1"] or \
        [float(r.split(",")[header.index("aero_realistic")]) for r in rows[1:]] == [0.0, 1.0]


def test_realism_grid_example_loads():
    from vivbench.validate import load_compare_config

    cfg = load_compare_config(REPO / "examples" / "compare_realism.toml")
    assert set(cfg.grid) == {"aero", "felt_wind", "drift"} and plan(cfg) == (4, 4)
