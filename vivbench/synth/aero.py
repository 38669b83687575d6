"""Aeroelastic force of the generalised Simiu-Scanlan model and its averaged truth.

The full model (docs/concepts.md (aeroelastic force)) enters the modal equation through five slowly
varying coefficients; first-order averaging of the same model (docs/concepts.md (the truth))
gives the amplitude equation Q' = r0 + r1 + r2 + r3. First-order averaging
holds for any smooth functions Y1, e1, e2, C_L of the wind (and of its angle to
the span): the amplitude coefficients are computed from the curves' values at
the slowly varying wind, the same values the full simulation uses. When the
functions are polynomials in U (the ``in_library`` mode), the per-section
polynomial parts are also computed once and shared by the truth, the exact
coefficient matrix and the tests.

With q = Q cos(phi), q' = -Q w sin(phi), a modal force f gives
Q' = -<f sin(phi)> / w; the averages used are <sin^2> = 1/2,
<|cos| sin^2> = 2/(3 pi) and <cos^2 sin^2> = 1/8.
"""

from __future__ import annotations

import math

import numpy as np
import xarray as xr
from numpy.polynomial import polynomial as P

from vivbench.synth.config import AeroConfig, StructureConfig
from vivbench.core.terms import feature_exponents

__all__ = [
    "aero_functions",
    "modal_coefficients",
    "amplitude_polynomials",
    "amplitude_coefficients",
    "order_contributions",
    "exact_coefficients",
    "truth_curves",
]


def aero_functions(U: np.ndarray, structure: StructureConfig, aero: AeroConfig,
                   yaw: np.ndarray | None = None) -> dict[str, np.ndarray]:
    """Values of Y1, e1, e2, Y2 and C_L at the local mean wind, yaw factor included.

    Parameters
    ----------
    U : ndarray, any shape (usually (n, S)), m/s
        Mean perpendicular wind speed; curves of reduced velocity use
        Ur = U / (f1 D) with the structure's frequency and depth.
    yaw : ndarray, the shape of U, degrees, or None
        Angle between the mean wind and the span's normal. Ignored when the
        configuration has no yaw factor; None means 0 (wind perpendicular).

    Returns
    -------
    dict of ndarray, the shape of U
        ``Y1``, ``e1``, ``e2``, ``Y2``, ``C_L`` (dimensionless).
    """
    U = np.asarray(U, dtype=float)
    f, D = structure.frequency, structure.depth
    out = {name: np.asarray(getattr(aero, name).at_wind(U, f, D), dtype=float)
           for name in ("Y1", "e1", "e2", "Y2", "C_L")}
    if aero.yaw is not None and yaw is not None:
        factor = aero.yaw(np.broadcast_to(yaw, U.shape))
        for name in aero.yaw.applies_to:
            out[name] = out[name] * factor
    return out



