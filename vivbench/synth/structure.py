"""Time integration of the modal equation with a compiled CasADi integrator.

One RK4 step is a CasADi function; ``mapaccum`` chains it over all steps so
that the whole record runs inside CasADi's virtual machine (no Python loop per
time step: an hour at 50 Hz takes about 0.1 s).
"""

from __future__ import annotations

from functools import lru_cache

import casadi as ca
import numpy as np

__all__ = ["simulate_modal", "modal_acceleration", "simulate_amplitude"]

# Regularises the locked-force shape q'/(w Q) at Q -> 0; far below any amplitude of interest.
_Q_FLOOR = 1e-9


def _modal_rhs(x, p, omega: float, zeta: float):
    q, v = x[0], x[1]
    c_lin, n1, n2, k_aero, f_lock, f_ext = (p[i] for i in range(6))
    Q = ca.sqrt(q**2 + (v / omega) ** 2 + _Q_FLOOR**2)
    acc = (-2.0 * zeta * omega * v - omega**2 * q + c_lin * v - n1 * ca.fabs(q) * v - n2 * q**2 * v
           + k_aero * q + f_lock * v / (omega * Q) + f_ext)
    return ca.vertcat(v, acc)


# Steps per compiled chunk: building a mapaccum costs time proportional to its
# length, so one cached chunk is reused for records of any length.
_CHUNK = 8192


@lru_cache(maxsize=32)
def _stepper(kind: str, omega: float, zeta: float, dt: float, n_steps: int = _CHUNK) -> ca.Function:
    if kind == "modal":
        x = ca.SX.sym("x", 2)
        p = ca.SX.sym("p", 6)
        f = lambda xx: _modal_rhs(xx, p, omega, zeta)  # noqa: E731
    else:
        x = ca.SX.sym("x", 1)
        p = ca.SX.sym("p", 4)
        f = lambda xx: p[0] + p[1] * xx + p[2] * xx**2 + p[3] * xx**3  # noqa: E731
    k1 = f(x)
    k2 = f(x + dt / 2 * k1)
    k3 = f(x + dt / 2 * k2)
    k4 = f(x + dt * k3)
    step = ca.Function("step", [x, p], [x + dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4)])
    return step.mapaccum("steps", n_steps)


def simulate_modal(x0, params: np.ndarray, dt: float, omega: float, zeta: float) -> np.ndarray:
    """Integrate the modal equation with RK4 (inputs held over each step).

    Parameters
    ----------
    x0 : (q0 m, v0 m/s)
    params : ndarray, shape (n_steps, 6)
        ``c_lin, n1, n2, k_aero, f_lock, f_ext`` per step (see
        :func:`vivbench.synth.aero.modal_coefficients`), best sampled at step midpoints.
    dt : float, s

    Returns
    -------
    x : ndarray, shape (n_steps + 1, 2)
        State (q m, q' m/s) at t = 0, dt, ..., n_steps dt.
    """
    F = _stepper("modal", float(omega), float(zeta), float(dt))
    return _run_chunked(F, np.asarray(x0, dtype=float), np.asarray(params, dtype=float))


def _run_chunked(F: ca.Function, x0: np.ndarray, params: np.ndarray) -> np.ndarray:
    n = params.shape[0]
    n_chunks = -(-n // _CHUNK)
    # Pad with the last input row; the padded steps are computed and discarded.
    padded = np.concatenate([params, np.repeat(params[-1:], n_chunks * _CHUNK - n, axis=0)], axis=0)
    out = [x0[None, :]]
    x = x0
    for c in range(n_chunks):  # a loop per chunk of 8192 steps, not per step
        X = np.asarray(F(x, padded[c * _CHUNK : (c + 1) * _CHUNK].T)).T
        out.append(X)
        x = X[-1]
    return np.concatenate(out, axis=0)[: n + 1]


def modal_acceleration(x: np.ndarray, params: np.ndarray, omega: float, zeta: float) -> np.ndarray:
    """q'' from states and the force coefficients at the same instants (vectorised).

    Parameters
    ----------
    x : ndarray, shape (n, 2)
    params : ndarray, shape (n, 6)

    Returns
    -------
    ndarray, shape (n,), m/s^2
    """
    q, v = x[:, 0], x[:, 1]
    c_lin, n1, n2, k_aero, f_lock, f_ext = params.T
    Q = np.sqrt(q**2 + (v / omega) ** 2 + _Q_FLOOR**2)
    return (-2.0 * zeta * omega * v - omega**2 * q + c_lin * v - n1 * np.abs(q) * v - n2 * q**2 * v
            + k_aero * q + f_lock * v / (omega * Q) + f_ext)


def simulate_amplitude(Q0: float, coefs: np.ndarray, dt: float) -> np.ndarray:
    """Integrate the averaged amplitude equation Q' = p0 + p1 Q + p2 Q^2 + p3 Q^3 with RK4.

    Parameters
    ----------
    Q0 : float, m
    coefs : ndarray, shape (n_steps, 4)
        Per-step coefficients (units m/s, 1/s, 1/(m s), 1/(m^2 s)).
    dt : float, s

    Returns
    -------
    Q : ndarray, shape (n_steps + 1,), m
    """
    F = _stepper("amplitude", 0.0, 0.0, float(dt))
    return _run_chunked(F, np.array([float(Q0)]), np.asarray(coefs, dtype=float))[:, 0]
