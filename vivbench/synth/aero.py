"""Aeroelastic force of the generalised Simiu-Scanlan model and its averaged truth.

The full model (DESIGN 2.2) enters the modal equation through five slowly
varying coefficients; first-order averaging of the same model (DESIGN 2.3)
gives the amplitude equation Q' = r0 + r1 + r2 + r3, whose per-section
polynomial parts are computed here once and shared by the truth, the exact
coefficient matrix and the tests.

With q = Q cos(phi), q' = -Q w sin(phi), a modal force f gives
Q' = -<f sin(phi)> / w; the averages used are <sin^2> = 1/2,
<|cos| sin^2> = 2/(3 pi) and <cos^2 sin^2> = 1/8.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.polynomial import polynomial as P

from vivbench.synth.config import AeroConfig, StructureConfig
from vivbench.core.terms import feature_exponents

__all__ = [
    "modal_coefficients",
    "amplitude_polynomials",
    "amplitude_coefficients",
    "order_contributions",
    "exact_coefficients",
]


def modal_coefficients(U: np.ndarray, structure: StructureConfig, aero: AeroConfig) -> dict[str, np.ndarray]:
    """Coefficients of the aeroelastic terms of the modal equation.

    The modal equation is
    q'' + 2 zeta w q' + w^2 q = c_lin q' - n1 |q| q' - n2 q^2 q' + k_aero q
    + f_lock q' / (w Q) + f_ext, where q'/(w Q) = -sin(phi) is the unit force
    shape locked in phase with the velocity.

    Parameters
    ----------
    U : ndarray, shape (n, S), m/s
        Mean perpendicular wind speed at the S sections.

    Returns
    -------
    dict of ndarray, shape (n,)
        ``c_lin`` (1/s), ``n1`` (1/(m s)), ``n2`` (1/(m^2 s)), ``k_aero`` (1/s^2), ``f_lock`` (m/s^2).
    """
    U = np.asarray(U, dtype=float)
    s = structure
    phi = np.array(s.mode_shape)
    beta = s.participation
    rho, D, m = s.air_density, s.depth, s.mass
    Y1, e1, e2, Y2, CL = (aero.Y1(U), aero.e1(U), aero.e2(U), aero.Y2(U), aero.C_L(U))
    damp = beta * rho * D * U * Y1 * phi / m
    return {
        "c_lin": damp.sum(axis=-1),
        "n1": (damp * e1 * np.abs(phi) / D).sum(axis=-1),
        "n2": (damp * e2 * phi**2 / D**2).sum(axis=-1),
        "k_aero": (beta * rho * U**2 * Y2 * phi / m).sum(axis=-1),
        "f_lock": (beta * rho * D * U**2 * CL / (2.0 * m)).sum(axis=-1),
    }


def amplitude_polynomials(structure: StructureConfig, aero: AeroConfig) -> np.ndarray:
    """Per-section polynomials in U of the averaged amplitude equation.

    Q' = sum_k sum_i P[k, i](U_k) Q^i  -  zeta w Q.

    Returns
    -------
    P : ndarray, shape (S, 4, n_coef)
        Coefficients in ascending powers of U_k (m/s), for section k and order i.
    """
    s = structure
    phi = np.array(s.mode_shape)
    beta = s.participation
    rho, D, m, w = s.air_density, s.depth, s.mass, s.omega
    UY1 = P.polymul([0.0, 1.0], aero.Y1.coefficients)
    g = [
        P.polymul([0.0, 0.0, rho * D / (4.0 * m * w)], aero.C_L.coefficients),
        rho * D / (2.0 * m) * UY1,
        -rho * D / m * (2.0 / (3.0 * math.pi)) / D * P.polymul(UY1, aero.e1.coefficients),
        -rho * D / m * (1.0 / 8.0) / D**2 * P.polymul(UY1, aero.e2.coefficients),
    ]
    section_factor = np.stack([beta, beta * phi, beta * phi * np.abs(phi), beta * phi**3], axis=1)  # (S, 4)
    n_coef = max(len(gi) for gi in g)
    out = np.zeros((phi.size, 4, n_coef))
    for i, gi in enumerate(g):
        out[:, i, : len(gi)] = section_factor[:, i : i + 1] * np.asarray(gi)[None, :]
    return out


def amplitude_coefficients(U: np.ndarray, structure: StructureConfig, aero: AeroConfig) -> np.ndarray:
    """Coefficients p_i of the averaged amplitude equation Q' = sum_i p_i Q^i.

    Parameters
    ----------
    U : ndarray, shape (n, S), m/s

    Returns
    -------
    p : ndarray, shape (n, 4)
        Units m/s, 1/s, 1/(m s), 1/(m^2 s); p_1 includes the structural damping -zeta w.
    """
    U = np.asarray(U, dtype=float)
    poly = amplitude_polynomials(structure, aero)
    # every section's polynomial at its own wind speed, summed over the sections
    coef = np.stack([sum(P.polyval(U[:, k], poly[k, i]) for k in range(poly.shape[0])) for i in range(4)], axis=1)
    coef[:, 1] -= structure.damping_ratio * structure.omega
    return coef


def order_contributions(Q: np.ndarray, U: np.ndarray, structure: StructureConfig, aero: AeroConfig) -> np.ndarray:
    """Order contributions r_0..r_3 to dQ/dt of the averaged model.

    Parameters
    ----------
    Q : ndarray, shape (n,), m
        Modal amplitude.
    U : ndarray, shape (n, S), m/s

    Returns
    -------
    r : ndarray, shape (n, 4), m/s
        r_1 includes the structural damping -zeta w Q. Multiply by phi_k to get
        section k's contributions to dA_k/dt.
    """
    Q = np.asarray(Q, dtype=float)
    return amplitude_coefficients(U, structure, aero) * Q[:, None] ** np.arange(4)


def exact_coefficients(structure: StructureConfig, aero: AeroConfig) -> np.ndarray | None:
    """The averaged truth as a coefficient matrix over the 23 S-term library (S sections).

    Equation m is dA_m/dt = phi_m dQ/dt; section k's part of order i is written
    with Q = A_k / phi_k, so it uses section k's own terms A_k^i U_k^j, and the
    structural damping -zeta w A_m sits in equation m's own A_m column. Because
    A_1 : ... : A_S = phi_1 : ... : phi_S exactly in the averaged model, this is
    one representative of a family of matrices that give the same dynamics; the
    order contributions (and so the regimes) are the same for all of them.

    Returns
    -------
    Xi : ndarray, shape (S, 23 S), or None
        None when the parameter polynomials have too high a degree for the library.
    """
    if not aero.exact_in_library:
        return None
    poly = amplitude_polynomials(structure, aero)
    phi = np.array(structure.mode_shape)
    n_sec = phi.size
    ex = feature_exponents(n_sec)
    Xi = np.zeros((n_sec, ex.shape[0]))
    for col, (k, i, j) in enumerate(ex):
        c = poly[k, i, j] if j < poly.shape[2] else 0.0
        Xi[:, col] = phi * c / phi[k] ** i
    for m in range(n_sec):
        col = int(np.flatnonzero((ex[:, 0] == m) & (ex[:, 1] == 1) & (ex[:, 2] == 0))[0])
        Xi[m, col] -= structure.damping_ratio * structure.omega
    return Xi