def modal_coefficients(U: np.ndarray, structure: StructureConfig, aero: AeroConfig,
                       yaw: np.ndarray | None = None) -> dict[str, np.ndarray]:
    """Coefficients of the aeroelastic terms of the modal equation.

    The modal equation is
    q'' + 2 zeta w q' + w^2 q = c_lin q' - n1 ``|q|`` q' - n2 q^2 q' + k_aero q
    + f_lock q' / (w Q) + f_ext, where q'/(w Q) = -sin(phi) is the unit force
    shape locked in phase with the velocity.

    Parameters
    ----------
    U : ndarray, shape (n, S), m/s
        Mean perpendicular wind speed at the S sections.
    yaw : ndarray, shape (n, S), degrees, or None
        Angle between the mean wind and the span's normal at the sections
        (used only with a yaw factor; None: perpendicular wind).

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
    F = aero_functions(U, s, aero, yaw)
    Y1, e1, e2, Y2, CL = F["Y1"], F["e1"], F["e2"], F["Y2"], F["C_L"]
    damp = beta * rho * D * U * Y1 * phi / m
    return {
        "c_lin": damp.sum(axis=-1),
        "n1": (damp * e1 * np.abs(phi) / D).sum(axis=-1),
        "n2": (damp * e2 * phi**2 / D**2).sum(axis=-1),
        "k_aero": (beta * rho * U**2 * Y2 * phi / m).sum(axis=-1),
        "f_lock": (beta * rho * D * U**2 * CL / (2.0 * m)).sum(axis=-1),
    }


def amplitude_polynomials(structure: StructureConfig, aero: AeroConfig) -> np.ndarray:
    """Per-section polynomials in U of the averaged amplitude equation (``in_library`` mode).

    Q' = sum_k sum_i P[k, i](U_k) Q^i  -  zeta w Q.

    Returns
    -------
    P : ndarray, shape (S, 4, n_coef)
        Coefficients in ascending powers of U_k (m/s), for section k and order i.

    Raises
    ------
    ValueError
        When Y1, e1, e2 or C_L is not a polynomial in U or a yaw factor applies.
    """
    polys = aero.polynomials()
    if polys is None:
        raise ValueError("amplitude_polynomials needs Y1, e1, e2 and C_L as polynomials in U and no yaw factor "
                         "(the in_library mode); use amplitude_coefficients for any curves")
    s = structure
    phi = np.array(s.mode_shape)
    beta = s.participation
    rho, D, m, w = s.air_density, s.depth, s.mass, s.omega
    UY1 = P.polymul([0.0, 1.0], polys["Y1"].coefficients)
    g = [
        P.polymul([0.0, 0.0, rho * D / (4.0 * m * w)], polys["C_L"].coefficients),
        rho * D / (2.0 * m) * UY1,
        -rho * D / m * (2.0 / (3.0 * math.pi)) / D * P.polymul(UY1, polys["e1"].coefficients),
        -rho * D / m * (1.0 / 8.0) / D**2 * P.polymul(UY1, polys["e2"].coefficients),
    ]
    section_factor = np.stack([beta, beta * phi, beta * phi * np.abs(phi), beta * phi**3], axis=1)  # (S, 4)
    n_coef = max(len(gi) for gi in g)
    out = np.zeros((phi.size, 4, n_coef))
    for i, gi in enumerate(g):
        out[:, i, : len(gi)] = section_factor[:, i : i + 1] * np.asarray(gi)[None, :]
    return out


def amplitude_coefficients(U: np.ndarray, structure: StructureConfig, aero: AeroConfig,
                           yaw: np.ndarray | None = None) -> np.ndarray:
    """Coefficients p_i of the averaged amplitude equation Q' = sum_i p_i Q^i.

    Averaging the modal equation of :func:`modal_coefficients` over one cycle
    of q = Q cos(w t + psi) gives p_0 = f_lock / (2 w), p_1 = c_lin / 2 - zeta w,
    p_2 = -(2 / (3 pi)) n1 and p_3 = -n2 / 8, whatever the shapes of the
    aerodynamic functions (first-order averaging needs only that they vary
    slowly with the wind). Polynomial configurations without a yaw factor take
    the per-section polynomials of :func:`amplitude_polynomials` (the same
    numbers up to rounding; the saved ``in_library`` truth stays bit for bit).

    Parameters
    ----------
    U : ndarray, shape (n, S), m/s
    yaw : ndarray, shape (n, S), degrees, or None
        The wind's angle to the span's normal, as given to the full simulation.

    Returns
    -------
    p : ndarray, shape (n, 4)
        Units m/s, 1/s, 1/(m s), 1/(m^2 s); p_1 includes the structural damping -zeta w.
    """
    U = np.asarray(U, dtype=float)
    zw = structure.damping_ratio * structure.omega
    if aero.polynomials() is None:
        c = modal_coefficients(U, structure, aero, yaw)
        return np.stack([c["f_lock"] / (2.0 * structure.omega), 0.5 * c["c_lin"] - zw,
                         -(2.0 / (3.0 * math.pi)) * c["n1"], -0.125 * c["n2"]], axis=1)
    poly = amplitude_polynomials(structure, aero)
    # every section's polynomial at its own wind speed, summed over the sections
    coef = np.stack([sum(P.polyval(U[:, k], poly[k, i]) for k in range(poly.shape[0])) for i in range(4)], axis=1)
    coef[:, 1] -= zw
    return coef


def order_contributions(Q: np.ndarray, U: np.ndarray, structure: StructureConfig, aero: AeroConfig,
                        yaw: np.ndarray | None = None) -> np.ndarray:
    """Order contributions r_0..r_3 to dQ/dt of the averaged model.

    Parameters
    ----------
    Q : ndarray, shape (n,), m
        Modal amplitude.
    U : ndarray, shape (n, S), m/s
    yaw : ndarray, shape (n, S), degrees, or None
        The wind's angle to the span's normal (only used with a yaw factor).

    Returns
    -------
    r : ndarray, shape (n, 4), m/s
        r_1 includes the structural damping -zeta w Q. Multiply by phi_k to get
        section k's contributions to dA_k/dt.
    """
    Q = np.asarray(Q, dtype=float)
    return amplitude_coefficients(U, structure, aero, yaw) * Q[:, None] ** np.arange(4)


def truth_curves(structure: StructureConfig, aero: AeroConfig, wind_grid) -> xr.DataArray:
    """The truth's coefficient curves a_ki(U) of docs/concepts.md (coefficient curves).

    With every section at the mean wind U and the wind perpendicular to the
    span (yaw 0), equation k reads dA_k/dt = sum_i a_ki(U) A_k^i. Since
    A_l = (phi_l / phi_k) A_k, the other sections' parts are folded in through
    the mode-shape ratios: a_ki = phi_k^(1 - i) p_i(U) with p_i of
    :func:`amplitude_coefficients` (a_k1 includes the damping -zeta w1).

    Parameters
    ----------
    wind_grid : array_like, shape (n_wind,), m/s

    Returns
    -------
    xarray.DataArray ``curves``, shape (S, 4, n_wind), dims (equation, order, wind)
        Units m^(1-i)/s; coordinates ``equation`` (section names), ``order``
        (0..3) and ``wind`` (m/s).
    """
    wind = np.atleast_1d(np.asarray(wind_grid, dtype=float))
    if wind.ndim != 1 or not np.all(np.isfinite(wind)) or np.any(wind <= 0):
        raise ValueError("wind_grid must be a 1-D array of finite positive speeds in m/s")
    phi = np.array(structure.mode_shape)
    U = np.broadcast_to(wind[:, None], (wind.size, phi.size))
    p = amplitude_coefficients(U, structure, aero, np.zeros_like(U))  # (n_wind, 4)
    a = phi[:, None, None] ** (1 - np.arange(4))[None, :, None] * p.T[None, :, :]
    return xr.DataArray(
        a, dims=("equation", "order", "wind"), name="curves",
        coords={"equation": list(structure.sections), "order": np.arange(4), "wind": ("wind", wind, {"units": "m/s"})},
        attrs={"units": "m^(1-order) s-1",
               "long_name": "true coefficient of A_k^order at mean wind U, yaw 0 (docs/concepts.md (coefficient curves))"},
    )


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
