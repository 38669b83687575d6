"""``vivbench leaderboard`` end to end on a tiny scenario: cells, resume after a stop, versions, workers, report."""

from __future__ import annotations

import csv
import dataclasses
import io
import json
import os
import shutil
import sys
import textwrap
import time

import pytest

from vivbench.cli import main
from vivbench.core.errors import InputError
from vivbench.validate import LEADERBOARD_COLUMNS, load_scenario_file, method_slug, run_leaderboard

# A method defined outside the package, as a user writes it: linearly damped dynamics (regime 1
# everywhere), no verdict. Every fit is logged to $LBPLUG_LOG; $LBPLUG_FAIL makes fit fail.
PLUGIN = textwrap.dedent('''
    import os
    import numpy as np

    class _Damped:
        def order_contributions(self, record):
            r = np.zeros(record.A.shape + (4,))
            r[..., 1] = -0.01 * record.A
            return r

    class LinearDamping:
        def fit(self, records):
            with open(os.environ["LBPLUG_LOG"], "a") as fh:
                fh.write("fit\\n")
            if os.environ.get("LBPLUG_FAIL"):
                raise RuntimeError("asked to fail")
            return _Damped()

    def linear_damping():
        return LinearDamping()
''')

SCENARIO = textwrap.dedent('''
    [scenario.tiny]
    version = {version}
    description = "one 4-min event of the default bridge (test size)"
    events = 1
    duration = 240.0
    seed = 1
    [scenario.tiny.generator]
    mode = "realistic"
''')

METHODS = "windows,lbplug:linear_damping"
TIME = LEADERBOARD_COLUMNS.index("fit_time_s")


@pytest.fixture(scope="module")
def plugin(tmp_path_factory):
    """The plug-in module on sys.path (and PYTHONPATH, for worker processes); its fit log."""
    d = tmp_path_factory.mktemp("plugin")
    (d / "lbplug.py").write_text(PLUGIN)
    log = d / "fits.log"
    mp = pytest.MonkeyPatch()
    mp.syspath_prepend(str(d))
    mp.setenv("PYTHONPATH", os.pathsep.join([str(d), *filter(None, [os.environ.get("PYTHONPATH")])]))
    mp.setenv("LBPLUG_LOG", str(log))
    yield log
    mp.undo()
    sys.modules.pop("lbplug", None)


def _scenario_file(path, version=1):
    path.write_text(SCENARIO.format(version=version))
    return path


def _cli(out, scenario_file, *extra):
    return main(["leaderboard", "--methods", METHODS, "--scenario-file", str(scenario_file), "--out", str(out),
                 "--workers", "1", *extra])


def _without_time(text: str) -> list[list[str]]:
    rows = list(csv.reader(io.StringIO(text)))
    return [r[:TIME] + r[TIME + 1:] for r in rows]


def _cell_without_time(path) -> dict:
    body = json.loads(path.read_text())
    body["scores"].pop("fit_time_s")
    return body


_REFERENCE_WALL_S: list[float] = []  # wall time of the reference run, s (bounds the fit times it records)


@pytest.fixture(scope="module")
def reference(plugin, tmp_path_factory):
    """An uninterrupted CLI run: (output directory, scenario file)."""
    d = tmp_path_factory.mktemp("lb_ref")
    sfile = _scenario_file(d / "tiny.toml")
    start = time.perf_counter()
    assert _cli(d / "out", sfile) == 0
    _REFERENCE_WALL_S.append(time.perf_counter() - start)
    return d / "out", sfile


def test_outputs(reference):
    out, _ = reference
    rows = list(csv.DictReader((out / "leaderboard.csv").open()))
    assert [(r["scenario"], r["method"]) for r in rows] == [("tiny", "windows"), ("tiny", "lbplug:linear_damping")]
    assert tuple(rows[0]) == LEADERBOARD_COLUMNS
    win, plug = rows
    assert (win["has_verdict"], plug["has_verdict"]) == ("True", "False")
    assert float(plug["coverage"]) == 0.0 and plug["accuracy_flagged"] == "nan"
    for r in rows:
        assert r["error"] == ""
        assert 0.0 <= float(r["accuracy_all"]) <= 1.0
        assert 0.0 < float(r["fit_time_s"]) < _REFERENCE_WALL_S[-1]  # measured, and within the run that fitted it
        assert float(r["rhs_error_true_AU"]) > 0.0
    assert plug["forecast_nmse"] == "nan"  # no simulate
    md = (out / "leaderboard.md").read_text()
    assert "| tiny v1 | " in md and "0 (no verdict)" in md and "n/a (no verdict)" in md
    assert "![Leaderboard heat maps](leaderboard.png)" in md
    assert (out / "leaderboard.png").read_bytes()[:4] == b"\x89PNG"
    assert (out / "command.txt").read_text().startswith("vivbench leaderboard --methods")
    rec = json.loads((out / "scenarios" / "tiny" / "scenario.json").read_text())
    assert rec["scenario"]["version"] == 1 and len(rec["fingerprint"]) == 64


