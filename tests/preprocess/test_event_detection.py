"""VIV events from continuous logs: detection on a small synthetic log, the boundary F1, bad input, the CLI round trip."""

from __future__ import annotations

import re

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tests.helpers import assert_close
from vivbench.cli import main
from vivbench.core import InputError, threshold_intervals
from vivbench.io import read_event
from vivbench.preprocess import CATALOGUE_COLUMNS, EventDetectionConfig, detect_events, find_events
from vivbench.synth import ContinuousLogConfig, generate_continuous_log, write_continuous_log
from vivbench.validate import boundary_f1

# Two hours: one VIV event and one wind-only gust, with short plateaus and gusts to stay fast.
SMALL = dict(duration_s=7200.0, seed=5, viv_per_day=12.0, gusts_per_day=12.0,
             viv_plateau_s=(600.0, 900.0), gust_hold_s=(300.0, 600.0))


@pytest.fixture(scope="module")
def small_log():
    return generate_continuous_log(ContinuousLogConfig(**SMALL))


@pytest.fixture(scope="module")
def small_log_files(small_log, tmp_path_factory):
    """The small log as hourly CSV files (local time +08:00, km/h, milli-g) and its mapping."""
    return write_continuous_log(small_log, tmp_path_factory.mktemp("log"), file_s=3600.0)


def test_small_log_has_one_event_and_one_gust(small_log):
    kinds = [e["kind"] for e in small_log.episodes]
    assert kinds.count("viv") == 1 and kinds.count("gust") == 1
    assert small_log.events.shape == (1, 2)
    viv = next(e for e in small_log.episodes if e["kind"] == "viv")
    assert viv["start_s"] < small_log.events[0, 0] < small_log.events[0, 1] < viv["end_s"]
    assert small_log.acc.shape == (int(SMALL["duration_s"] * 50), 3)


def test_detection_finds_the_event_and_not_the_gust(small_log):
    det = detect_events(small_log.accel_time, small_log.acc)
    assert_close(det.frequency_hz, 0.327, rtol=0.01, reason="Welch peak of a 2 h record: bins of 1/1200 Hz, parabola-refined")
    score = boundary_f1(small_log.events, det.intervals, margin_s=120.0)
    assert score.f1 == 1.0, (small_log.events, det.intervals)
    gust = next(e for e in small_log.episodes if e["kind"] == "gust")
    assert not np.any((det.intervals[:, 1] > gust["start_s"]) & (det.intervals[:, 0] < gust["end_s"]))
    # The gust raises the amplitude above the quiet floor, below the threshold.
    inside = (det.t > gust["start_s"]) & (det.t < gust["end_s"])
    assert 2.0 * det.noise_floor_m.max() < np.nanmax(det.amplitude[inside]) < det.threshold_m.max()


def test_detection_with_gaps_and_an_absolute_threshold(small_log):
    acc = small_log.acc.astype(float)
    acc[100_000:100_500] = np.nan  # 10 s of NaN
    keep = np.ones(acc.shape[0], bool)
    keep[200_000:201_000] = False  # 20 s of missing stamps
    det = detect_events(small_log.accel_time[keep], acc[keep], EventDetectionConfig(threshold_m=0.005, frequency_hz=0.327))
    assert np.all(det.threshold_m == 0.005) and det.frequency_hz == 0.327
    assert np.isnan(det.amplitude[(det.t > 2001) & (det.t < 2009)]).all()
    assert det.intervals.shape[0] == 1


def test_stamps_off_a_regular_clock_are_refused(small_log):
    t = small_log.accel_time.copy()
    t[5000] += 0.4 / 50
    with pytest.raises(InputError, match=r"^log\.csv: the time stamp 100.008 s after the first is 0.40 steps away from a regular 50 Hz clock"):
        detect_events(t, small_log.acc, name="log.csv")


@pytest.mark.parametrize("kwargs, message", [
    ({"threshold_factor": 1.0}, "threshold_factor must be a number > 1"),
    ({"threshold_m": -1.0}, "threshold_m must be None"),
    ({"min_duration_s": float("nan")}, "min_duration_s must be a finite number"),
    ({"merge_gap_s": -5}, "merge_gap_s must be"),
    ({"band_hz": (2.0, 1.0)}, "band_hz must be"),
    ({"half_width": 0.7}, "half_width must be in"),
    ({"frequency_hz": 0.0}, "frequency_hz must be None"),
])
def test_config_refuses_bad_values(kwargs, message):
    with pytest.raises(InputError, match=message):
        EventDetectionConfig(**kwargs)
    with pytest.raises(TypeError):
        EventDetectionConfig(10.0)  # keyword-only


