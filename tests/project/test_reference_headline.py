"""The reference report's headline figures are what the chain gives today (slow: ``make test-slow``).

reports/default/report.md was written by ``vivbench demo`` (realistic campaign, 31 events, seed 0,
20-60 min each, the varying campaign model) and ``vivbench report``; the README quotes its table
"Recovery side by side" (``make readme``). This test reruns the steps that the realistic column of
that table comes from, ``synth``, ``identify``, ``pool --model varying`` and ``validate``, with the
demo's settings, and compares the figures with the committed report's. A change of the chain that
moves a headline figure fails here: the reference report (and the README) must then be
regenerated, and the change named.

The demo's other steps (cluster, forecast, refit, grey-box, the in-library baseline) do not enter
these rows and are not rerun. The four steps take about 10 min of wall time on two cores.
"""

from __future__ import annotations

import json

import pytest

from tests.helpers import REPO, assert_close
from vivbench.report import HEADLINE_SECTION, headline_table

REPORT = REPO / "reports" / "default" / "report.md"

#: The demo's campaign (vivbench demo's defaults, as the report's "What was run" states them).
EVENTS, SEED, MINUTES, MODE, MODEL = 31, 0, "20-60", "realistic", "varying"

#: Row of the report's table -> key of ``vivbench validate``'s summary.json.
ROWS = {
    "chance level: share of the most common true regime": "truth_most_common_regime_share",
    "window models: coverage (flagged identifiable)": "regime_coverage",
    "window models: regime accuracy, all windows": "regime_accuracy_all",
    "window models: median rel. error of dA/dt on the true (A, U), windows with dynamics":
        "median_rhs_error_true_AU_active",
    "campaign model: coverage (flagged identifiable)": "campaign_model_regime_coverage",
    "campaign model: regime accuracy, flagged windows": "campaign_model_regime_accuracy_identifiable",
    "campaign model: regime accuracy, all windows": "campaign_model_regime_accuracy_all",
    "campaign model: median rel. error of dA/dt on the true (A, U), windows with dynamics":
        "campaign_model_median_rhs_error_true_AU_active",
    "campaign model: rel. error of dA/dt on the true (A, U), energy-weighted over every sample":
        "campaign_model_energy_rhs_error_true_AU",
    "campaign model: curve error over lock-in, net linear a_k1(U) (rel. RMS)": "campaign_model_curve_error_linear",
}
#: Counts that must be equal.
COUNTS = {"events scored": "n_events", "window-equations scored": "n_window_equations"}


def reference_figures(report_text: str) -> dict[str, str]:
    """The realistic column of the report's headline table, as printed: {row label: cell}."""
    table = headline_table(report_text, rows=(*COUNTS, *ROWS)).splitlines()
    header = [c.strip() for c in table[0].strip().strip("|").split("|")]
    column = next(i for i, name in enumerate(header) if name.startswith(f"{MODE}, "))
    cells = [[c.strip() for c in line.strip().strip("|").split("|")] for line in table[2:]]
    return {row[0]: row[column] for row in cells}


def printed_half_unit(cell: str) -> float:
    """Half a unit of the last digit printed in a cell of fixed-point digits ("0.516" -> 5e-4)."""
    decimals = len(cell.partition(".")[2])
    return 0.5 * 10.0 ** -decimals


def test_reference_figures_are_read_from_the_committed_report():
    """The parser reads the committed table (fast: no chain is run)."""
    text = REPORT.read_text(encoding="utf-8")
    assert HEADLINE_SECTION in text
    ref = reference_figures(text)
    assert ref["events scored"] == str(EVENTS)
    assert set(ROWS) <= set(ref) and all(float(ref[r]) >= 0.0 for r in ROWS)
    assert printed_half_unit("0.516") == 5e-4 and printed_half_unit("207.312") == 5e-4


@pytest.mark.slow
def test_headline_figures_of_the_reference_report_are_reproduced(tmp_path):
    from vivbench.cli import main

    campaign, identify, validate = tmp_path / "campaign", tmp_path / "identify", tmp_path / "validate"
    workers = ["--workers", "2"]
    assert main(["synth", "--events", str(EVENTS), "--seed", str(SEED), "--duration", MINUTES, "--mode", MODE,
                 "--out", str(campaign), *workers]) == 0
    assert main(["identify", str(campaign), "--out", str(identify), *workers]) == 0
    assert main(["pool", str(identify), "--model", MODEL, *workers]) == 0
    assert main(["validate", str(campaign), str(identify), "--out", str(validate)]) == 0
    summary = json.loads((validate / "summary.json").read_text(encoding="utf-8"))

    ref = reference_figures(REPORT.read_text(encoding="utf-8"))
    for label, key in COUNTS.items():
        assert summary[key] == int(ref[label]), label
    for label, key in ROWS.items():
        # The report prints each figure rounded to its digits; the chain is deterministic (same seed,
        # same bytes), so the rerun must round to the same printed value.
        assert_close(summary[key], float(ref[label]), rtol=0.0, atol=printed_half_unit(ref[label]),
                     reason="the committed report rounds to the digits it prints", what=label)
