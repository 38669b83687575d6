"""The method comparison: grid validation, designs, and a tiny comparison end to end."""

from __future__ import annotations

import csv
import json

import numpy as np
import pytest

from vivbench.cli import main
from vivbench.validate import CompareConfig, compare_cells, compare_config_from_dict, load_compare_config, plan, run_comparison
from tests.helpers import assert_close


def test_one_at_a_time_design_varies_one_factor_around_the_base():
    cfg = CompareConfig(grid={"optimizer": ["stlsq", "sr3"], "window": [30, 50, 100]}, duration=(600.0, 600.0))
    cells = compare_cells(cfg)
    # base + sr3 + windows 30 and 100 (50 is the base level)
    assert [c["cell_id"] for c in cells] == ["c000", "c001", "c002", "c003"]
    assert [c["varied"] for c in cells] == ["base", "optimizer", "window", "window"]
    for c in cells[1:]:
        diff = [k for k in cfg.base if c[k] != cfg.base[k]]
        assert diff == [c["varied"]], f"{c['cell_id']} must differ from the base in its factor only"
    assert plan(cfg) == (1, 4)


def test_product_design_and_campaign_sharing():
    cfg = CompareConfig(design="product", grid={"scaling": ["scaled", "raw"], "accel_noise": [0.0, 1.0, 2.0]},
                        duration=(600.0, 600.0))
    cells = compare_cells(cfg)
    assert len(cells) == 6
    assert {(c["scaling"], c["accel_noise"]) for c in cells} == {(s, a) for s in ("scaled", "raw") for a in (0.0, 1.0, 2.0)}
    assert plan(cfg) == (3, 6), "identification settings must share a campaign per noise level"


@pytest.mark.parametrize(
    "data, message",
    [
        ({"grid": {}}, "at least one factor"),
        ({"grid": {"optimiser": ["stlsq"]}}, "unknown factors"),
        ({"grid": {"optimizer": ["stlsq", "lasso"]}}, "optimizer level 'lasso' is not one of"),
        ({"grid": {"derivative": "tv"}}, "non-empty list"),
        ({"grid": {"window": [30, 30]}}, "repeated levels"),
        ({"grid": {"window": [-5]}}, "window must be > 0"),
        ({"grid": {"window": [400]}, "campaign": {"duration": [600, 600]}}, "quarter of the shortest event"),
        ({"grid": {"turbulence_intensity": [0.7]}}, "turbulence_intensity must be in"),
        ({"grid": {"accel_noise": [-1]}}, "accel_noise must be >= 0"),
        ({"grid": {"scaling": ["raw"]}, "base": {"scaling": "log"}}, r"\[base\]: scaling level 'log'"),
        ({"grid": {"scaling": ["raw"]}, "design": "latin"}, "design must be one of"),
        ({"grid": {"scaling": ["raw"]}, "campaign": {"events": 0}}, "events must be an integer"),
        ({"grid": {"scaling": ["raw"]}, "campaign": {"runs": 3}}, "unknown keys"),
        ({"grid": {"scaling": ["raw"]}, "colour": "red"}, "unknown keys"),
        ({"design": "product", "max_cells": 10, "campaign": {"duration": [1200, 1200]},
          "grid": {"window": [20, 30, 40], "derivative": ["tv", "savgol", "spline"], "scaling": ["raw", "scaled"]}},
         "18 cells, more than max_cells"),
    ],
)
def test_bad_grids_are_rejected_with_clear_messages(data, message):
    with pytest.raises(ValueError, match=message):
        compare_config_from_dict(data)


def test_grid_file_errors_name_the_file(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text('[grid]\noptimizer = ["stlsq", "sr4"]\n')
    with pytest.raises(ValueError, match="bad.toml: .*sr4"):
        load_compare_config(bad)
    assert main(["compare", "--grid", str(bad), "--out", str(tmp_path / "o")]) == 2
    with pytest.raises(ValueError, match="no such grid file"):
        load_compare_config(tmp_path / "missing.toml")


def _rows(path):
    with open(path, newline="") as fh:
        return list(csv.DictReader(fh))


def test_two_cell_comparison_is_independent_of_workers(tmp_path):
    """One 5-minute event, two cells (scaled and raw library): the table has one row per cell,
    by cell id, and the same numbers with 1 and 2 workers; the second run reuses the campaign."""
    grid = tmp_path / "grid.toml"
    grid.write_text('[campaign]\nevents = 1\nduration = [300.0, 300.0]\nseed = 4\n'
                    '[base]\nwindow = 40.0\n[grid]\nscaling = ["scaled", "raw"]\n')
    cfg = load_compare_config(grid)
    out = tmp_path / "out"
    r1 = run_comparison(cfg, out, workers=1)
    assert not r1.failures, r1.failures
    first = _rows(out / "compare.csv")
    event = next((out / "campaigns" / "k00").glob("E*.nc"))
    mtime = event.stat().st_mtime_ns
    calls = []
    r2 = run_comparison(cfg, out, workers=2, progress=calls.append)
    assert not r2.failures, r2.failures
    assert event.stat().st_mtime_ns == mtime, "the campaign must be reused, not regenerated"
    assert sorted(calls) == ["campaign", "cell", "cell"]
    second = _rows(out / "compare.csv")
    assert [r["cell_id"] for r in first] == ["c000", "c001"]
    assert [r["scaling"] for r in first] == ["scaled", "raw"]
    timing = {"wall_time_s", "wall_time_per_event_s", "cpu_time_s"}
    for a, b in zip(first, second):
        assert {k: v for k, v in a.items() if k not in timing} == {k: v for k, v in b.items() if k not in timing}
    for r in first:
        assert r["error"] == ""
        assert int(r["n_scored"]) > 0
        for k in ("coverage", "accuracy_all", "no_model_share", "truth_majority_share"):
            assert 0.0 <= float(r[k]) <= 1.0, (k, r[k])
        assert float(r["rhs_median_rel_error_active"]) > 0 and float(r["wall_time_s"]) > 0
    assert (out / "compare_scaling.png").stat().st_size > 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["n_cells"] == 2 and summary["n_failed"] == 0
    assert_close(summary["base_accuracy_all"], float(first[0]["accuracy_all"]), rtol=1e-5,
                 reason="the CSV holds six significant digits")
    assert sorted(p.name for p in (out / "cells" / "c001").iterdir()) == ["E001.identify.nc"]


def test_record_command_quotes_the_invocation(tmp_path):
    import argparse

    from vivbench.cli.common import record_command

    record_command(tmp_path, argparse.Namespace(argv=["compare", "--grid", "my grid.toml", "--out", str(tmp_path)]))
    assert (tmp_path / "command.txt").read_text() == f"vivbench compare --grid 'my grid.toml' --out {tmp_path}\n"
    record_command(tmp_path / "missing", argparse.Namespace(argv=["compare"]))   # no directory: nothing written
    assert not (tmp_path / "missing").exists()