def test_threshold_intervals_merge_then_drop():
    t = np.arange(20.0)
    above = np.zeros(20, bool)
    above[[2, 3, 5, 6, 7, 15]] = True
    assert threshold_intervals(t, above, merge_gap_s=3.0, min_duration_s=0.0).tolist() == [[2.0, 7.0], [15.0, 15.0]]
    # A gap as long as merge_gap_s is not merged (shorter ones are).
    assert threshold_intervals(t, above, merge_gap_s=2.0, min_duration_s=0.0).tolist() == [[2.0, 3.0], [5.0, 7.0], [15.0, 15.0]]
    assert threshold_intervals(t, above, merge_gap_s=1.0, min_duration_s=2.0).tolist() == [[5.0, 7.0]]
    assert threshold_intervals(t, above, merge_gap_s=100.0, min_duration_s=0.0).tolist() == [[2.0, 15.0]]
    assert threshold_intervals(t, np.zeros(20, bool), merge_gap_s=1.0, min_duration_s=0.0).shape == (0, 2)


# ----------------------------------------------------------------------------- F1


def test_f1_hand_made_cases():
    truth = [[1000.0, 2000.0], [5000.0, 6000.0]]
    perfect = boundary_f1(truth, truth)
    assert (perfect.precision, perfect.recall, perfect.f1, perfect.true_positives) == (1.0, 1.0, 1.0, 4)
    # Within the margin (inclusive) counts; beyond it does not.
    assert boundary_f1(truth, [[1120.0, 1880.0], [5000.0, 6000.0]]).f1 == 1.0
    s = boundary_f1(truth, [[1121.0, 2000.0], [5000.0, 6000.0]])
    assert (s.true_positives, s.precision, s.recall) == (3, 0.75, 0.75)
    # A missed event: precision 1, recall 1/2.
    s = boundary_f1(truth, [[1000.0, 2000.0]])
    assert (s.precision, s.recall) == (1.0, 0.5)
    assert_close(s.f1, 2 / 3)
    # A false event: precision 2/3.
    s = boundary_f1(truth, truth + [[8000.0, 9000.0]])
    assert (s.precision, s.recall) == (4 / 6, 1.0)
    # An event split in two: its outer start and end are right, the split's end and start are false.
    s = boundary_f1([[1000.0, 2000.0]], [[1000.0, 1400.0], [1600.0, 2000.0]])
    assert (s.true_positives, s.n_detected, s.precision, s.recall) == (2, 4, 0.5, 1.0)
    # Starts match starts and ends match ends: a detected start on a true end is no match.
    assert boundary_f1([[1000.0, 1100.0]], [[1100.0, 1200.0]]).true_positives == 2
    assert boundary_f1([[1000.0, 1050.0]], [[1050.0, 1300.0]], margin_s=10.0).true_positives == 0
    # One-to-one: two detected starts near one true start give one true positive.
    s = boundary_f1([[1000.0, 3000.0]], [[990.0, 995.0], [1005.0, 3000.0]], margin_s=30.0)
    assert s.true_positives == 2 and s.n_detected == 4
    # Nothing to find and nothing found is perfect; something missed or invented is not.
    assert boundary_f1(np.empty((0, 2)), np.empty((0, 2))).f1 == 1.0
    assert boundary_f1(np.empty((0, 2)), truth).f1 == 0.0
    assert boundary_f1(truth, np.empty((0, 2))).f1 == 0.0


def test_f1_refuses_bad_input():
    with pytest.raises(InputError, match="margin_s must be a positive"):
        boundary_f1([[0, 1]], [[0, 1]], margin_s=0)
    with pytest.raises(InputError, match="true_events must be"):
        boundary_f1([[2.0, 1.0]], [[0, 1]])


_events = st.lists(st.tuples(st.floats(0, 1e5), st.floats(0, 3600)), max_size=8).map(
    lambda xs: np.array([[a, a + d] for a, d in xs]).reshape(-1, 2))


