"""Method factories for ``vivbench leaderboard`` / ``vivbench compare``: the varying model with other settings.

The wind weights and penalty choices side by side on the leaderboard's scenarios::

    PYTHONPATH=benchmarks vivbench leaderboard --out DIR --workers 2 \\
        --methods varying,varying_settings:modal_cv,varying_settings:modal_least,varying_settings:modal_loeo,varying_settings:equal_least

(``DIR`` a copy of ``make demo``'s ``demo/leaderboard`` reuses its scenario campaigns). Each factory returns
:class:`vivbench.validate.CampaignMethod`, the built-in ``"varying"`` method
with other parameters, so the leaderboard scores its verdict too (a bare
model would be scored without one: coverage 0).
"""

from __future__ import annotations

from vivbench.validate import CampaignMethod

#: The settings ``wind_input="additive"`` once had, chosen on the seed-0 default campaign (10 unpenalised
#: B-splines per curve, 15 s of wind smoothing); the package no longer uses them, the studies that measured
#: them (``study_misspecification``, ``study_wind_input_cv``) still can.
SEED0_ADDITIVE_SETTINGS = {"n_basis": (10,), "penalties": (1e-8,), "wind_smoothing_s": 15.0}


def _make(weights: str, choice: str) -> CampaignMethod:
    return CampaignMethod("varying", wind_weights=weights, penalty_choice=choice)


def modal_cv() -> CampaignMethod:
    """Modal weights in the mean wind, the 5-fold penalty."""
    return _make("modal", "cv")


def modal_least() -> CampaignMethod:
    """Modal weights, the least plausible penalty."""
    return _make("modal", "least")


def modal_loeo() -> CampaignMethod:
    """Modal weights, the leave-one-event-out penalty."""
    return _make("modal", "loeo")


def equal_least() -> CampaignMethod:
    """Equal weights (the plain mean), the least plausible penalty."""
    return _make("equal", "least")
