"""The grey-box as a ``vivbench study`` method: fitted on each draw with its structural properties only."""

from __future__ import annotations

import dataclasses
import json
import math

import pytest

from vivbench.core.errors import InputError
from vivbench.models.greybox import BridgeProperties
from vivbench.synth.family import draw_bridge
from vivbench.validate.greybox_method import STRUCTURAL_FIELDS, GreyBoxMethod, structural_properties
from vivbench.validate.study import STUDY_COLUMNS, StudyConfig, method_spec, run_study, study_method

CAPS = dict(max_events=2, max_duration=600.0)


@pytest.fixture(scope="module")
def greybox_study(tmp_path_factory):
    out = tmp_path_factory.mktemp("study_greybox")
    # greybox listed first: it must still take varying's fitted model as its reference
    config = StudyConfig(split="development", draws=(0,), methods=("greybox", "varying"), **CAPS)
    result = run_study(config, out, workers=1)
    return out, result


def _rows(out):
    lines = (out / "study.csv").read_text().splitlines()
    return [dict(zip(STUDY_COLUMNS, line.split(","))) for line in lines[1:]]


def test_a_tiny_draw_runs_with_the_greybox_and_records_its_scores(greybox_study):
    out, result = greybox_study
    assert result.computed == (0,) and not result.failures
    rows = _rows(out)
    assert [r["method"] for r in rows] == ["greybox", "varying"]  # the configuration's order, not the fit order
    gb = rows[0]
    assert gb["error"] == "" and gb["n_events"] == "2"
    n = int(gb["n_scored"])
    assert n > 0 and 0 <= int(gb["n_flagged"]) <= n and int(gb["self_excited_flags"]) >= 0
    assert 0.0 <= float(gb["coverage"]) <= 1.0 and 0.0 <= float(gb["accuracy_all"]) <= 1.0
    for key in ("rhs_error_true_AU_energy", "rhs_error_true_AU_median", "curve_error_energy"):
        assert 0.0 < float(gb[key]) < 100.0, key
    assert gb["rhs_error_true_AU_energy"] != rows[1]["rhs_error_true_AU_energy"]  # its own fit, not varying's
    # the journal keeps the fit times: varying's fitted model was reused as the reference (no own fit)
    record = json.loads((out / "study.jsonl").read_text().splitlines()[0])["row"]
    assert record["methods"]["greybox"]["fit_time_s"] > 0
    assert math.isnan(record["methods"]["greybox"]["reference_fit_time_s"])
    summary = json.loads((out / "summary.json").read_text())
    block = summary["methods"]["greybox"]["all"]
    assert block["n_draws"] == 1 and block["scores"]["rhs_error_true_AU_energy"]["n"] == 1
    assert set(summary["versus"]) == {"greybox vs varying", "varying vs greybox"}
    page = (out / "study.md").read_text()
    assert "- greybox: the grey-box refit given each draw" in page
    sections = {part.split("\n", 1)[0]: part for part in page.split("\n## ")[1:]}
    assert "| greybox | all (1) | dA/dt error on the true (A, U), energy-weighted | 1 |" in sections["Scores over campaigns"]
    assert f"| greybox | all (1) | {int(int(gb['n_flagged']) >= 20)} |" in sections["The verdict's promise"]
    assert "| greybox | all (1) | 0 |" in sections["Forced-only draws"]  # draw 0 is not forced-only
    assert "| greybox vs varying | 1 |" in sections["Against each other"]


def test_the_greybox_gets_the_draws_structure_and_no_aerodynamic_truth():
    draw = draw_bridge("development", 3)
    s = draw.config.structure
    bridge = structural_properties(s)
    assert set(dataclasses.asdict(bridge)) == set(STRUCTURAL_FIELDS)
    assert {f: getattr(bridge, f) for f in STRUCTURAL_FIELDS} == {f: getattr(s, f) for f in STRUCTURAL_FIELDS}
    assert set(STRUCTURAL_FIELDS).isdisjoint(f.name for f in dataclasses.fields(draw.config.aero))
    with pytest.raises(InputError, match="StructureConfig"):
        structural_properties(draw.config)  # the whole configuration holds the aerodynamics
    method = study_method("greybox", draw)
    assert isinstance(method, GreyBoxMethod) and method.bridge == bridge
    # another bridge's aerodynamics (bell, limiters, C_L, yaw effect) leave what the grey-box gets unchanged
    other = draw_bridge("development", 4).config.aero
    assert other != draw.config.aero
    swapped = dataclasses.replace(draw, config=dataclasses.replace(draw.config, aero=other))
    assert study_method("greybox", swapped).bridge == bridge
    # and another structure changes it
    assert study_method("greybox", draw_bridge("development", 4)).bridge != bridge


def test_greybox_method_checks_its_arguments():
    assert method_spec("greybox") == "greybox"
    bridge = BridgeProperties(mass=2.0e4, depth=4.0, frequency=0.3, damping_ratio=0.005)
    with pytest.raises(InputError, match="BridgeProperties"):
        GreyBoxMethod({"mass": 2.0e4})
    with pytest.raises(InputError, match="reference"):
        GreyBoxMethod(bridge, reference="pooled")
    with pytest.raises(InputError, match="sets"):
        GreyBoxMethod(bridge, warm_start=None)
    with pytest.raises(InputError, match="wind_smoothing_s"):
        GreyBoxMethod(bridge, wind_smoothing_s=-1.0)


def test_the_leaderboard_scores_the_greybox_on_a_tiny_scenario(tmp_path):
    from vivbench.validate import run_leaderboard
    from vivbench.validate.scenarios import load_scenario_file

    (tmp_path / "tiny.toml").write_text(
        '[scenario.tiny]\nversion = 1\ndescription = "two 10-min events of the default bridge (test size)"\n'
        'events = 2\nduration = 600.0\nseed = 1\n[scenario.tiny.generator]\nmode = "realistic"\n')
    scenarios = list(load_scenario_file(tmp_path / "tiny.toml").values())
    result = run_leaderboard(["greybox"], scenarios, tmp_path / "out")
    (row,) = result.rows
    assert row["method"] == "greybox" and row["error"] == "" and row["has_verdict"]
    assert 0.0 < row["rhs_error_true_AU"] < 100.0 and 0.0 <= row["accuracy_all"] <= 1.0
    assert 0.0 <= row["coverage"] <= 1.0
