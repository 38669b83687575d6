"""Figures and reports."""

from vivbench.report.event_figure import event_figure
from vivbench.report.figures import (
    DPI,
    REGIME_COLOURS,
    coefficient_map_figure,
    decision_graph_figure,
    displacement_figure,
    forecast_figure,
    model_forecast_figure,
    regime_timeline_figure,
    sensor_layout_figure,
    term_scale,
    time_frequency_figure,
    wind_figure,
)
from vivbench.report.figure_sections import ReportFigures, campaign_model_figures, paper_figures
from vivbench.report.figure_style import SECTION_COLOURS, count_word, figure_file, section_index
from vivbench.report.forecast_figures import curves_figure
from vivbench.report.greybox import (greybox_curves_figure, greybox_functions_figure, greybox_section,
                                     greybox_simulation_figure, greybox_yaw_figure)
from vivbench.report.headline import (HEADLINE_BEGIN, HEADLINE_END, HEADLINE_ROWS, HEADLINE_SECTION, headline_table,
                                      readme_with_headline)
from vivbench.report.leaderboard import LEADERBOARD_TITLE, leaderboard_section
from vivbench.report.markdown import EXTRA_STEPS, write_report
from vivbench.report.pair_figures import PAIR_COLOURS, recovery_pair_figure
from vivbench.report.tables import md_cell, md_table, produced_by
from vivbench.report.twin import twin_section
from vivbench.report.sidebyside import MODE_LABELS, CampaignRun, baseline_section, campaign_run, inverse_crime_paragraph

__all__ = [
    "CampaignRun", "DPI", "EXTRA_STEPS", "LEADERBOARD_TITLE", "MODE_LABELS", "PAIR_COLOURS", "baseline_section", "campaign_run",
    "inverse_crime_paragraph", "leaderboard_section", "recovery_pair_figure", "REGIME_COLOURS", "coefficient_map_figure", "decision_graph_figure", "displacement_figure",
    "event_figure", "forecast_figure", "model_forecast_figure", "regime_timeline_figure", "sensor_layout_figure", "term_scale",
    "time_frequency_figure", "wind_figure", "write_report", "greybox_curves_figure", "greybox_functions_figure",
    "greybox_section", "greybox_simulation_figure", "greybox_yaw_figure", "HEADLINE_BEGIN", "HEADLINE_END", "HEADLINE_ROWS",
    "HEADLINE_SECTION", "headline_table", "readme_with_headline", "SECTION_COLOURS", "count_word", "figure_file",
    "section_index", "curves_figure", "ReportFigures", "campaign_model_figures", "paper_figures", "md_cell", "md_table",
    "produced_by", "twin_section",
]
