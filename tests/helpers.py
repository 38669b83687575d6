"""The shared tolerance helper: every test compares numbers through it.

A tolerance looser than the defaults must come with a ``reason`` saying why
(noise level, record length, discretisation), so that loosening is deliberate.
"""

from __future__ import annotations

import numpy as np

DEFAULT_RTOL = 1e-9
DEFAULT_ATOL = 0.0


def assert_close(actual, desired, *, rtol: float = DEFAULT_RTOL, atol: float = DEFAULT_ATOL, reason: str | None = None, what: str = "") -> None:
    """``numpy.testing.assert_allclose`` with a mandatory reason for loose tolerances."""
    if (rtol > DEFAULT_RTOL or atol > DEFAULT_ATOL) and not reason:
        raise AssertionError("a tolerance looser than the default needs a reason")
    np.testing.assert_allclose(actual, desired, rtol=rtol, atol=atol, err_msg=f"{what} (tolerance: {reason or 'default'})")


def relative_rms(actual, desired) -> float:
    """RMS of the difference relative to the RMS of ``desired``."""
    actual = np.asarray(actual, dtype=float)
    desired = np.asarray(desired, dtype=float)
    return float(np.sqrt(np.mean((actual - desired) ** 2)) / np.sqrt(np.mean(desired**2)))
