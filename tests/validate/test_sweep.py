"""Monte-Carlo recovery sweeps: configuration, determinism across backends, resume after a stop."""

from __future__ import annotations

import json
import logging
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from vivbench.core.parallel import run_tasks
from vivbench.validate import (
    METRIC_COLUMNS,
    SweepConfig,
    load_sweep_config,
    run_sweep,
    sweep_config_from_dict,
    sweep_tasks,
)
from vivbench.validate import sweep as sweep_module
from tests.helpers import REPO, assert_close


# Two campaigns of one 200 s event (two windows each): the smallest sweep that
# still has a grid axis and a range (one event: the pooled campaign model, the varying one needs two).
TINY = {
    "campaign_model": "pooled",
    "seed": 5,
    "n_campaigns": 1,
    "n_events": 1,
    "duration": [200.0, 200.0],
    "grid": {"noise_density": [30.0, 300.0]},
    "ranges": {"turbulence_intensity": [0.04, 0.12]},
}


@pytest.fixture(scope="module")
def tiny_config():
    return sweep_config_from_dict(TINY)


@pytest.fixture(scope="module")
def reference(tiny_config, tmp_path_factory):
    """The tiny sweep, uninterrupted, in this process, with its files kept."""
    out = tmp_path_factory.mktemp("sweep_ref")
    result = run_sweep(tiny_config, out, workers=1, keep_files=True)
    assert not result.failures, result.failures
    return out, result


@pytest.fixture(scope="module")
def dask_address():
    """One LocalCluster, two worker processes on loopback, shared by the dask tests."""
    distributed = pytest.importorskip("dask.distributed")
    cluster = distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, host="127.0.0.1",
                                       dashboard_address=None, silence_logs=logging.CRITICAL)
    try:
        yield cluster.scheduler_address
    finally:
        cluster.close()


def _files(out: Path) -> dict[str, bytes]:
    """Kept event and identification files, keyed by their path below OUT/files."""
    base = out / "files"
    return {str(p.relative_to(base)): p.read_bytes() for p in sorted(base.rglob("*.nc"))}


# ---------------------------------------------------------------- configuration


def test_tasks_carry_their_own_seeds(tiny_config):
    tasks = sweep_tasks(tiny_config)
    assert [t.task_id for t in tasks] == [0, 1]
    assert [dict(t.params)["noise_density"] for t in tasks] == [30.0, 300.0]
    # Replicate r has the same campaign at every grid point (common random numbers) ...
    assert tasks[0].campaign_seed == tasks[1].campaign_seed
    # ... but each task draws its own range values, always the same ones.
    ti = [dict(t.params)["turbulence_intensity"] for t in tasks]
    assert ti[0] != ti[1] and all(0.04 <= v <= 0.12 for v in ti)
    assert [t.campaign.generator.wind.turbulence.intensity for t in tasks] == ti
    again = sweep_tasks(sweep_config_from_dict(TINY))
    assert [(t.campaign_seed, t.params) for t in again] == [(t.campaign_seed, t.params) for t in tasks]
    other = sweep_tasks(sweep_config_from_dict({**TINY, "seed": 6}))
    assert other[0].campaign_seed != tasks[0].campaign_seed
    explicit = sweep_tasks(sweep_config_from_dict({**TINY, "n_campaigns": None, "seeds": [3, 9]}))
    assert [t.campaign_seed for t in explicit] == [3, 9, 3, 9]


def test_parameters_reach_the_generator():
    cfg = sweep_config_from_dict({"duration": [240.0, 240.0], "grid": {"y1_peak": [10.0], "damping_ratio": [0.004]},
                                  "ranges": {"anemometer_noise": [0.02, 0.02]}})
    (task,) = sweep_tasks(cfg)
    gen = task.campaign.generator
    base = SweepConfig().generator
    # Y1 is scaled as a whole: half the default peak (20), same zero crossings (the realistic default's bell).
    U = np.linspace(2.0, 16.0, 57)
    assert_close(gen.aero.Y1.at_wind(U, 0.327, 3.5), base.aero.Y1.at_wind(U, 0.327, 3.5) / 2, rtol=1e-12)
    assert gen.structure.damping_ratio == 0.004 and gen.wind.noise == 0.02
    assert gen.sensors == base.sensors and gen.wind.turbulence == base.wind.turbulence
    assert cfg.varied == ()


