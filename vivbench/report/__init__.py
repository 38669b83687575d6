"""Figures and reports."""

from vivbench.report.event_figure import event_figure

__all__ = ["event_figure"]
