"""Field import of many files per sensor (a glob or a list), concatenated in time order."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from tests.helpers import assert_close
from vivbench.cli import main
from vivbench.io import event_arrays, export_csv
from vivbench.io.fieldimport import import_event


def _split(path, parts, *, overlap_rows: int = 0):
    """Cut a CSV into ``parts`` files (``<stem>_<k>.csv``, the last written first) and delete it."""
    frame = pd.read_csv(path)
    edges = np.linspace(0, len(frame), parts + 1).astype(int)
    names = []
    for k in reversed(range(parts)):
        name = f"{path.stem}_{k}.csv"
        frame.iloc[max(edges[k] - (overlap_rows if k else 0), 0):edges[k + 1]].to_csv(path.parent / name, index=False)
        names.append(name)
    path.unlink()
    return names


def _edit(mapping, old, new):
    text = mapping.read_text()
    assert old in text
    mapping.write_text(text.replace(old, new, 1))


def test_daily_files_by_glob_and_list_import_like_one_file(short_event, tmp_path):
    mapping = export_csv(short_event, tmp_path, time_format="iso8601")
    _split(tmp_path / "wind_S1.csv", 3)
    names = _split(tmp_path / "accel_S2.csv", 4)  # listed out of time order
    _edit(mapping, 'file = "wind_S1.csv"', 'file = "wind_S1_*.csv"')
    _edit(mapping, 'file = "accel_S2.csv"', f"file = {names!r}".replace("'", '"'))
    tree = import_event(mapping)
    a, b = event_arrays(tree), event_arrays(short_event)
    for k in ("u", "v", "w", "acc"):
        np.testing.assert_array_equal(a[k], b[k], err_msg=k)
    for k in ("wind_time", "accel_time"):
        assert_close(a[k], b[k], rtol=0, atol=1e-6, reason="ISO 8601 stamps carry microseconds", what=k)
    assert "wind_S1_2.csv" in tree.attrs["import_sources"] and "accel_S2_3.csv" in tree.attrs["import_sources"]


@pytest.mark.parametrize("case, words", [
    ("overlap", "wind_S1_0.csv, /"),
    ("overlap", "wind_S1_1.csv: the files overlap in time (wind_S1_1.csv starts before wind_S1_0.csv ends)"),
    ("no match", "[wind.S1] u: the file pattern 'wind_X_*.csv' matches no file"),
    ("twice", "names a file twice"),
])
def test_bad_file_sets_are_one_line(short_event, tmp_path, capsys, case, words):
    mapping = export_csv(short_event, tmp_path)
    _split(tmp_path / "wind_S1.csv", 3, overlap_rows=5 if case == "overlap" else 0)
    pattern = {"overlap": "wind_S1_*.csv", "no match": "wind_X_*.csv"}.get(case)
    new = f'file = "{pattern}"' if pattern else 'file = ["wind_S1_*.csv", "wind_S1_0.csv"]'
    _edit(mapping, 'file = "wind_S1.csv"', new)
    out = tmp_path / "o" / "F.nc"
    assert main(["import", str(mapping), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and words in err, err
    assert not out.exists()
