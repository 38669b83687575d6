"""The scenario suite: named, versioned, fingerprinted campaign configurations (no generation here)."""

from __future__ import annotations

import dataclasses

import pytest

from vivbench.core.errors import InputError
from vivbench.synth import config_to_dict, load_config
from vivbench.validate import (SCENARIO_FINGERPRINTS, SCENARIOS, Scenario, load_scenario_file, scenario,
                               select_scenarios)


def test_the_suite_has_the_issue_scenarios_in_order():
    assert list(SCENARIOS) == ["in_library", "realistic", "other_bridge", "forced_only", "drift", "high_noise",
                               "dropouts"]
    assert [s.name for s in SCENARIOS.values() if s.in_class] == ["in_library"]


@pytest.mark.parametrize("name", list(SCENARIOS))
def test_every_scenario_matches_its_pinned_fingerprint(name):
    # A scenario whose content (or a generator default it relies on) changes must get a new version and a
    # new entry in SCENARIO_FINGERPRINTS: the same name and version always gives the same campaign.
    s = SCENARIOS[name]
    assert SCENARIO_FINGERPRINTS[(s.name, s.version)] == s.fingerprint()


def test_changing_a_scenario_changes_its_fingerprint_and_the_pin_catches_it():
    s = SCENARIOS["high_noise"]
    changed = dataclasses.replace(s, generator={**s.generator, "sensors": {"noise_density": 301.0}})
    assert changed.fingerprint() != s.fingerprint()
    assert SCENARIO_FINGERPRINTS[(changed.name, changed.version)] != changed.fingerprint()
    # the description is not part of the campaign
    assert dataclasses.replace(s, description="other words").fingerprint() == s.fingerprint()
    assert dataclasses.replace(s, seed=3).fingerprint() != s.fingerprint()


def test_scenarios_are_the_example_bridges():
    for name, example in (("other_bridge", "bridge_b_realistic"), ("forced_only", "forced_only")):
        assert config_to_dict(SCENARIOS[name].generator_config()) == config_to_dict(
            load_config(f"examples/{example}.toml"))
    drift = load_config("examples/drift.toml")
    gen = SCENARIOS["drift"].generator_config()
    assert gen.changes == dataclasses.replace(drift.changes, retrofit_event=5)
    assert SCENARIOS["in_library"].generator_config().mode == "in_library"
    assert SCENARIOS["realistic"].generator_config().mode == "realistic"
    assert SCENARIOS["forced_only"].generator_config().lock_in is None
    assert SCENARIOS["dropouts"].generator_config().sensors.defects.dropouts_per_hour == 6.0
    assert SCENARIOS["high_noise"].generator_config().sensors.noise_density == 300.0


def test_select_scenarios():
    assert [s.name for s in select_scenarios(None)] == list(SCENARIOS)
    assert [s.name for s in select_scenarios("drift, realistic")] == ["drift", "realistic"]
    with pytest.raises(InputError, match="unknown scenario.*nope.*available: in_library"):
        select_scenarios("realistic,nope")
    with pytest.raises(InputError, match="named twice"):
        select_scenarios(["drift", "drift"])
    with pytest.raises(InputError, match="unknown scenario 'x'"):
        scenario("x")


def test_bad_scenarios_are_refused_with_the_reason():
    with pytest.raises(InputError, match="version must be an integer >= 1"):
        Scenario(name="a", version=0, description="d")
    with pytest.raises(InputError, match="name must be lower-case"):
        Scenario(name="A b", version=1, description="d")
    with pytest.raises(InputError, match="scenario a: .*duration"):
        Scenario(name="a", version=1, description="d", duration=(10.0, 10.0))
    with pytest.raises(InputError, match="scenario a: generator: .*unknown"):
        Scenario(name="a", version=1, description="d", generator={"sensors": {"nois": 1}})


def test_scenario_file(tmp_path):
    path = tmp_path / "s.toml"
    path.write_text('[scenario.tiny]\nversion = 2\ndescription = "one short event"\nevents = 1\n'
                    'duration = 300.0\nseed = 5\n[scenario.tiny.generator]\nmode = "in_library"\n')
    extra = load_scenario_file(path)
    tiny = extra["tiny"]
    assert (tiny.version, tiny.n_events, tiny.duration, tiny.seed) == (2, 1, (300.0, 300.0), 5)
    assert tiny.generator_config().mode == "in_library"
    assert select_scenarios(None, extra) == [tiny]
    assert [s.name for s in select_scenarios("tiny,realistic", extra)] == ["tiny", "realistic"]
    path.write_text('[scenario.realistic]\nversion = 1\ndescription = "x"\n')
    with pytest.raises(InputError, match="s.toml: .*built-in scenario"):
        load_scenario_file(path)
    path.write_text('[scenario.t]\nversion = 1\ndescription = "x"\nevnts = 2\n')
    with pytest.raises(InputError, match="unknown keys \\['evnts'\\]"):
        load_scenario_file(path)


def test_synth_scenario_refuses_options_it_fixes(tmp_path, capsys):
    from vivbench.cli import main

    assert main(["synth", "--scenario", "drift", "--seed", "3", "--out", str(tmp_path / "c")]) == 2
    assert "--scenario drift fixes the campaign" in capsys.readouterr().err
    assert main(["synth", "--scenario", "nope", "--out", str(tmp_path / "c")]) == 2
    assert "unknown scenario 'nope'" in capsys.readouterr().err
    assert not (tmp_path / "c").exists()
