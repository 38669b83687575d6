"""Field import: CSV and MAT round trips, unit conversion, repairs, and one-line refusals of bad mappings."""

from __future__ import annotations

import re
import shutil

import h5py
import numpy as np
import pandas as pd
import pytest
import xarray as xr

from tests.helpers import assert_close
from vivbench.cli import main
from vivbench.io.field_export import export_csv, export_mat
from vivbench.io.fieldimport import import_event, load_mapping
from vivbench.analysis.identify import IdentifyConfig, identify_files
from vivbench.io.event import event_arrays, read_event
from vivbench.io.quality import ACC_UNITS, G, WIND_UNITS

VARS = ("wind_time", "u", "v", "w", "accel_time", "acc")


@pytest.fixture(scope="module")
def csv_dir(short_event, tmp_path_factory):
    """The short event exported once as per-section CSV files; tests copy it before editing."""
    d = tmp_path_factory.mktemp("csv")
    export_csv(short_event, d)
    return d


def _copy(csv_dir, dest):
    shutil.copytree(csv_dir, dest)
    return dest / "mapping.toml"


def _same(a, b, exact=True):
    for k in VARS:
        if exact:
            np.testing.assert_array_equal(a[k], b[k], err_msg=k)
        else:
            assert_close(a[k], b[k], rtol=1e-12, atol=1e-15, reason="unit conversion and back in float64", what=k)


def test_csv_round_trip_per_section_is_exact(short_event, csv_dir, tmp_path):
    mapping = csv_dir / "mapping.toml"
    out = tmp_path / "F.nc"
    tree = import_event(mapping, out)
    _same(event_arrays(read_event(out)), event_arrays(short_event))
    assert tree.attrs["source"] == "field"
    assert tree.attrs["start_time"] == short_event.attrs["start_time"]
    assert tree.attrs["quality_duplicates_dropped"] == 0 and tree.attrs["quality_missing_wind"] == 0
    assert tree.attrs["import_units_acc_S2"] == "m/s^2" and tree.attrs["import_factor_acc_S2"] == 1.0


@pytest.mark.parametrize(
    "wind_units, acc_units, time_format",
    [("km/h", "g", "iso8601"), ("knots", "mm/s^2", "seconds"), ("m/s", "mg", "iso8601"), ("kt", "milli-g", "seconds")],
)
def test_csv_single_file_units_are_converted(short_event, tmp_path, wind_units, acc_units, time_format):
    mapping = export_csv(short_event, tmp_path, layout="single", wind_units=wind_units, acc_units=acc_units,
                         time_format=time_format)
    raw = pd.read_csv(tmp_path / "accel.csv")
    # the file really holds the other unit
    assert_close(raw["acc_S2"].to_numpy() * ACC_UNITS[acc_units], event_arrays(short_event)["acc"][:, 1],
                 rtol=1e-12, atol=1e-15, reason="one multiplication in float64")
    tree = import_event(mapping)
    _same(event_arrays(tree), event_arrays(short_event), exact=False)
    assert tree.attrs["import_units_u_S1"] == wind_units
    assert tree.attrs["import_factor_u_S1"] == WIND_UNITS[wind_units]
    assert tree.attrs["import_factor_acc_S3"] == ACC_UNITS[acc_units]


def test_unit_factors():
    assert_close(WIND_UNITS["km/h"], 1 / 3.6)
    assert_close(WIND_UNITS["knots"], 0.514444, rtol=1e-6, reason="the knot, 1852/3600 m/s, written to six digits")
    assert ACC_UNITS["g"] == G == 9.80665
    assert_close(ACC_UNITS["mg"], 9.80665e-3)
    assert ACC_UNITS["mm/s^2"] == 1e-3


