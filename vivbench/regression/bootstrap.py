"""The block bootstrap's resampling: how many times each block enters each replicate.

Every block bootstrap of the models draws ``n_blocks`` blocks with replacement
(blocks of ``block_s`` seconds of an event, or whole events) and refits on the
blocks' sufficient statistics weighted by their multiplicities, so a replicate
is one weighted sum, never a resampled copy of the samples. Two draw orders give
the same distribution (multinomial counts with equal probabilities) and differ
only in the random stream a seed yields: ``"multinomial"`` (one multinomial draw
per replicate) and ``"indices"`` (``n_blocks`` uniform block indices per
replicate, counted).
"""

from __future__ import annotations

import numpy as np

__all__ = ["DRAWS", "block_counts"]

#: The draw orders of :func:`block_counts`.
DRAWS = ("multinomial", "indices")


def block_counts(n_blocks: int, n_replicates: int, rng: np.random.Generator, *,
                 draw: str = "multinomial") -> np.ndarray:
    """Multiplicities of ``n_blocks`` blocks drawn with replacement, shape (n_replicates, n_blocks), int.

    Every row sums to ``n_blocks``. ``draw`` chooses the random stream (module docstring).
    """
    if draw not in DRAWS:
        raise ValueError(f"draw must be one of {DRAWS}; got {draw!r}")
    if draw == "multinomial":
        return rng.multinomial(n_blocks, np.full(n_blocks, 1.0 / n_blocks), size=n_replicates)
    draws = rng.integers(0, n_blocks, size=(n_replicates, n_blocks))
    return np.stack([np.bincount(d, minlength=n_blocks) for d in draws]) if n_replicates else np.zeros(
        (0, n_blocks), dtype=np.int64)
