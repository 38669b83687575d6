"""The grey-box's physics: the bridge's properties and the averaged Simiu-Scanlan amplitude equation's factors.

dQ/dt = g_0 + g_1 Q + g_2 Q^2 + g_3 Q^3 for the modal amplitude Q, with
g_0 = sum_k a_0k C_L, g_1 = sum_k a_1k Y1 - zeta w, g_2 = sum_k a_2k Y1 e1 and
g_3 = sum_k a_3k Y1 e2, the functions evaluated at each section's wind and the
factors a_ik (:func:`section_factors`) from the bridge's properties
(:class:`BridgeProperties`), its mode shape phi and participation factors beta
(docs/concepts.md (the truth)).

Structural damping and Y1. Both enter the linear coefficient, -zeta w and
sum_k beta_k phi_k rho U_k D Y1(U_k) / (2 m), and with Y1 a free function of U
they cannot be told apart from amplitude records alone (Y1 = -K / U would mimic
any damping). The damping ratio is therefore *given*: measured from free
decays at quiet wind, where the aerodynamic part rho U D Y1 / m vanishes with
U, or from the design value. A wrong zeta moves Y1 by (delta zeta) 2 m w /
(rho U D sum beta phi) and leaves the fitted dynamics (the curves a_k1 and
dA/dt) unchanged, so the curves of docs/concepts.md (coefficient curves) do not depend on it.
"""

from __future__ import annotations

import json
import math
from dataclasses import asdict, dataclass

import numpy as np

from vivbench.core.errors import InputError
from vivbench.models.campaign import amplitude_ratios

__all__ = ["BridgeProperties", "section_factors", "g_from_values", "curves_to_functions", "mode_geometry"]


