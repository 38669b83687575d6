"""Studies on the truth's own wind and amplitude (StudyConfig.wind_source, amplitude_source): oracles."""

from __future__ import annotations

import numpy as np
import pytest
import xarray as xr

import vivbench.validate.study as study_module
from tests.helpers import assert_close, run_cli
from vivbench.core.errors import InputError
from vivbench.core.record import Record
from vivbench.validate.recovery import record_with_truth_amplitude, record_with_truth_wind
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


def test_the_truths_amplitude_replaces_the_measured_one_and_its_derivative():
    rec = _record()
    A = np.array(rec.A)
    A[5, 0] = np.nan
    rec = Record(event_id=rec.event_id, t=rec.t, A=A, U=rec.U, dA=rec.dA, yaw=rec.yaw, wind_distance=rec.wind_distance)
    tt = np.arange(0.0, 30.0, 2.0)
    At = np.column_stack([0.01 + 0.001 * tt, 0.02 - 0.0002 * tt])
    r = np.zeros((tt.size, 2, 4))
    r[:, 0, 1], r[:, 0, 3] = 0.0006, 0.0004  # dA/dt is the sum of the orders: 0.001 m/s on section 1
    r[:, 1, 0] = -0.0002
    truth = xr.Dataset({"A": (("time", "section"), At), "r": (("time", "section", "order"), r)}, coords={"time": tt})
    out = record_with_truth_amplitude(rec, truth)
    ok = np.isfinite(A[:, 0])
    assert_close(out.A[ok, 0], 0.01 + 0.001 * rec.t[ok])  # linear in time: interpolation is exact
    assert_close(out.A[:, 1], 0.02 - 0.0002 * rec.t)
    assert_close(out.dA[ok, 0], np.full(ok.sum(), 0.001), rtol=1e-12, reason="a sum of two binary fractions")
    assert_close(out.dA[:, 1], np.full(rec.t.size, -0.0002))
    assert np.isnan(out.A[5, 0]) and np.isnan(out.dA[5, 0])  # no measured sample there: none of the truth's either
    for name in ("t", "U", "yaw", "wind_distance"):
        np.testing.assert_array_equal(getattr(out, name), getattr(rec, name))
    three = truth.isel(section=[0, 1, 1])
    with pytest.raises(ValueError, match="3 sections and the record E001 has 2"):
        record_with_truth_amplitude(rec, three)


def test_the_amplitude_source_is_validated_and_left_out_of_a_measured_study():
    plain = StudyConfig(split="development", draws=(2,), methods=("binned",))
    assert "amplitude_source" not in plain.to_dict()
    oracle = StudyConfig(split="development", draws=(2,), methods=("binned",), amplitude_source="truth")
    assert oracle.to_dict()["amplitude_source"] == "truth" and oracle.fingerprint() != plain.fingerprint()
    with pytest.raises(InputError, match="amplitude_source must be one of measured, truth"):
        StudyConfig(split="development", draws=(2,), methods=("binned",), amplitude_source="envelope")


def test_the_model_classes_own_error_is_below_the_measured_one_and_the_page_says_it_is_an_oracle(tmp_path):
    # development draw 18 (one kept event would leave nothing to fit across): the measured envelope carries
    # buffeting and the noise floor, the anemometers 10 % point turbulence; the oracle has neither
    runs = {}
    for source in ("measured", "truth"):
        out = run_cli("study", "--split", "development", "--draws", "18", "--methods", "pooled", "--max-events", "2",
                      "--max-duration", "10", "--wind-source", source, "--amplitude-source", source,
                      "--out", tmp_path / source, "--workers", "1")
        assert out.returncode == 0, out.stderr
        lines = (tmp_path / source / "study.csv").read_text().splitlines()
        row = dict(zip(lines[0].split(","), lines[1].split(",")))
        runs[source] = float(row["rhs_error_true_AU_energy"])
    assert runs["truth"] < 0.5 * runs["measured"]
    assert "Oracle amplitude" in (tmp_path / "truth" / "study.md").read_text()
    assert "Oracle amplitude" not in (tmp_path / "measured" / "study.md").read_text()
