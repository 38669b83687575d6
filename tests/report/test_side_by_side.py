"""The report with a baseline campaign side by side (issue 11 part 4; vivbench.report.sidebyside)."""

from __future__ import annotations

import json
import re
import shutil
from pathlib import Path
from urllib.parse import unquote

import pytest

from vivbench.cli import main
from vivbench.report import CampaignRun, inverse_crime_paragraph, write_report
from vivbench.validate import validate_campaign

_LINK = re.compile(r"!?\[[^\]]*\]\(([^)\s]+)\)")
_SECTION = "## In-library against realistic: the inverse crime, side by side"


def _pooled_copy(results, tmp_path_factory, name) -> Path:
    """The fixture's results copied and pooled (the shared fixture directories stay untouched)."""
    _campaign, results_dir, _written = results
    out = tmp_path_factory.mktemp(name)
    for p in Path(results_dir).glob("*.identify.nc"):
        shutil.copyfile(p, out / p.name)
    assert main(["pool", str(out), "--bootstrap", "10"]) == 0
    return out


@pytest.fixture(scope="module")
def two_runs(small_results, small_results_in_library, tmp_path_factory):
    """(realistic run, in-library run) of the session's small campaigns, two events each, pooled."""
    real = CampaignRun(campaign=Path(small_results[0].files[0]).parent,
                       results=_pooled_copy(small_results, tmp_path_factory, "real_pooled"))
    lib = CampaignRun(campaign=Path(small_results_in_library[0].files[0]).parent,
                      results=_pooled_copy(small_results_in_library, tmp_path_factory, "lib_pooled"))
    return real, lib


@pytest.fixture(scope="module")
def side_by_side(two_runs, tmp_path_factory):
    real, lib = two_runs
    root = tmp_path_factory.mktemp("reports_baseline")
    path = write_report("sbs", real.campaign, real.results, out_root=root, baseline=lib)
    return path, real, lib


def _section(text: str) -> str:
    assert _SECTION in text
    return text.split(_SECTION, 1)[1].split("\n## ", 1)[0]


def test_both_columns_from_their_own_campaign(side_by_side):
    path, real, lib = side_by_side
    section = _section(path.read_text())
    # columns labelled by the generator mode read from the event files, baseline first
    assert "| quantity | in-library, 2 events | realistic, 2 events |" in section
    assert "(the same seed and wind scripts; 2 and 2 events scored)" in section
    assert "in-library (truth inside the model class: the inverse crime)" in section
    assert "realistic (default: truth outside the model class)" in section
    rows = {line.split(" | ")[0].lstrip("| "): line.split(" | ")[1:] for line in section.splitlines()
            if line.startswith("| ")}
    # each column holds its own campaign's scores (validate_campaign on each run)
    s_lib = validate_campaign(lib.campaign, lib.results)["summary"]
    s_real = validate_campaign(real.campaign, real.results)["summary"]
    for label, key in (("window models: regime accuracy, all windows", "regime_accuracy_all"),
                       ("campaign model: regime accuracy, all windows", "campaign_model_regime_accuracy_all"),
                       ("campaign model: median rel. error of dA/dt on the true (A, U), windows with dynamics",
                        "campaign_model_median_rhs_error_true_AU_active")):
        cells = [c.strip(" |") for c in rows[label]]
        assert cells == [f"{s_lib[key]:.3f}", f"{s_real[key]:.3f}"], (label, cells)
    assert s_lib[key] != s_real[key]  # the two campaigns differ: the columns are not copies
    # the exact-matrix error exists only in-library
    cells = [c.strip(" |") for c in rows["window models: median rel. error of dA/dt on the measured (A, U), exact "
                                        "matrix (in-library only)"]]
    assert cells[0] != "n/a" and cells[1] == "n/a"
    # steps not given are said so, not left blank
    assert "not run" in rows["clusters (coef features): number, ARI, purity"][0]
    # the paragraph quotes the measured numbers of both
    assert f"{s_lib['campaign_model_median_rhs_error_true_AU_active']:.3f} in-library against " \
           f"{s_real['campaign_model_median_rhs_error_true_AU_active']:.3f} realistic" in section


