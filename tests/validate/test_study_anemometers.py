"""Studies over the family with fewer anemometers than sections (StudyConfig.anemometer_span, --anemometers)."""

from __future__ import annotations

import pytest

from tests.helpers import run_cli
from vivbench.core.errors import InputError
from vivbench.synth.family import draw_bridge
from vivbench.validate.study import StudyConfig, study_tasks


def test_the_layout_is_validated_and_left_out_of_a_per_section_study():
    plain = StudyConfig(split="development", draws=(2,), methods=("binned",))
    assert "anemometer_span" not in plain.to_dict()  # studies without it keep their fingerprint
    mid = StudyConfig(split="development", draws=(2,), methods=("binned",), anemometer_span=[0.5])
    assert mid.anemometer_span == (0.5,) and mid.to_dict()["anemometer_span"] == [0.5]
    assert mid.fingerprint() != plain.fingerprint()
    with pytest.raises(InputError, match="anemometer_span must be None"):
        StudyConfig(split="development", draws=(2,), methods=("binned",), anemometer_span=(1.5,))
    with pytest.raises(InputError, match="wind_rule"):
        StudyConfig(split="development", draws=(2,), methods=("binned",), anemometer_span=(0.5,), wind_rule="next")


def test_each_task_places_the_anemometers_on_the_draws_campaign():
    config = StudyConfig(split="development", draws=(2, 7), methods=("binned",), max_events=2,
                         anemometer_span=(0.25, 0.75), wind_rule="interpolation")
    for task in study_tasks(config):
        draw = draw_bridge("development", task.draw)
        wind = task.campaign(draw).generator.wind
        assert wind.anemometer_span == (0.25, 0.75) and wind.wind_rule == "interpolation"
        assert task.campaign(draw).generator.structure == draw.config.structure  # only the anemometers change
        assert task.campaign(draw).n_events == 2


def test_the_command_line_refuses_a_bad_layout_in_one_line(tmp_path):
    out = run_cli("study", "--split", "development", "--draws", "2", "--methods", "binned", "--out", tmp_path / "s",
                  "--anemometers", "middle")
    assert out.returncode != 0 and "--anemometers must be comma-separated fractions" in out.stderr
    assert len(out.stderr.strip().splitlines()) == 1
