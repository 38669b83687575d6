"""One integrator for every model's simulation: classical fixed-step RK4 on a given time grid, batched.

The models' right-hand sides depend on the wind, which is known at the grid's
samples (and at the steps' midpoints, however the model interpolates it), so
the integrator asks the right-hand side for its value at step ``n`` and stage
0 (the step's start), 1 (its midpoint, used twice) or 2 (its end):

    k1 = f(x, n, 0), k2 = f(x + h k1 / 2, n, 1), k3 = f(x + h k2 / 2, n, 1), k4 = f(x + h k3, n, 2),
    x_{n+1} = x_n + h / 6 (k1 + 2 k2 + 2 k3 + k4).

The state may carry leading batch axes (many trajectories at once, e.g. every
interval of a multiple-shooting grid): each step is one array operation over
the batch, and the only Python loop is over the time steps. A trajectory stops
(:class:`StopRule`) when its state turns non-finite or leaves the rule's
bounds; it is frozen there, the others go on.

The fits that differentiate through the integration (the grey-box's multiple
shooting, :func:`vivbench.models.greybox_shooting.rk4_step_function`) build the
same step as a CasADi expression for its exact Jacobians; their simulations use
this integrator.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

__all__ = ["StopRule", "Integration", "rk4", "NOT_STOPPED", "NON_FINITE", "ABOVE", "BELOW"]

#: Stop codes of :class:`Integration` ``reason``.
NOT_STOPPED, NON_FINITE, ABOVE, BELOW = 0, 1, 2, 3


@dataclass(frozen=True, kw_only=True)
class StopRule:
    """When a trajectory stops: after a step whose state is non-finite, or some ``scale`` x state component
    is above ``upper`` or below ``lower`` (strict inequalities; checked in that order).

    Parameters
    ----------
    upper, lower : float or array_like
        Bounds in the units of ``scale`` x state (default: none); arrays give each trajectory of a batch
        its own bounds (broadcast against the state's leading axes).
    scale : float
        Factor from the integrated state to the units of the bounds (e.g. a model that integrates a
        scaled amplitude and bounds the amplitude in m).
    """

    upper: float | np.ndarray = math.inf
    lower: float | np.ndarray = -math.inf
    scale: float = 1.0

    def __post_init__(self):
        upper, lower = np.asarray(self.upper, dtype=float), np.asarray(self.lower, dtype=float)
        if np.isnan(upper).any() or np.isnan(lower).any() or not np.all(lower <= upper):
            raise ValueError(f"StopRule needs lower <= upper (not NaN); got lower={self.lower}, upper={self.upper}")
        if not (math.isfinite(self.scale) and self.scale > 0):
            raise ValueError(f"StopRule scale must be a finite positive number; got {self.scale!r}")

    def check(self, x: np.ndarray) -> np.ndarray:
        """Stop codes of states x (..., d): shape (...), ``NOT_STOPPED``, ``NON_FINITE``, ``ABOVE`` or ``BELOW``."""
        y = self.scale * x
        upper, lower = np.asarray(self.upper, dtype=float), np.asarray(self.lower, dtype=float)
        if y.size:
            # Every step asks: when the extremes are finite and inside the bounds, nothing stops (a NaN
            # anywhere makes them NaN, an infinite component makes them infinite: the full test below).
            if upper.ndim == 0 and lower.ndim == 0:
                lo, hi = float(y.min()), float(y.max())
                inside = math.isfinite(lo) and math.isfinite(hi) and lo >= lower and hi <= upper
            else:
                lo, hi = y.min(axis=-1), y.max(axis=-1)
                inside = bool(np.isfinite(lo).all() and np.isfinite(hi).all() and np.all(lo >= lower)
                              and np.all(hi <= upper))
            if inside:
                return np.zeros(y.shape[:-1], dtype=np.int64)
        finite = np.all(np.isfinite(x), axis=-1)
        code = np.where(~finite, NON_FINITE, NOT_STOPPED)
        if np.any(upper < math.inf):
            code = np.where((code == NOT_STOPPED) & np.any(y > upper[..., None], axis=-1), ABOVE, code)
        if np.any(lower > -math.inf):
            code = np.where((code == NOT_STOPPED) & np.any(y < lower[..., None], axis=-1), BELOW, code)
        return code


@dataclass(frozen=True)
class Integration:
    """An RK4 run.

    Attributes
    ----------
    x : ndarray, shape (n_times,) + x0.shape
        The state at every time of the grid; NaN from where a trajectory stopped (and after ``n_steps``).
    stop : ndarray of int, shape x0.shape[:-1]
        Index of the first time a trajectory did not reach (-1: it ran through every step).
    reason : ndarray of int, shape x0.shape[:-1]
        Its stop code (``NOT_STOPPED``, ``NON_FINITE``, ``ABOVE``, ``BELOW``).
    """

    x: np.ndarray
    stop: np.ndarray
    reason: np.ndarray


def rk4(rhs: Callable[[np.ndarray, int, int], np.ndarray], x0, t, *, stop: StopRule | None = None,
        n_steps: int | None = None) -> Integration:
    """Integrate dx/dt = rhs by classical RK4 on the time grid ``t``.

    Parameters
    ----------
    rhs : callable
        ``rhs(x, n, stage)`` -> dx/dt, the shape of x (..., d), at step ``n``'s start (stage 0),
        midpoint (1) or end (2).
    x0 : array_like, shape (..., d)
        Initial states (leading axes: a batch of trajectories).
    t : array_like, shape (n_times,) or (n_times,) + x0.shape[:-1], s
        The time grid (its steps need not be equal), or each trajectory's own (a trajectory whose
        grid ends early is padded with NaN: its state turns non-finite there and it stops).
    stop : StopRule, optional
        Default: stop at a non-finite state only.
    n_steps : int, optional
        Steps to take (default all, n_times - 1); the later times stay NaN.

    Returns
    -------
    Integration
    """
    stop = StopRule() if stop is None else stop
    x = np.array(x0, dtype=float)
    if x.ndim == 0:
        raise ValueError("x0 needs a state axis (shape (..., d))")
    t = np.asarray(t, dtype=float)
    n_steps = t.shape[0] - 1 if n_steps is None else min(int(n_steps), t.shape[0] - 1)
    out = np.full((t.shape[0],) + x.shape, np.nan)
    out[0] = x
    batch = x.shape[:-1]
    alive = np.ones(batch, dtype=bool)
    stop_at = np.full(batch, -1, dtype=np.int64)
    reason = np.zeros(batch, dtype=np.int64)
    dt = np.diff(t, axis=0)
    if dt.ndim > 1:  # each trajectory's own steps, against its state's components
        dt = dt[..., None]
    for n in range(max(n_steps, 0)):  # an ODE step needs the previous one: the loop is over time steps
        h = dt[n]
        k1 = rhs(x, n, 0)
        k2 = rhs(x + 0.5 * h * k1, n, 1)
        k3 = rhs(x + 0.5 * h * k2, n, 1)
        k4 = rhs(x + h * k3, n, 2)
        x = x + h / 6.0 * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
        code = stop.check(x)
        ended = alive & (code != NOT_STOPPED)
        if ended.any():
            stop_at[ended], reason[ended] = n + 1, code[ended]
            alive = alive & ~ended
            if not alive.any():
                break
            x = np.where(alive[..., None], x, np.nan)  # frozen: NaN from here on
        out[n + 1] = x
    return Integration(x=out, stop=stop_at, reason=reason)
