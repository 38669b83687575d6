"""Names of the chain's optional steps whose output directories a report embeds.

Kept here, below every stage, so the command line can build its parser
without importing the report package (matplotlib, scipy.signal: seconds per
command).
"""

from __future__ import annotations

__all__ = ["EXTRA_STEPS"]

#: ``vivbench <step>`` commands whose ``--out`` directory ``vivbench report`` embeds, in report order.
EXTRA_STEPS = ("cluster", "forecast", "refit", "greybox", "validate", "compare", "sweep", "leaderboard")
