"""A confidence set of models from their per-event held-out losses: a one-sided paired test against the best."""

from __future__ import annotations

import numpy as np
from scipy.stats import norm, wilcoxon

__all__ = ["MODEL_SET_TESTS", "confidence_set"]

#: The paired tests of :func:`confidence_set`.
MODEL_SET_TESTS = ("z", "signed_rank")


def confidence_set(loss: np.ndarray, level: float, test: str = "z", *, margin: float = 0.0) -> np.ndarray:
    """Models whose per-event held-out loss is not significantly, or not materially, above the best's.

    Parameters
    ----------
    loss : ndarray, shape (n_models, n_events)
        Per-event held-out losses (any unit, the same for every model).
    level : float
        A one-sided paired test of each model's per-event loss against the
        model with the smallest total, at ``level``, the events as the
        independent units.
    test : {"z", "signed_rank"}
        ``"z"``, the mean difference (z-approximation); ``"signed_rank"``,
        Wilcoxon's signed-rank test of the differences (their ranks, not their
        sizes: one long, energetic event cannot outweigh all the others).
    margin : float, >= 0
        A model whose total loss is at most ``1 + margin`` times the best's is
        kept whatever the test says: over many events a consistent excess of a
        fraction of a per cent is significant, yet says nothing about which model
        is right (0: the test alone).

    Returns
    -------
    ndarray of bool, shape (n_models,)
    """
    if not (np.isfinite(margin) and margin >= 0):
        raise ValueError(f"margin must be a finite number >= 0; got {margin!r}")
    total = loss.sum(axis=1)
    best = int(np.argmin(total))
    within = total <= (1.0 + margin) * total[best] if margin > 0 else np.zeros(loss.shape[0], dtype=bool)
    diff = loss - loss[best]
    n = loss.shape[1]
    if test == "signed_rank":
        keep = np.ones(loss.shape[0], dtype=bool)
        for a in range(loss.shape[0]):
            d = diff[a]
            if a == best or n < 2 or not np.any(d != 0):
                continue
            keep[a] = wilcoxon(d, alternative="greater", zero_method="wilcox").pvalue > 1.0 - level
        return keep | within
    se = diff.std(axis=1, ddof=1) / np.sqrt(max(n, 1)) if n > 1 else np.zeros(loss.shape[0])
    z = norm.ppf(level)
    return (diff.mean(axis=1) <= z * se + 1e-12 * np.abs(loss[best]).mean()) | within