@dataclass(frozen=True, kw_only=True)
class BridgeProperties:
    """What the user knows about the bridge and its mode (never read from a synthetic truth by the fit).

    Parameters
    ----------
    mass : float, kg/m
        Equivalent modal mass per unit length m.
    depth : float, m
        Deck depth D.
    frequency : float, Hz
        The mode's frequency f.
    damping_ratio : float
        Structural damping ratio zeta (dimensionless, >= 0).
    air_density : float, kg/m^3
    mode_shape : tuple of float or None
        phi_k at the instrumented sections; None: ``|phi|`` from the data's amplitude ratios.
    tributary_lengths : tuple of float or None, m
        L_k of the sections' strips; None: equal lengths.
    """

    mass: float
    depth: float
    frequency: float
    damping_ratio: float
    air_density: float = 1.225
    mode_shape: tuple[float, ...] | None = None
    tributary_lengths: tuple[float, ...] | None = None

    def __post_init__(self):
        for name in ("mass", "depth", "frequency", "air_density"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise InputError(f"bridge {name} must be a finite positive number; got {v!r}")
        if not (isinstance(self.damping_ratio, (int, float)) and math.isfinite(self.damping_ratio)
                and 0 <= self.damping_ratio < 1):
            raise InputError(f"bridge damping_ratio must lie in [0, 1); got {self.damping_ratio!r}")
        for name in ("mode_shape", "tributary_lengths"):
            v = getattr(self, name)
            if v is None:
                continue
            try:
                arr = tuple(float(x) for x in v)
            except (TypeError, ValueError):
                raise InputError(f"bridge {name} must be a list of numbers; got {v!r}") from None
            if not arr or not all(math.isfinite(x) for x in arr):
                raise InputError(f"bridge {name} must be a non-empty list of finite numbers; got {v!r}")
            if name == "tributary_lengths" and min(arr) <= 0:
                raise InputError(f"bridge tributary_lengths must be positive; got {v!r}")
            object.__setattr__(self, name, arr)

    @property
    def omega(self) -> float:
        """Circular frequency w = 2 pi f, rad/s."""
        return 2.0 * math.pi * self.frequency

    def to_json(self) -> str:
        return json.dumps(asdict(self), sort_keys=True)

    @classmethod
    def from_dict(cls, data: dict) -> "BridgeProperties":
        allowed = {"mass", "depth", "frequency", "damping_ratio", "air_density", "mode_shape", "tributary_lengths"}
        unknown = set(data) - allowed
        if unknown:
            raise InputError(f"unknown bridge propert{'ies' if len(unknown) > 1 else 'y'} {sorted(unknown)}; "
                             f"allowed: {sorted(allowed)}")
        missing = {"mass", "depth", "frequency", "damping_ratio"} - set(data)
        if missing:
            raise InputError(f"bridge properties lack {sorted(missing)} (kg/m, m, Hz, ratio)")
        return cls(**data)


def section_factors(U: np.ndarray, bridge: BridgeProperties, phi: np.ndarray, beta: np.ndarray) -> np.ndarray:
    """Factors a_ik with g_0 = sum a_0k C_L, g_1 = sum a_1k Y1, g_2 = sum a_2k Y1 e1, g_3 = sum a_3k Y1 e2.

    Parameters
    ----------
    U : ndarray, shape (..., S), m/s

    Returns
    -------
    ndarray, shape (..., S, 4); units of g_i (m^(1-i)/s) per unit function.
    """
    rho, D, m, w = bridge.air_density, bridge.depth, bridge.mass, bridge.omega
    U = np.asarray(U, dtype=float)
    return np.stack([
        beta * rho * U**2 * D / (4.0 * m * w),
        beta * phi * rho * U * D / (2.0 * m),
        -beta * phi * np.abs(phi) * rho * U * (2.0 / (3.0 * math.pi)) / m,
        -beta * phi**3 * rho * U / (8.0 * m * D),
    ], axis=-1)


def g_from_values(F: np.ndarray, a: np.ndarray, zw: float) -> np.ndarray:
    """g (..., 4) from function values F (..., S, 4) [Y1, e1, e2, C_L] and factors a (..., S, 4)."""
    Y, E1, E2, CL = F[..., 0], F[..., 1], F[..., 2], F[..., 3]
    return np.stack([(a[..., 0] * CL).sum(-1), (a[..., 1] * Y).sum(-1) - zw,
                     (a[..., 2] * Y * E1).sum(-1), (a[..., 3] * Y * E2).sum(-1)], axis=-1)


def curves_to_functions(wind: np.ndarray, p: np.ndarray, bridge: BridgeProperties, phi: np.ndarray,
                        beta: np.ndarray, *, share: float = 0.3) -> np.ndarray:
    """Y1, e1, e2, C_L on a wind grid from the amplitude-equation coefficients p_i(U) (all sections at U).

    Parameters
    ----------
    wind : ndarray, shape (n,), m/s
    p : ndarray, shape (4, n)
        p_i(U) such that dQ/dt = sum_i p_i Q^i (p_1 includes -zeta w).
    share : float
        e1 and e2 are read only where Y1 exceeds this share of its largest
        value (elsewhere Y1 e is near 0/0); outside, their median there.

    Returns
    -------
    ndarray, shape (4, n) [Y1, e1, e2, C_L]; e and C_L clipped at 0.
    """
    U = np.repeat(np.asarray(wind, dtype=float)[:, None], phi.size, axis=1)
    k = section_factors(U, bridge, phi, beta).sum(axis=1)  # (n, 4)
    Y = (p[1] + bridge.omega * bridge.damping_ratio) / k[:, 1]
    CL = np.clip(p[0] / k[:, 0], 0.0, None)
    out = [Y]
    big = np.isfinite(Y) & (Y > share * np.nanmax(np.where(np.isfinite(Y), Y, -np.inf), initial=0.0)) & (Y > 0)
    for i in (2, 3):
        with np.errstate(divide="ignore", invalid="ignore"):
            e = p[i] / (k[:, i] * Y)
        ok = big & np.isfinite(e) & (e > 0)
        fill = float(np.median(e[ok])) if ok.any() else 1.0
        out.append(np.where(ok, e, fill))
    out.append(CL)
    return np.stack(out)


def mode_geometry(bridge: BridgeProperties, records) -> tuple[np.ndarray, np.ndarray]:
    """The mode shape phi (S,) and participation factors beta_k = L_k phi_k / sum_l L_l phi_l^2 (S,), dimensionless.

    phi from the bridge's ``mode_shape``, or ``|phi|`` from the median amplitude ratios of the records' A
    (largest 1); L from ``tributary_lengths`` (equal without).
    """
    S = records[0].n_sections
    b = bridge
    if b.mode_shape is not None:
        if len(b.mode_shape) != S:
            raise InputError(f"bridge mode_shape has {len(b.mode_shape)} values; the records have {S} sections")
        phi = np.array(b.mode_shape)
    else:
        ratios = amplitude_ratios(np.concatenate([r.A for r in records]))
        ref = int(np.nanargmax(np.nanmedian(ratios, axis=0)))  # the section others are largest against
        phi = np.abs(ratios[ref])
        phi = np.where(np.isfinite(phi), phi, 1.0)
        phi = phi / phi.max()
    L = np.ones(S) if b.tributary_lengths is None else np.array(b.tributary_lengths)
    if L.size != S:
        raise InputError(f"bridge tributary_lengths has {L.size} values; the records have {S} sections")
    beta = L * phi / np.sum(L * phi**2)
    return phi, beta