@pytest.mark.parametrize("change, message", [
    ({"grid": {"noise_level": [1.0]}}, "unknown parameter 'noise_level'"),
    ({"grid": {"noise_density": []}}, "needs at least one value"),
    ({"grid": {"noise_density": [-1.0]}}, "noise_density = -1.0: noise_density must be >= 0"),
    ({"ranges": {"turbulence_intensity": [0.1, 0.7]}}, "intensity (sigma_u / U) must be in [0, 0.5)"),
    ({"ranges": {"damping_ratio": [0.01, 0.001]}}, "must be [low, high] with low <= high"),
    ({"ranges": {"noise_density": [1.0, 2.0]}}, "in both [grid] and [ranges]"),
    ({"duration": [150.0, 150.0]}, "the shortest event must be longer than 180 s"),
    ({"seeds": [1, 1], "n_campaigns": None}, "seeds must be distinct"),
    ({"seeds": [1, 2], "n_campaigns": 3}, "disagrees with the 2 seeds"),
    ({"n_campaigns": 0}, "n_campaigns (campaigns per grid point) must be"),
    ({"n_events": 2.5}, "n_events (events per campaign) must be an integer"),
    ({"grid": {"noise_density": list(range(1000)), "damping_ratio": [i / 1e4 for i in range(200)]}},
     "the sweep has 200000 campaigns"),
    ({"identify": {"window": -5.0}}, "[identify]: window and step must be positive"),
    ({"identify": {"windw": 5.0}}, "unknown keys ['windw'] in [identify]"),
    ({"generator": {"sensors": {"nois": 1}}}, "[generator]: unknown keys ['nois'] in [sensors]"),
    ({"grid": {"noise_density": ["loud"]}}, "[grid] noise_density value must be a number"),
    ({"stride": 3}, "unknown keys ['stride']"),
    ({"campaign_model": "sindy"}, "campaign_model must be one of varying, pooled; got 'sindy'"),
    ({"campaign_model": "varying"}, 'campaign_model "varying" needs n_events >= 2'),
])
def test_config_errors_say_what_is_wrong(change, message):
    with pytest.raises(ValueError) as info:
        sweep_config_from_dict({**TINY, **change})
    assert message in str(info.value)


def test_campaign_model_is_part_of_the_sweep(tiny_config):
    """The campaign model behind the pooled_* columns is the pool default unless named, and names a different sweep."""
    assert tiny_config.campaign_model == "pooled" and tiny_config.to_dict()["campaign_model"] == "pooled"
    varying = sweep_config_from_dict({**{k: v for k, v in TINY.items() if k != "campaign_model"}, "n_events": 2})
    assert varying.campaign_model == "varying" and varying.fingerprint() != tiny_config.fingerprint()
    assert {t.campaign_model for t in sweep_tasks(varying)} == {"varying"}


def test_varying_campaign_model_scores_a_campaign(tmp_path):
    """The default campaign model (varying) is fitted and scored on a two-event campaign: finite pooled_* columns."""
    cfg = sweep_config_from_dict({**{k: v for k, v in TINY.items() if k not in ("campaign_model", "grid")},
                                  "n_events": 2})
    result = run_sweep(cfg, tmp_path / "v", workers=1, keep_files=True)
    assert not result.failures, result.failures
    header, row = (line.split(",") for line in result.table.read_text().splitlines())
    row = dict(zip(header, row))
    assert np.isfinite(float(row["campaign_model_rhs_error_true_AU_median_active"])), row
    assert 0.0 <= float(row["campaign_model_coverage"]) <= 1.0
    assert any(p.name == "campaign.model.nc" for p in (tmp_path / "v" / "files").rglob("*.nc"))


def test_example_grid_loads_and_bad_file_is_named(tmp_path):
    cfg = load_sweep_config(REPO / "examples" / "sweep_small.toml")
    assert cfg.n_tasks == 4 and cfg.n_events == 2
    bad = tmp_path / "bad.toml"
    bad.write_text("[grid]\nnoise_density = [30.0, 30.0]\n")
    with pytest.raises(ValueError, match=r"bad\.toml: \[grid\] noise_density values must be distinct"):
        load_sweep_config(bad)


# ------------------------------------------------------------------ determinism


def test_dask_cluster_and_this_process_agree(tiny_config, reference, dask_address, tmp_path):
    """Same table bytes and same event and identification files in this process and on a dask
    cluster of two worker processes; a failing task on dask comes back as an Outcome."""
    ref_out, ref = reference
    table = ref.table.read_bytes()
    files = _files(ref_out)
    # one event, its result, the campaign regimes and the campaign model's file per campaign
    assert len(files) == 8 and sum(name.endswith("campaign.model.nc") for name in files) == 2
    result = run_sweep(tiny_config, tmp_path / "dask", keep_files=True, scheduler=dask_address)
    assert result.table.read_bytes() == table, "dask: table differs from the single-process run"
    assert _files(tmp_path / "dask") == files, "dask: event or identification files differ"
    outcomes = sorted(run_tasks(int, ["1", "x", "3"], scheduler=dask_address), key=lambda o: o.index)
    assert [o.value for o in outcomes] == [1, None, 3]
    assert outcomes[1].error == "ValueError: invalid literal for int() with base 10: 'x'"


