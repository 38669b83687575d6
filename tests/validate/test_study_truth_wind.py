"""Studies on the truth's own wind (StudyConfig.wind_source, --wind-source truth): an oracle without errors in the wind."""

from __future__ import annotations

import numpy as np
import pytest
import xarray as xr

import vivbench.validate.study as study_module
from tests.helpers import assert_close, run_cli
from vivbench.core.errors import InputError
from vivbench.core.record import Record
from vivbench.validate.recovery import record_with_truth_wind
from vivbench.validate.study import StudyConfig, run_study_task, study_tasks


def _record(n=50, S=2):
    t = np.arange(n) * 0.5
    U = np.full((n, S), 7.0)
    U[3, 1] = np.nan
    return Record(event_id="E001", t=t, A=np.full((n, S), 0.01), U=U, dA=np.zeros((n, S)),
                  yaw=np.zeros((n, S)), wind_distance=np.array([0.0, 40.0]))


def test_the_truths_wind_replaces_the_measured_one_and_nothing_else():
    rec = _record()
    tt = np.arange(0.0, 30.0, 2.0)
    truth = xr.Dataset({"U": (("time", "section"), np.column_stack([5.0 + 0.1 * tt, 6.0 - 0.1 * tt]))},
                       coords={"time": tt})
    out = record_with_truth_wind(rec, truth)
    assert_close(out.U[:, 0], 5.0 + 0.1 * rec.t)  # linear in time: interpolation is exact
    ok = np.isfinite(rec.U[:, 1])
    assert_close(out.U[ok, 1], 6.0 - 0.1 * rec.t[ok])
    assert np.isnan(out.U[3, 1])  # no measured sample there: none on the truth's wind either
    assert out.wind_distance is None  # the deck's own wind
    for name in ("t", "A", "dA", "yaw"):
        np.testing.assert_array_equal(getattr(out, name), getattr(rec, name))
    one = xr.Dataset({"U": (("time",), 5.0 + 0.1 * tt)}, coords={"time": tt})  # one wind for every section
    assert_close(record_with_truth_wind(rec, one).U[ok, 1], 5.0 + 0.1 * rec.t[ok])
    three = xr.Dataset({"U": (("time", "section"), np.ones((tt.size, 3)))}, coords={"time": tt})
    with pytest.raises(ValueError, match="3 sections and the record E001 has 2"):
        record_with_truth_wind(rec, three)


def test_the_wind_source_is_validated_and_left_out_of_a_measured_study():
    plain = StudyConfig(split="development", draws=(2,), methods=("binned",))
    assert "wind_source" not in plain.to_dict()  # studies on the measured wind keep their fingerprint
    oracle = StudyConfig(split="development", draws=(2,), methods=("binned",), wind_source="truth")
    assert oracle.to_dict()["wind_source"] == "truth" and oracle.fingerprint() != plain.fingerprint()
    with pytest.raises(InputError, match="wind_source must be one of measured, truth"):
        StudyConfig(split="development", draws=(2,), methods=("binned",), wind_source="felt")


@pytest.mark.parametrize("source", ["measured", "truth"])
def test_a_task_fits_its_methods_on_the_wind_of_its_source(monkeypatch, source):
    calls = []

    def spy(record, truth):
        calls.append(record.event_id)
        return record_with_truth_wind(record, truth)

    monkeypatch.setattr(study_module, "record_with_truth_wind", spy)
    config = StudyConfig(split="development", draws=(3,), methods=("binned",), max_events=2, max_duration=300.0,
                         wind_source=source)
    (task,) = study_tasks(config)
    row = run_study_task(task)
    assert row["methods"]["binned"]["error"] == ""
    assert calls == ([] if source == "measured" else ["E001", "E002"][:row["n_events"] - row["events_failed"]])


def test_the_oracle_lowers_the_error_of_a_campaign_with_point_turbulence_at_the_anemometers(tmp_path):
    # development draw 18: the deck feels the smooth mean wind, its anemometers see 10 % point turbulence
    runs = {}
    for source in ("measured", "truth"):
        out = run_cli("study", "--split", "development", "--draws", "18", "--methods", "pooled", "--max-events", "2",
                      "--max-duration", "10", "--wind-source", source, "--out", tmp_path / source, "--workers", "1")
        assert out.returncode == 0, out.stderr
        lines = (tmp_path / source / "study.csv").read_text().splitlines()
        row = dict(zip(lines[0].split(","), lines[1].split(",")))
        runs[source] = float(row["rhs_error_true_AU_energy"])
    assert runs["truth"] < 0.5 * runs["measured"]  # 1.19 against 29.9 when written
    assert "Oracle wind" in (tmp_path / "truth" / "study.md").read_text()
    assert "Oracle wind" not in (tmp_path / "measured" / "study.md").read_text()