def test_paired_figures_and_links(side_by_side):
    path, *_ = side_by_side
    text = path.read_text()
    section = _section(text)
    images = [t for t in _LINK.findall(section) if t.endswith(".png")]
    assert {"sbs_recovery.png", "sbs_curves_1_in_library.png", "sbs_curves_2_realistic.png",
            "sbs_forecast_1_in_library.png", "sbs_forecast_2_realistic.png"} <= set(images), images
    # paired panels: one table row with one figure per campaign
    assert "| ![curves, in-library, 2 events](sbs_curves_1_in_library.png) | " \
           "![curves, realistic, 2 events](sbs_curves_2_realistic.png) |" in section
    for target in _LINK.findall(text):
        assert (path.parent / unquote(target)).is_file(), target
    assert {p.name for p in path.parent.glob("*.png")} == {t for t in _LINK.findall(text) if t.endswith(".png")}
    # every table is followed by the command that produced it
    blocks = re.split(r"\n\n", section)
    for i, block in enumerate(blocks):
        if block.startswith("| "):
            assert "*Produced by:* `vivbench " in "\n\n".join(blocks[i + 1: i + 3]), block[:80]


@pytest.fixture(scope="module")
def identified_real(small_results):
    return Path(small_results[0].files[0]).parent, small_results[1]


def test_bad_baseline_directory(identified_real, tmp_path, capsys):
    campaign, results = identified_real
    with pytest.raises(ValueError, match="must hold campaign/ and identify/"):
        write_report("x", campaign, results, out_root=tmp_path, baseline=tmp_path)
    code = main(["report", "--campaign", str(campaign), "--results", str(results), "--name", "x",
                 "--out-root", str(tmp_path), "--baseline", str(tmp_path / "nothing")])
    assert code == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("vivbench report: ") and "campaign/ and identify/" in err and "\n" not in err


def test_paragraph_without_two_modes_has_no_numbers():
    text = inverse_crime_paragraph(["realistic", "realistic"], [{}, {}])
    assert "inverse crime" in text and "Measured on" not in text
    with_numbers = inverse_crime_paragraph(["in_library", "realistic"],
                                           [{"median_rhs_error_true_AU_active": 0.5, "regime_coverage": 0.0},
                                            {"median_rhs_error_true_AU_active": 1.25, "regime_coverage": 0.0}])
    assert "0.500 in-library against 1.250 realistic" in with_numbers


@pytest.mark.slow
def test_cli_demo_with_baseline(tmp_path):
    """`vivbench demo --baseline in_library` runs both chains and writes the side-by-side report."""
    import subprocess
    import sys

    run = subprocess.run([sys.executable, "-m", "vivbench.cli", "demo", "--out", str(tmp_path), "--events", "2",
                          "--duration", "8", "--workers", "1", "--baseline", "in_library"],
                         capture_output=True, text=True)
    assert run.returncode == 0, run.stderr
    assert "baseline: in-library" in run.stdout
    base = tmp_path / "baseline_in_library"
    for step in ("cluster", "forecast", "validate"):
        assert (base / step / "command.txt").read_text().startswith(f"vivbench {step} ")
    assert not (base / "refit").exists()
    from vivbench.io.event import read_event_summary
    from vivbench.synth import config_from_dict

    meta = json.loads(read_event_summary(base / "campaign" / "E001.nc").truth.attrs["config_json"])
    assert config_from_dict(meta["generator"]).mode == "in_library"
    text = (tmp_path / "reports" / "demo" / "report.md").read_text()
    section = _section(text)
    assert "| quantity | in-library, 2 events | realistic, 2 events |" in section
    assert f"--baseline {base}" in text
    for target in _LINK.findall(text):
        assert (tmp_path / "reports" / "demo" / unquote(target)).is_file(), target