@pytest.mark.slow
def test_two_local_processes_agree_with_one(tiny_config, reference, tmp_path):
    ref_out, ref = reference
    result = run_sweep(tiny_config, tmp_path / "p2", keep_files=True, workers=2)
    assert result.table.read_bytes() == ref.table.read_bytes()
    assert _files(tmp_path / "p2") == _files(ref_out)
    assert not (tmp_path / "p2" / ".work").exists()


def test_table_figures_and_summary(reference, tiny_config):
    out, result = reference
    lines = result.table.read_text().splitlines()
    header = lines[0].split(",")
    assert header[:2] == ["task_id", "point"] and set(METRIC_COLUMNS) <= set(header) and header[-1] == "error"
    assert [line.split(",")[0] for line in lines[1:]] == ["0", "1"]
    rows = [dict(zip(header, line.split(","))) for line in lines[1:]]
    assert all(r["error"] == "" and int(r["n_window_equations"]) > 0 for r in rows)
    summary = json.loads(result.summary.read_text())
    assert summary["campaigns_total"] == 2 and summary["campaigns_finished"] == 2
    assert summary["varied_parameters"] == "noise_density,turbulence_intensity"
    expected = float(np.median([float(r["coverage"]) for r in rows]))
    assert_close(summary["median_coverage"], expected, rtol=1e-5, reason="the rows are CSV text with six significant digits")
    for fig in result.figures:
        assert fig.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert [f.name for f in result.figures] == ["recovery_vs_noise.png", "recovery_vs_turbulence.png"]


# ----------------------------------------------------------------------- resume


class _Stop(Exception):
    pass


def test_interrupted_sweep_resumes_without_recomputing(tiny_config, reference, tmp_path):
    _, ref = reference
    out = tmp_path / "run"

    def stop_after_first(done, total):
        if done == 1:
            raise _Stop

    with pytest.raises(_Stop):
        run_sweep(tiny_config, out, workers=1, progress=stop_after_first)
    first = (out / "sweep.jsonl").read_text().splitlines()
    assert len(first) == 1 and json.loads(first[0])["task_id"] == 0
    assert not (out / ".work").exists(), "temporary campaigns left behind by the interrupted run"
    result = run_sweep(tiny_config, out, workers=1)
    assert result.resumed == (0,) and result.computed == (1,)
    assert result.table.read_bytes() == ref.table.read_bytes()
    assert (out / "sweep.jsonl").read_text().splitlines()[0] == first[0]
    # A finished sweep run again computes nothing and changes nothing.
    again = run_sweep(tiny_config, out, workers=1)
    assert again.computed == () and again.table.read_bytes() == ref.table.read_bytes()


@pytest.fixture()
def replay(reference, monkeypatch):
    """Replace the campaign computation by the reference run's journalled metrics.

    The journal and resume logic do not look inside a task; replaying known
    metrics tests them without generating campaigns again. Returns the list of
    task ids the replacement was called for.
    """
    ref_out, _ = reference
    rows = {}
    for line in (ref_out / "sweep.jsonl").read_text().splitlines():
        rec = json.loads(line)
        rows[rec["task_id"]] = {c: rec["row"][c] for c in METRIC_COLUMNS}
    calls = []

    def fake(task):
        calls.append(task.task_id)
        return dict(rows[task.task_id])

    monkeypatch.setattr(sweep_module, "run_sweep_task", fake)
    return calls


