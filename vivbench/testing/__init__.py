"""Hypothesis strategies and assertion helpers for users' test suites (docs/methods.md).

``from vivbench.testing import strategies as vst`` gives bridges, aerodynamic
curves, wind scripts, events with their truth, campaigns and corruptions;
:func:`assert_recovers` checks that a user's method recovers the truth. See
``docs/testing.md`` for a worked property test.

Needs hypothesis: ``pip install vivbench[testing]``.
"""

try:
    import hypothesis  # noqa: F401
except ImportError as exc:  # pragma: no cover - depends on the environment
    raise ImportError("vivbench.testing needs hypothesis, which is not installed: "
                      "pip install vivbench[testing]") from exc

from vivbench.testing import strategies
from vivbench.testing.assertions import RECORD_SOURCES, assert_recovers, assert_valid_event, event_records
from vivbench.testing.strategies import (
    CORRUPTION_KINDS,
    Corruption,
    aero_curves,
    bridges,
    campaign_configs,
    campaigns,
    corruptions,
    events,
    generators,
    wind_scripts,
)

__all__ = [
    "strategies", "bridges", "aero_curves", "wind_scripts", "generators", "events", "campaign_configs", "campaigns",
    "corruptions", "Corruption", "CORRUPTION_KINDS", "assert_recovers", "assert_valid_event", "event_records",
    "RECORD_SOURCES",
]