@pytest.mark.parametrize("version", ["5", "7.3"])
def test_mat_round_trip(short_event, tmp_path, version):
    mapping = export_mat(short_event, tmp_path, version=version, acc_units="g")
    assert h5py.is_hdf5(tmp_path / "event.mat") == (version == "7.3")
    tree = import_event(mapping)
    _same(event_arrays(tree), event_arrays(short_event), exact=False)
    assert tree.attrs["import_units_acc_S1"] == "g"


def test_cli_import_then_identify_keeps_quality(short_event, csv_dir, tmp_path, capsys):
    mapping = _copy(csv_dir, tmp_path / "csv")
    # two repeated rows and one swapped pair in S2's wind file
    f = tmp_path / "csv" / "wind_S2.csv"
    lines = f.read_text().splitlines()
    lines = lines[:10] + [lines[10], lines[10], lines[12], lines[11]] + lines[13:200] + [lines[200]] + lines[200:]
    f.write_text("\n".join(lines) + "\n")
    out = tmp_path / "F.nc"
    assert main(["import", str(mapping), "--out", str(out)]) == 0
    assert "duplicates_dropped 2" in capsys.readouterr().out
    tree = read_event(out)
    assert tree.attrs["quality_duplicates_dropped"] == 2
    assert tree.attrs["quality_rows_reordered"] == 2
    _same(event_arrays(tree), event_arrays(short_event))
    written, failures = identify_files([out], tmp_path / "res", IdentifyConfig(window=30.0, step=15.0))
    assert not failures
    res = xr.open_dataset(written[0])
    assert res.attrs["quality_duplicates_dropped"] == 2 and res.attrs["quality_spikes_accel"] == 0
    res.close()


def test_missing_cells_and_rows_become_nan(short_event, csv_dir, tmp_path):
    mapping = _copy(csv_dir, tmp_path / "in")
    tmp_path = tmp_path / "in"
    f = tmp_path / "wind_S1.csv"
    frame = pd.read_csv(f)
    frame.loc[5:9, "u"] = np.nan          # 5 missing cells
    frame = frame.drop(index=range(100, 132))  # 32 rows (1 s) missing from S1 only
    frame.to_csv(f, index=False)
    tree = import_event(mapping)
    a, b = event_arrays(tree), event_arrays(short_event)
    np.testing.assert_array_equal(a["wind_time"], b["wind_time"])  # the other sections keep the clock
    assert np.isnan(a["u"][5:10, 0]).all() and np.isnan(a["w"][100:132, 0]).all()
    assert np.isfinite(a["u"][:, 1]).all()
    assert tree.attrs["quality_missing_wind"] == 5 + 3 * 32


def _edit_text(path, old, new):
    text = path.read_text()
    assert old in text, (old, text)
    path.write_text(text.replace(old, new, 1))


def _csv(col, fn):
    def edit(d):
        f = d / "accel_S2.csv" if col == "acc" else d / "wind_S2.csv"
        frame = pd.read_csv(f)
        fn(frame)
        frame.to_csv(f, index=False)
    return edit


def _time_back(frame):
    frame.loc[100:, "time"] = frame.loc[100:, "time"].to_numpy()[::-1]


