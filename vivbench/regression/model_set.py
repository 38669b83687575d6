"""A confidence set of models from their per-event held-out losses: a one-sided paired test against the best."""

from __future__ import annotations

import numpy as np
from scipy.stats import norm, wilcoxon

__all__ = ["MODEL_SET_TESTS", "confidence_set"]

#: The paired tests of :func:`confidence_set`.
MODEL_SET_TESTS = ("z", "signed_rank")


def confidence_set(loss: np.ndarray, level: float, test: str = "z") -> np.ndarray:
    """Models whose per-event held-out loss is not significantly above the best's, shape (n_models,) bool.

    ``loss`` (n_models, n_events): a one-sided paired test of each model's
    per-event loss against the model with the smallest total, at ``level``,
    the events as the independent units. ``test``: ``"z"``, the mean
    difference (z-approximation); ``"signed_rank"``, Wilcoxon's signed-rank
    test of the differences (their ranks, not their sizes: one long,
    energetic event cannot outweigh all the others).
    """
    best = int(np.argmin(loss.sum(axis=1)))
    diff = loss - loss[best]
    n = loss.shape[1]
    if test == "signed_rank":
        keep = np.ones(loss.shape[0], dtype=bool)
        for a in range(loss.shape[0]):
            d = diff[a]
            if a == best or n < 2 or not np.any(d != 0):
                continue
            keep[a] = wilcoxon(d, alternative="greater", zero_method="wilcox").pvalue > 1.0 - level
        return keep
    se = diff.std(axis=1, ddof=1) / np.sqrt(max(n, 1)) if n > 1 else np.zeros(loss.shape[0])
    z = norm.ppf(level)
    return diff.mean(axis=1) <= z * se + 1e-12 * np.abs(loss[best]).mean()