@settings(max_examples=100, deadline=None)
@given(a=_events, b=_events, margin=st.floats(1.0, 600.0))
def test_f1_invariants(a, b, margin):
    ab, ba = boundary_f1(a, b, margin_s=margin), boundary_f1(b, a, margin_s=margin)
    assert ab.true_positives == ba.true_positives
    assert_close(ab.f1, ba.f1)
    if a.size and b.size:
        assert_close(ab.precision, ba.recall)
    assert 0.0 <= ab.f1 <= 1.0
    assert boundary_f1(a, a, margin_s=margin).f1 == 1.0
    # Matching is order-free and never exceeds either count.
    assert boundary_f1(a[::-1], b, margin_s=margin).true_positives == ab.true_positives
    assert ab.true_positives <= min(ab.n_true, ab.n_detected)


# ------------------------------------------------------------------ files and CLI


def test_cli_events_then_identify(small_log, small_log_files, tmp_path, capsys):
    out = tmp_path / "events"
    assert main(["events", str(small_log_files), "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "1 events" in printed and "LOG_001" in printed
    lines = (out / "catalogue.csv").read_text().splitlines()
    assert lines[0].split(",") == list(CATALOGUE_COLUMNS) and len(lines) == 2
    row = dict(zip(lines[0].split(","), lines[1].split(",")))
    assert_close(float(row["frequency_hz"]), 0.327, rtol=0.01, reason="the event's own Welch peak, ~20 min")
    assert sorted(p.name for p in out.iterdir()) == ["LOG_001.nc", "catalogue.csv"]
    event = read_event(out / "LOG_001.nc")
    assert event.attrs["source"] == "field" and event.attrs["import_units_acc_S1"] == "mg"
    # The event's core is where the catalogue says, within the margins of its file.
    start = float(event.attrs["detection_start_s"])
    assert_close(start, 300.0, atol=0.5, reason="the margin is counted from the first accelerometer sample in it")
    truth = small_log.events[0]
    assert abs(float(row["duration_s"]) - (truth[1] - truth[0])) < 240
    ident = tmp_path / "identify"
    assert main(["identify", str(out / "LOG_001.nc"), "--out", str(ident)]) == 0
    assert (ident / "LOG_001.identify.nc").is_file()


def test_a_log_without_events_is_one_line_and_nothing_written(tmp_path, capsys):
    quiet = generate_continuous_log(ContinuousLogConfig(duration_s=3600.0, seed=2, viv_per_day=0.0, gusts_per_day=0.0))
    assert quiet.events.shape == (0, 2) and {e["kind"] for e in quiet.episodes} == {"quiet"}
    mapping = write_continuous_log(quiet, tmp_path / "log", file_s=1800.0)
    out = tmp_path / "events"
    assert main(["events", str(mapping), "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1
    assert re.match(rf"vivbench events: {re.escape(str(mapping))}: no VIV event in 3600 s of records: .*nothing written", err)
    assert not out.exists()
    with pytest.raises(InputError, match="no VIV event"):
        find_events(mapping, out)
    assert not out.exists()


def test_rates_that_contradict_the_stamps_are_refused(small_log_files, tmp_path, capsys):
    bad = small_log_files.parent / "mapping_rate.toml"
    bad.write_text(small_log_files.read_text().replace('units = "mg"', 'units = "mg"\nrate = 25'))
    out = tmp_path / "events"
    assert main(["events", str(bad), "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1
    assert re.search(r"accel_\d{8}T\d{6}\.csv.*declares rate = 25 Hz but the time stamps step every 0\.02 s", err), err
    assert not out.exists()


def test_same_seed_same_log():
    cfg = ContinuousLogConfig(duration_s=3600.0, seed=9, viv_per_day=0.0, gusts_per_day=24.0, gust_hold_s=(120.0, 300.0))
    a, b = generate_continuous_log(cfg), generate_continuous_log(cfg)
    assert a.acc.tobytes() == b.acc.tobytes() and a.u.tobytes() == b.u.tobytes()
    assert a.episodes == b.episodes


@pytest.mark.parametrize("kwargs, message", [
    ({"duration_s": 100.0}, "duration_s must be a whole number of seconds >= 3600"),
    ({"gust_speed": (5.0, 6.0)}, "speeds must order quiet < lock-in < gust"),
    ({"start": "yesterday"}, "start must be an ISO 8601"),
    ({"duration_s": 3600.0, "viv_per_day": 24.0, "viv_plateau_s": (3000.0, 3600.0)}, "too short for 1 VIV episodes"),
])
def test_log_config_refuses_bad_values(kwargs, message):
    with pytest.raises(InputError, match=message):
        generate_continuous_log(ContinuousLogConfig(**kwargs))