BAD = {
    "missing channel": (lambda d: _edit_text(d / "mapping.toml", 'w = "w"\n', "", ), "mapping.toml", "lacks the channel 'w'"),
    "unknown key": (lambda d: _edit_text(d / "mapping.toml", 'acc = "acc"', 'acc = "acc"\nacc2 = "x"'), "mapping.toml", "unknown key"),
    "unknown units": (lambda d: _edit_text(d / "mapping.toml", 'units = "m/s^2"', 'units = "G"'), "mapping.toml", "allowed for accel"),
    "missing units": (lambda d: _edit_text(d / "mapping.toml", 'units = "m/s"\n', ""), "mapping.toml", "has no units"),
    "bad toml": (lambda d: _edit_text(d / "mapping.toml", "[wind]", "[wind"), "mapping.toml", "not valid TOML"),
    "section mismatch": (lambda d: _edit_text(d / "mapping.toml", "[accel.S3]", "[accel.S4]"), "mapping.toml", "expected tables S1..Sn"),
    "bad time format": (lambda d: _edit_text(d / "mapping.toml", 'time_format = "seconds"', 'time_format = "ms"'), "mapping.toml", "time_format"),
    "missing file": (lambda d: (d / "wind_S3.csv").unlink(), "wind_S3.csv", "no such data file"),
    "missing column": (lambda d: _edit_text(d / "mapping.toml", 'v = "v"', 'v = "V"'), "wind_S1.csv", "no column 'V'"),
    "text in a cell": (_csv("acc", lambda fr: fr.__setitem__("acc", fr["acc"].astype(object).where(fr.index != 7, "ERR"))),
                       "accel_S2.csv", "line 9 holds 'ERR'"),
    "missing time": (_csv("u", lambda fr: fr.__setitem__("time", fr["time"].where(fr.index != 3))), "wind_S2.csv", "missing at line 5"),
    "clock goes back": (_csv("u", _time_back), "wind_S2.csv", "time goes back"),
    "time in ms": (_csv("acc", lambda fr: fr.__setitem__("time", fr["time"] * 1000)), "accel_S2.csv", "sampling rate"),
    "clocks do not line up": (_csv("u", lambda fr: fr.__setitem__("time", fr["time"] + 0.01)), "wind_S1.csv", "do not line up"),
    "acc in g with gravity": (_csv("acc", lambda fr: fr.__setitem__("acc", fr["acc"] / G + 1.0)), "accel_S2.csv",
                              'looks like g including gravity; set units = "g"'),
    "acc in mm/s^2": (_csv("acc", lambda fr: fr.__setitem__("acc", fr["acc"] * 1000)), "accel_S2.csv",
                      'looks like "mm/s^2" or "mg"'),
    "acc in mg with gravity": (_csv("acc", lambda fr: fr.__setitem__("acc", fr["acc"] / G * 1000 + 1000)), "accel_S2.csv",
                               'looks like mg including gravity'),
    "wind in km/h": (_csv("u", lambda fr: [fr.__setitem__(c, fr[c] * 3.6 * 3) for c in ("u", "v")]), "wind_S2.csv",
                     'looks like "km/h" or "knots"'),
}


@pytest.mark.parametrize("kind", sorted(BAD))
def test_bad_input_is_one_line_naming_the_file(csv_dir, tmp_path, capsys, kind):
    edit, file, words = BAD[kind]
    d = tmp_path / "in"
    _copy(csv_dir, d)
    edit(d)
    out = tmp_path / "out" / "F.nc"
    assert main(["import", str(d / "mapping.toml"), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("vivbench import: "), err
    assert file in err and words in err, err
    assert not out.exists() and not (out.parent.exists() and any(out.parent.iterdir()))


def test_mat_refuses_iso_times_and_matrix_without_index(short_event, tmp_path):
    mapping = export_mat(short_event, tmp_path)
    text = mapping.read_text()
    mapping.write_text(text.replace('u = { column = "u", index = 1 }', 'u = "u"', 1))
    with pytest.raises(ValueError, match=r"event\.mat: variable 'u' has shape \(\d+, 3\); give index"):
        import_event(mapping)
    mapping.write_text(text.replace('units = "m/s"', 'units = "m/s"\ntime_format = "iso8601"'))
    with pytest.raises(ValueError, match="ISO 8601 times are read from CSV only"):
        import_event(mapping)


def test_iso_times_give_the_default_start(short_event, tmp_path):
    mapping = export_csv(short_event, tmp_path, time_format="iso8601")
    text = mapping.read_text()
    mapping.write_text(re.sub(r"start_time = .*\n", "", text))
    m = load_mapping(mapping)
    assert m["start_time"] is None
    tree = import_event(mapping)
    assert tree.attrs["start_time"] == short_event.attrs["start_time"]
    _same(event_arrays(tree), event_arrays(short_event), exact=False)
