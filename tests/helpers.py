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


def change_records(n: int = 12, change_at: int | None = None, *, scale: float = 1.0, shift: float = 0.0,
                   seed: int = 0) -> list:
    """Single-section records of dA/dt = a1(U) A - 2 A^3 + noise with a change the wind does not carry.

    a1(U) = -0.01 + 0.05 exp(-((U - 9) / 1.5)^2 / 2) (1/s, U in m/s); from event
    ``change_at`` on, its self-excitation is multiplied by ``scale`` and ``shift``
    (1/s, negative: more damped) is added. ``change_at=None``: no change.
    """
    from vivbench.core import Record

    rng = np.random.default_rng(seed)
    out = []
    for e in range(n):
        t = np.arange(0.0, 900.0, 1.0)
        U = 6.0 + 6.0 * rng.random() + 2.0 * np.sin(2 * np.pi * t / (500 + 60 * e) + e)
        A = 0.05 + 0.1 * rng.random() * (1 + np.sin(2 * np.pi * t / 300 + e))
        changed = change_at is not None and e >= change_at
        a1 = -0.01 + (scale if changed else 1.0) * 0.05 * np.exp(-0.5 * ((U - 9.0) / 1.5) ** 2) + (shift if changed else 0.0)
        dA = a1 * A - 2.0 * A**3 + 2e-4 * rng.standard_normal(t.size)
        out.append(Record(event_id=f"E{e + 1:03d}", t=t, A=A[:, None], U=U[:, None], dA=dA[:, None]))
    return out
