"""Method factories for ``vivbench leaderboard`` / ``vivbench compare``: the varying model with other settings.

The README's table of the wind weights and penalty choices on the leaderboard's
8-event scenarios was made with::

    PYTHONPATH=benchmarks vivbench leaderboard --out DIR --workers 2 \\
        --methods varying,varying_settings:modal_cv,varying_settings:modal_least,varying_settings:modal_loeo,varying_settings:equal_least

(``DIR`` a copy of the reference pipeline's ``demo/leaderboard`` reuses its
scenario campaigns). Methods given as factories have no verdict in the
leaderboard (coverage 0); their dA/dt and curve errors are scored as any.
"""

from __future__ import annotations

from vivbench.models import VaryingCoefficientSINDy


def _make(weights: str, choice: str) -> VaryingCoefficientSINDy:
    return VaryingCoefficientSINDy(wind_weights=weights, penalty_choice=choice)


def modal_cv() -> VaryingCoefficientSINDy:
    """Modal weights in the mean wind, the 5-fold penalty."""
    return _make("modal", "cv")


def modal_least() -> VaryingCoefficientSINDy:
    """Modal weights, the least plausible penalty."""
    return _make("modal", "least")


def modal_loeo() -> VaryingCoefficientSINDy:
    """Modal weights, the leave-one-event-out penalty."""
    return _make("modal", "loeo")


def equal_least() -> VaryingCoefficientSINDy:
    """Equal weights (the plain mean), the least plausible penalty."""
    return _make("equal", "least")