def test_stopped_run_resumes_without_recomputing_finished_cells(reference, plugin, tmp_path, capsys):
    ref_out, sfile = reference
    out = tmp_path / "out"
    # The reference's campaign and identification, reused (same scenario record): only cells run here.
    shutil.copytree(ref_out / "scenarios", out / "scenarios")
    scenarios = list(load_scenario_file(sfile).values())
    seen = []

    def stop_after_first_cell(kind, scenario, method):
        if kind == "cell":
            seen.append(method)
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        run_leaderboard(METHODS.split(","), scenarios, out, progress=stop_after_first_cell)
    cells = sorted((out / "cells" / "tiny").iterdir())
    assert [c.name for c in cells] == [f"{method_slug('windows')}.json"] and seen == ["windows"]
    first = cells[0]
    before = (first.read_bytes(), first.stat().st_mtime_ns)
    event = out / "scenarios" / "tiny" / "campaign" / "E001.nc"
    event_mtime = event.stat().st_mtime_ns

    # The plug-in fails: one line for that cell, exit 1, the finished cell stays as it was.
    os.environ["LBPLUG_FAIL"] = "1"
    try:
        capsys.readouterr()
        assert _cli(out, sfile) == 1
    finally:
        del os.environ["LBPLUG_FAIL"]
    err = [line for line in capsys.readouterr().err.splitlines() if line.startswith("vivbench leaderboard:")]
    assert err == ["vivbench leaderboard: cell tiny / lbplug:linear_damping: RuntimeError: asked to fail"]
    assert "asked to fail" in (out / "leaderboard.csv").read_text()

    n_fits = plugin.read_text().count("fit")
    assert _cli(out, sfile) == 0
    assert "1 resumed" in capsys.readouterr().out
    assert plugin.read_text().count("fit") == n_fits + 1  # only the unfinished cell was fitted
    assert (first.read_bytes(), first.stat().st_mtime_ns) == before  # not recomputed, not rewritten
    assert event.stat().st_mtime_ns == event_mtime  # the scenario's campaign was reused
    # The same table as the uninterrupted run (fit times aside: wall clock).
    assert _without_time((out / "leaderboard.csv").read_text()) == _without_time(
        (ref_out / "leaderboard.csv").read_text())
    for m in METHODS.split(","):
        name = f"{method_slug(m)}.json"
        assert _cell_without_time(out / "cells" / "tiny" / name) == _cell_without_time(
            ref_out / "cells" / "tiny" / name)


def test_a_new_scenario_version_regenerates_its_campaign_and_cells(reference, plugin, tmp_path):
    ref_out, _ = reference
    out = tmp_path / "out"
    shutil.copytree(ref_out, out)
    scenarios = list(load_scenario_file(_scenario_file(tmp_path / "v1.toml", 1)).values())
    same = run_leaderboard(METHODS.split(","), scenarios, out)
    assert same.prepared == () and same.computed == () and len(same.resumed) == 2
    reworded = [dataclasses.replace(scenarios[0], description="other words, same campaign")]
    assert run_leaderboard(METHODS.split(","), reworded, out).prepared == ()
    assert "other words" in (out / "scenarios" / "tiny" / "scenario.json").read_text()
    again = run_leaderboard(METHODS.split(","), scenarios, out, rerun=["lbplug:linear_damping"])
    assert again.computed == (("tiny", "lbplug:linear_damping"),) and again.resumed == (("tiny", "windows"),)
    with pytest.raises(InputError, match="rerun names methods that are not run: pooled"):
        run_leaderboard(METHODS.split(","), scenarios, out, rerun=["pooled"])
    bumped = list(load_scenario_file(_scenario_file(tmp_path / "v2.toml", 2)).values())
    new = run_leaderboard(METHODS.split(","), bumped, out)
    assert new.prepared == ("tiny",) and new.resumed == () and len(new.computed) == 2
    assert json.loads((out / "scenarios" / "tiny" / "scenario.json").read_text())["scenario"]["version"] == 2
    rows = list(csv.DictReader((out / "leaderboard.csv").open()))
    assert {r["scenario_version"] for r in rows} == {"2"}
    # same campaign content under a new version: the same scores
    assert _without_time((out / "leaderboard.csv").read_text().replace("tiny,2,", "tiny,1,")) == _without_time(
        (ref_out / "leaderboard.csv").read_text())


