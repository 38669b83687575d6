"""Field import at other rates than the event grid's: resampling, recorded rates, and refused rates."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from scipy.interpolate import CubicSpline

from tests.helpers import assert_close
from vivbench.analysis.identify import IdentifyConfig, identify_event
from vivbench.cli import main
from vivbench.io import NOMINAL_RATES, event_arrays
from vivbench.io.field_resample import measured_rate, resample_to_grid
from vivbench.io.fieldimport import import_event
from vivbench.io.quality import ACC_UNITS, WIND_UNITS

CONFIG = IdentifyConfig(window=30.0, step=15.0)


def _local_stamps(start_time: str, t: np.ndarray, hours: int = 8) -> np.ndarray:
    """ISO 8601 local-time stamps at UTC+hours with their offset, e.g. 2026-01-01T22:34:00.050000+08:00."""
    start = pd.Timestamp(start_time).tz_convert("UTC").tz_localize(None)
    local = start + pd.Timedelta(hours=hours) + pd.to_timedelta(np.round(t * 1e6).astype(np.int64), unit="us")
    return np.char.add(np.asarray(local.strftime("%Y-%m-%dT%H:%M:%S.%f"), dtype=str), f"+{hours:02d}:00")


def write_field_files(tree, out, *, wind_rate: float, acc_rate: float, declare: bool = True):
    """Write an event as field files at other rates: one CSV per sensor in km/h and milli-g, local ISO stamps.

    The records are interpolated with cubic splines (not the import's polyphase filter) onto the
    new clocks; the mapping follows docs/field_import.md. Returns the mapping's path.
    """
    arr = event_arrays(tree)
    sections = list(arr["sections"])
    lines = [f'event_id = "{tree.attrs["event_id"]}F"', f"span_azimuth_deg = {float(tree.attrs['span_azimuth_deg'])!r}", ""]
    for group, variables, units, rate in (("wind", ("u", "v", "w"), "km/h", wind_rate),
                                          ("accel", ("acc",), "mg", acc_rate)):
        t = arr[f"{group}_time"]
        new_t = np.arange(int(np.floor((t[-1] - t[0]) * rate)) + 1) / rate + t[0]
        factor = {**WIND_UNITS, **ACC_UNITS}[units]
        lines += [f"[{group}]", 'time = "time"', 'time_format = "iso8601"', f'units = "{units}"']
        lines += [f"rate = {rate!r}"] if declare else []
        lines.append("")
        for i, sec in enumerate(sections):
            frame = {"time": _local_stamps(str(tree.attrs["start_time"]), new_t)}
            for var in variables:
                frame[var] = CubicSpline(t, arr[var][:, i])(new_t) / factor
            pd.DataFrame(frame).to_csv(out / f"{group}_{sec}.csv", index=False)
            lines += [f"[{group}.{sec}]", f'file = "{group}_{sec}.csv"', *[f'{v} = "{v}"' for v in variables], ""]
    mapping = out / "mapping.toml"
    mapping.write_text("\n".join(lines))
    return mapping


def _rms_rel(a, b):
    ok = np.isfinite(a) & np.isfinite(b)
    return float(np.sqrt(np.mean((a[ok] - b[ok]) ** 2)) / np.sqrt(np.mean(b[ok] ** 2)))


def test_20hz_wind_100hz_accel_identify_like_the_nominal_event(short_event, tmp_path):
    mapping = write_field_files(short_event, tmp_path, wind_rate=20.0, acc_rate=100.0)
    assert "+08:00" in (tmp_path / "wind_S1.csv").read_text().splitlines()[1]
    tree = import_event(mapping, tmp_path / "F.nc")
    assert_close([tree.attrs["import_rate_wind_hz"], tree.attrs["import_rate_accel_hz"]], [20.0, 100.0], rtol=1e-9,
                 reason="median step of microsecond ISO stamps")
    assert tree.attrs["import_resampled_wind"] == 1 and tree.attrs["import_resampled_accel"] == 1
    assert tree.attrs["start_time"] == short_event.attrs["start_time"]
    a, b = event_arrays(tree), event_arrays(short_event)
    for group in ("wind", "accel"):
        assert_close(np.median(np.diff(a[f"{group}_time"])), 1.0 / NOMINAL_RATES[group], rtol=1e-12,
                     reason="differences of float64 times")
    # The grids start at the same instant; the imported one may stop a sample or two short of the last stamp.
    n = a["accel_time"].size
    assert_close(a["accel_time"], b["accel_time"][:n], atol=1e-9, reason="k / 50 Hz against the event's own float64 times")
    # Acceleration: the VIV band (well below 25 Hz) survives 50 -> 100 -> 50 Hz; the ends are the filter's edges.
    inner = slice(50, n - 50)
    # Loose: the broadband sensor noise and quantisation near 25 Hz fall in the filter's transition band.
    assert _rms_rel(a["acc"][inner], b["acc"][:n][inner]) < 0.05
    got = identify_event(tree, CONFIG)
    ref = identify_event(short_event, CONFIG)
    m = min(got.sizes["time"], ref.sizes["time"])
    assert_close(got["time"].values[:m], ref["time"].values[:m], atol=1e-9, reason="the same grid computed twice")
    err = _rms_rel(got["A"].values[:m], ref["A"].values[:m])
    assert err < 0.02, err
    # The wind, too, gives the same mean speed across the span (U).
    assert _rms_rel(got["U"].values[:m], ref["U"].values[:m]) < 0.02


def test_resampling_keeps_a_tone_and_removes_what_would_alias():
    # 100 Hz record: a 2 Hz tone kept, a 40 Hz tone (above the 25 Hz Nyquist of 50 Hz) removed.
    t = np.arange(0, 60, 0.01)
    x = np.sin(2 * np.pi * 2.0 * t) + np.sin(2 * np.pi * 40.0 * t)
    grid = np.arange(0, 59.99, 0.02)
    y = resample_to_grid(t, x, 100.0, grid, "x.csv")
    inner = slice(100, -100)
    assert_close(y[inner], np.sin(2 * np.pi * 2.0 * grid[inner]), atol=0.01,
                 reason="the filter's stop-band leaves a trace of the 40 Hz tone and its pass-band ripple")
    # A dropped sample becomes NaN on the grid around it, not a silent fill.
    x2 = x.copy()
    x2[3001] = np.nan
    y2 = resample_to_grid(t, x2, 100.0, grid, "x.csv")
    assert np.isnan(y2[1500]) and np.isnan(y2[1501]) and np.isfinite(y2[1499]) and np.isfinite(y2[1502])


@pytest.mark.parametrize("edit, words", [
    (lambda text: text.replace("rate = 20.0", "rate = 25.0"), "declares rate = 25 Hz but the time stamps step every 0.05 s"),
    (lambda text: text.replace("rate = 20.0\n", ""), None),
])
def test_declared_rate_must_match_the_stamps(short_event, tmp_path, capsys, edit, words):
    mapping = write_field_files(short_event, tmp_path, wind_rate=20.0, acc_rate=100.0)
    mapping.write_text(edit(mapping.read_text()))
    out = tmp_path / "out.nc"
    code = main(["import", str(mapping), "--out", str(out)])
    err = capsys.readouterr().err
    if words is None:  # no declared rate: the stamps decide
        assert code == 0 and out.exists()
        return
    assert code == 2 and not out.exists()
    assert err.count("\n") == 1 and "wind_S1.csv" in err and words in err, err


@pytest.mark.parametrize("group, rate", [("wind", 0.5), ("wind", 64.0), ("accel", 10.0), ("accel", 2000.0)])
def test_implausible_rates_are_refused(group, rate):
    t = np.arange(200) / rate
    with pytest.raises(ValueError, match=rf"^s\.csv: sampling rate {rate:.4g} Hz \(median step\) is outside"):
        measured_rate(t, "s.csv", group)


def test_stamps_off_a_regular_clock_are_refused():
    t = np.arange(400) / 20.0
    t[100:200:2] += 0.016  # every other stamp 0.32 of a step late: not a regular clock
    with pytest.raises(ValueError, match=r"^w\.csv: the time stamp .* steps away from a regular 20 Hz clock"):
        resample_to_grid(t, np.ones(400), 20.0, np.arange(0, 19, 1 / 32), "w.csv")
