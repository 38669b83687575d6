"""The Markdown report and its figures (vivbench.report)."""

from __future__ import annotations

import csv
import hashlib
import json
import re
from pathlib import Path
from urllib.parse import unquote

import numpy as np
import pytest
import xarray as xr

from vivbench.cli import main
from vivbench.models.simulate import forecast_table
from vivbench.io.netcdf import NETCDF_ENGINE
from vivbench.io.event import read_event
from vivbench.report import EXTRA_STEPS, forecast_figure, sensor_layout_figure, write_report

_LINK = re.compile(r"!?\[[^\]]*\]\(([^)\s]+)\)")


@pytest.fixture(scope="module")
def identified(small_results):
    """The session's small campaign, of which the first two events are identified."""
    campaign, out, written = small_results
    return Path(campaign.files[0]).parent, out, written


@pytest.fixture(scope="module")
def forecast_dir(identified, tmp_path_factory):
    """A step directory with real content: forecast NMSE table, its figure and headline numbers."""
    _campaign, _results, written = identified
    out = tmp_path_factory.mktemp("forecast")
    with xr.open_dataset(written[0], engine=NETCDF_ENGINE) as ds:
        res = ds.load()
    t0 = float(res["window_start"].values[len(res["window_start"]) // 3])
    rows = forecast_table(res, t0, 120.0, ds=(0, 25, 50))
    with open(out / "forecast_E001.csv", "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    forecast_figure(res, out / "forecast_E001.png", t0=t0, horizon=120.0, ds=(0, 25, 50))
    nmse = [r["nmse"] for r in rows if np.isfinite(r["nmse"])]
    (out / "summary.json").write_text(json.dumps({"median_nmse": float(np.median(nmse)) if nmse else None,
                                                  "n_runs": len(rows)}))
    return out, rows


@pytest.fixture(scope="module")
def report(identified, forecast_dir, tmp_path_factory):
    campaign, results, _written = identified
    root = tmp_path_factory.mktemp("reports")
    extra = {"forecast": forecast_dir[0], "validate": root / "does-not-exist"}
    path = write_report("small", campaign, results, out_root=root, extra_dirs=extra, max_rows=5)
    return path, root, campaign, results, extra


def _digests(directory: Path) -> dict[str, str]:
    return {p.name: hashlib.sha256(p.read_bytes()).hexdigest() for p in sorted(directory.iterdir())}


def test_report_links_resolve(report):
    path, root, *_ = report
    assert path == root / "small" / "report.md"
    text = path.read_text()
    links = _LINK.findall(text)
    images = [t for t in links if t.endswith(".png")]
    # the paper's figures plus the copied step figure
    assert len(images) >= 10, images
    for target in links:
        assert not target.startswith(("/", "http")), f"{target}: links must be relative"
        assert (path.parent / unquote(target)).is_file(), f"{target} is linked but missing"
    # the report directory holds exactly what report.md shows
    pngs = {p.name for p in path.parent.glob("*.png")}
    assert pngs == set(images)
    for p in path.parent.glob("*.png"):
        assert p.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_report_sections_and_tables(report, forecast_dir):
    path, _root, campaign, results, _extra = report
    text = path.read_text()
    for step in EXTRA_STEPS:
        assert f"`vivbench {step}`" in text
    # no directory given, and a directory that does not exist: both "not run"
    assert "**Not run**: no `--cluster` directory was given." in text
    assert "**Not run**: the directory" in text and "does-not-exist" in text
    # the step's CSV is embedded, cut at max_rows and said so
    rows = forecast_dir[1]
    assert f"first 5 of {len(rows)} rows" in text
    assert "forecast_forecast_E001.png" in text
    assert "median_nmse" in text
    # events without a result are named, not silently dropped
    identified_ids = {p.name.split(".")[0] for p in Path(results).glob("*.identify.nc")}
    missing = sorted(p.stem for p in Path(campaign).glob("E*.nc") if p.stem not in identified_ids)
    assert missing, "the fixture should leave some events unidentified"
    assert f"**no result for {', '.join(missing)}**" in text
    # recovery table: one row per identified event plus the campaign
    n_events = len(identified_ids)
    recovery = text.split("## Recovery of the truth", 1)[1].split("\n## ", 1)[0]
    assert len(re.findall(r"^\| E\d{3} \|", recovery, flags=re.M)) == 2 * n_events
    assert "| **all** |" in recovery
    # every table is followed by the command that produced it
    blocks = re.split(r"\n\n", text)
    for i, block in enumerate(blocks):
        if block.startswith("| ") and not block.startswith("|---"):
            after = "\n\n".join(blocks[i + 1 : i + 3])
            assert "*Produced by:* `vivbench " in after, f"table without its command: {block[:80]}"
    assert f"--campaign {campaign}" in text and f"--results {results}" in text
    # without --baseline there is no side-by-side section (tests/report/test_side_by_side.py has it)
    assert "## In-library against realistic" not in text and "--baseline" not in text and "sbs_" not in text


def test_report_is_deterministic(report):
    path, root, campaign, results, extra = report
    before = _digests(path.parent)
    write_report("small", campaign, results, out_root=root, extra_dirs=extra, max_rows=5)
    assert _digests(path.parent) == before


def test_report_bad_input(identified, tmp_path):
    campaign, results, _ = identified
    with pytest.raises(ValueError, match="report name"):
        write_report("../x", campaign, results, out_root=tmp_path)
    with pytest.raises(ValueError, match="no such results directory"):
        write_report("x", campaign, tmp_path / "nothing", out_root=tmp_path)
    with pytest.raises(ValueError, match="no identification result"):
        write_report("x", campaign, tmp_path, out_root=tmp_path)
    with pytest.raises(ValueError, match="E999"):
        write_report("x", campaign, results, out_root=tmp_path, events=["E999"])


def test_cli_report_bad_input(identified, tmp_path, capsys):
    campaign, _results, _ = identified
    code = main(["report", "--campaign", str(campaign), "--results", str(tmp_path / "none"), "--name", "x",
                 "--out-root", str(tmp_path)])
    assert code == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("vivbench report: ") and "no such results directory" in err
    assert "\n" not in err


def test_layout_figure_without_truth(small_campaign, tmp_path):
    tree = read_event(small_campaign.files[0])
    field = tree.copy()
    del field["truth"]
    a = sensor_layout_figure(field, tmp_path / "a.png")
    b = sensor_layout_figure(tree, tmp_path / "b.png")
    assert a.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    # the mode shape panel is drawn only when the event carries it
    assert a.read_bytes() != b.read_bytes()
    # no temporary file is left beside the figures
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.png", "b.png"]


def test_curves_figure_draws_the_extrapolated_parts_apart(tmp_path, monkeypatch):
    """The curves past the fitted data's winds are a line of their own, grey dotted, named in the legend."""
    import matplotlib.axes

    from vivbench.models import mark_extrapolated
    from vivbench.report.figures import curves_figure

    wind = np.linspace(5.0, 12.0, 15)
    curves = xr.Dataset({"curves": (("equation", "order", "wind"), np.tile(np.linspace(-1, 1, 15), (1, 4, 1)))},
                        coords={"equation": ["S1"], "order": np.arange(4), "wind": wind})
    labels = []
    plot = matplotlib.axes.Axes.plot

    def spy(self, *args, **kwargs):
        labels.append((kwargs.get("label"), kwargs.get("ls"), args[1] if len(args) > 1 else None))
        return plot(self, *args, **kwargs)

    monkeypatch.setattr(matplotlib.axes.Axes, "plot", spy)
    curves_figure(mark_extrapolated(curves, [[6.0, 10.0]]), tmp_path / "c.png", name="m")
    ext = [y for label, ls, y in labels if label == "m: extrapolated (outside its data's winds)"]
    inside = [y for label, ls, y in labels if label == "m" and ls == "--"]
    assert len(ext) == 4 and len(inside) == 4  # one of each per order
    outside = (wind < 6.0) | (wind > 10.0)
    assert np.isnan(inside[0][outside]).all() and np.isfinite(inside[0][~outside]).all()
    assert np.isfinite(ext[0][outside]).all()
    labels.clear()
    curves_figure(curves, tmp_path / "d.png", name="m")  # unmarked curves: one dashed line, no extrapolated entry
    assert not [1 for label, _ls, _y in labels if label and "extrapolated" in label]