@pytest.mark.slow
@pytest.mark.parametrize("where", [["--workers", "2"], ["--scheduler", "local:2"]], ids=["processes", "dask"])
def test_two_workers_or_dask_give_the_same_table(reference, tmp_path, where):
    if where[0] == "--scheduler":
        pytest.importorskip("dask.distributed")
    ref_out, sfile = reference
    assert _cli(tmp_path / "out", sfile, *where) == 0
    assert _without_time((tmp_path / "out" / "leaderboard.csv").read_text()) == _without_time(
        (ref_out / "leaderboard.csv").read_text())


def test_bad_method_and_scenario_exit_2(tmp_path, capsys):
    assert main(["leaderboard", "--methods", "windows,windows", "--out", str(tmp_path)]) == 2
    assert "named twice" in capsys.readouterr().err
    assert main(["leaderboard", "--methods", "windows", "--scenarios", "nope", "--out", str(tmp_path)]) == 2
    assert "unknown scenario(s) nope" in capsys.readouterr().err


def test_report_section(reference, tmp_path):
    from vivbench.report import EXTRA_STEPS, leaderboard_section

    assert "leaderboard" in EXTRA_STEPS  # `vivbench report --leaderboard DIR`
    out, _ = reference
    written = []
    lines = leaderboard_section(out, tmp_path, written)
    text = "\n".join(lines)
    assert lines[0].startswith("## Leaderboard")
    assert "vivbench leaderboard --methods windows,lbplug:linear_damping" in text
    assert "| tiny v1 | " in text and "one 4-min event" in text  # table and scenario legend
    assert written == ["leaderboard_heatmaps.png"] and (tmp_path / written[0]).is_file()
    assert "Not run" in leaderboard_section(None, tmp_path, [])[2]


@pytest.mark.slow
def test_report_cli_embeds_the_leaderboard(reference, tmp_path):
    out, _ = reference
    scen = out / "scenarios" / "tiny"
    assert main(["report", "--campaign", str(scen / "campaign"), "--results", str(scen / "identify"), "--name", "lb",
                 "--out-root", str(tmp_path), "--leaderboard", str(out)]) == 0
    text = (tmp_path / "lb" / "report.md").read_text()
    assert "## Leaderboard: methods on the scenario suite" in text and "--leaderboard " in text
    assert "![Leaderboard heat maps](leaderboard_heatmaps.png)" in text
    assert (tmp_path / "lb" / "leaderboard_heatmaps.png").is_file()


def test_a_table_written_before_the_energy_weighted_scores_reads_with_nan_there(tmp_path):
    import math

    from vivbench.validate.leaderboard_table import LEADERBOARD_COLUMNS, leaderboard_markdown, read_leaderboard

    old = [c for c in LEADERBOARD_COLUMNS if c not in ("rhs_error_true_AU_energy", "curve_error_energy")]
    values = {"scenario": "realistic", "scenario_version": "1", "in_class": "False", "method": "binned",
              "has_verdict": "False", "error": ""}
    row = [values.get(c, "0.25") for c in old]
    (tmp_path / "leaderboard.csv").write_text(",".join(old) + "\n" + ",".join(row) + "\n")
    (r,) = read_leaderboard(tmp_path)
    assert r["rhs_error_true_AU"] == 0.25 and math.isnan(r["rhs_error_true_AU_energy"])
    assert math.isnan(r["curve_error_energy"])
    assert "| realistic v1 | n/a |" in leaderboard_markdown([r])


def test_family_draws_as_scenarios_are_the_family_campaigns(tmp_path, capsys):
    from vivbench.synth import draw_bridge
    from vivbench.synth.config import config_to_dict
    from vivbench.validate import family_scenarios

    scns = family_scenarios("evaluation", [0, 3])
    assert [s.name for s in scns] == ["evaluation_000", "evaluation_003"]
    for s, i in zip(scns, (0, 3)):
        d = draw_bridge("evaluation", i)
        assert (s.n_events, s.duration, s.seed) == (d.n_events, tuple(d.duration), d.campaign_seed)
        assert s.generator == json.loads(json.dumps(config_to_dict(d.config)))
        assert not s.in_class
    # development and evaluation draws of one number are different bridges
    assert family_scenarios("development", [0])[0].seed != scns[0].seed
    assert main(["leaderboard", "--methods", "binned", "--family", "evaluation", "--out", str(tmp_path)]) == 2
    assert "--family needs --draws" in capsys.readouterr().err
    assert main(["leaderboard", "--methods", "binned", "--family", "evaluation", "--draws", "0",
                 "--scenarios", "realistic", "--out", str(tmp_path)]) == 2