def test_half_written_line_is_dropped_and_recomputed(tiny_config, reference, replay, tmp_path):
    ref_out, ref = reference
    out = tmp_path / "cut"
    out.mkdir()
    for name in ("sweep_config.json", "sweep.jsonl"):
        shutil.copy(ref_out / name, out / name)
    journal = out / "sweep.jsonl"
    data = journal.read_bytes()
    last = data.rstrip(b"\n").rfind(b"\n") + 1
    journal.write_bytes(data[: last + (len(data) - last) // 2])  # a kill in the middle of the last line
    result = run_sweep(tiny_config, out, workers=1)
    assert result.repaired_lines == 1 and result.resumed == (0,) and result.computed == (1,) and replay == [1]
    assert result.table.read_bytes() == ref.table.read_bytes()
    assert journal.read_bytes() == data
    # A corrupt line in the middle is dropped too, and only its task is recomputed.
    lines = data.splitlines(keepends=True)
    journal.write_bytes(b"{not json\n" + lines[1])
    result = run_sweep(tiny_config, out, workers=1)
    assert result.repaired_lines == 1 and result.computed == (0,) and replay == [1, 0]
    assert result.table.read_bytes() == ref.table.read_bytes()


def test_failed_task_is_reported_then_retried(tiny_config, reference, replay, tmp_path, monkeypatch):
    _, ref = reference
    replayed = sweep_module.run_sweep_task

    def flaky(task):
        if task.task_id == 1:
            raise RuntimeError("worker lost")
        return replayed(task)

    monkeypatch.setattr(sweep_module, "run_sweep_task", flaky)
    out = tmp_path / "flaky"
    result = run_sweep(tiny_config, out, workers=1)
    assert result.failures == {1: "RuntimeError: worker lost"}
    row = result.table.read_text().splitlines()[2]
    assert row.endswith(",RuntimeError: worker lost") and ",nan," in row
    assert json.loads(result.summary.read_text())["campaigns_failed"] == 1
    monkeypatch.setattr(sweep_module, "run_sweep_task", replayed)
    again = run_sweep(tiny_config, out, workers=1)
    assert again.resumed == (0,) and again.computed == (1,) and not again.failures
    assert again.table.read_bytes() == ref.table.read_bytes()
    assert replay == [0, 1]


def test_other_configuration_in_the_same_directory_is_refused(reference):
    out, _ = reference
    with pytest.raises(ValueError, match="holds the results of a different sweep configuration"):
        run_sweep(sweep_config_from_dict({**TINY, "seed": 99}), out, workers=1)


@pytest.mark.slow
def test_killed_cli_sweep_resumes_to_the_same_table(tmp_path):
    """SIGKILL the CLI once the first campaign is journalled; the rerun finishes the same table."""
    grid = tmp_path / "grid.toml"
    grid.write_text('seed = 5\nn_campaigns = 3\nn_events = 1\nduration = [200.0, 200.0]\ncampaign_model = "pooled"\n'
                    '[grid]\nnoise_density = [30.0]\n')
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    cmd = [sys.executable, "-m", "vivbench.cli", "sweep", "--grid", str(grid), "--workers", "1"]
    out = tmp_path / "killed"
    proc = subprocess.Popen([*cmd, "--out", str(out)], env=env, cwd=REPO,
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    journal = out / "sweep.jsonl"
    deadline = time.monotonic() + 300
    while proc.poll() is None and time.monotonic() < deadline:
        if journal.exists() and journal.read_bytes().count(b"\n") >= 1:
            proc.send_signal(signal.SIGKILL)
            break
        time.sleep(0.05)
    proc.wait(timeout=60)
    n_before = journal.read_bytes().count(b"\n")
    assert 1 <= n_before < 3, "the sweep was not stopped part-way"
    done = subprocess.run([*cmd, "--out", str(out)], env=env, cwd=REPO, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr
    assert f"{3 - n_before} computed" in done.stdout and f"{n_before} resumed" in done.stdout
    clean = subprocess.run([*cmd, "--out", str(tmp_path / "clean"), "--scheduler", "local:2"], env=env, cwd=REPO,
                           capture_output=True, text=True, timeout=600)
    assert clean.returncode == 0, clean.stderr
    assert (out / "sweep.csv").read_bytes() == (tmp_path / "clean" / "sweep.csv").read_bytes()
    assert not (out / ".work").exists()
    # the report cites the exact command of the run that finished the directory
    assert (out / "command.txt").read_text() == f"vivbench sweep --grid {grid} --workers 1 --out {out}\n"


def _sleep_and_mark(path):
    time.sleep(0.2)
    Path(path).touch()
    return path


def test_stopping_early_cancels_queued_local_tasks(tmp_path):
    paths = [str(tmp_path / f"m{i}") for i in range(24)]
    outcomes = run_tasks(_sleep_and_mark, paths, workers=2)
    first = next(outcomes)
    assert first.ok
    outcomes.close()  # what an interrupt of the consumer does
    # The running tasks and the few already handed to the workers finish; the rest never start.
    assert len(list(tmp_path.iterdir())) <= 8


def test_cli_bad_grid_exits_2(tmp_path):
    from vivbench.cli import main

    bad = tmp_path / "g.toml"
    bad.write_text("n_events = 0\n")
    assert main(["sweep", "--grid", str(bad), "--out", str(tmp_path / "o")]) == 2
