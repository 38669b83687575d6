"""Aerodynamic functions of the synthetic bridge: polynomials in U and shapes in reduced velocity.

The functions Y1, e1, e2, Y2 and C_L of the generalised Simiu-Scanlan force
(docs/concepts.md (aeroelastic force)) are curves of the local mean wind. Two families exist:

- :class:`Polynomial`, a polynomial in the wind speed U (m/s) itself: the
  ``in_library`` mode, whose averaged truth is a combination of the library
  terms A^i U^j (docs/concepts.md (no inverse crime));
- shapes in the reduced velocity Ur = U / (f1 D) (dimensionless; f1 the
  mode's frequency in Hz, D the deck depth in m) that are not polynomials:
  :class:`GaussianBell`, :class:`LorentzianBell`, :class:`AsymmetricBell`,
  :class:`LogisticStep` and :class:`Constant`.

Every curve is evaluated on the wind with :meth:`at_wind` ``(U, frequency,
depth)``, so the caller never needs to know which variable a curve uses;
``curve(x)`` evaluates a curve on its own variable (U for a polynomial, Ur for
the shapes). The shapes carry a ``kind`` key (``"gaussian"``, ``"lorentzian"``,
``"asymmetric"``, ``"logistic"``, ``"constant"``) in their plain-data form; a mapping without
``kind`` (or a bare coefficient list) is a polynomial, as in configurations
written before the shapes existed.

:class:`YawFactor` is the optional dependence on the wind's angle to the span:
a factor in [0, 1] of the yaw (the angle between the mean wind and the span's
normal) that multiplies some of the functions.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from vivbench.core.errors import InputError

__all__ = [
    "Polynomial",
    "GaussianBell",
    "LorentzianBell",
    "AsymmetricBell",
    "LogisticStep",
    "Constant",
    "Curve",
    "CURVE_KINDS",
    "YawFactor",
    "YAW_SHAPES",
    "curve_from_data",
    "reduced_velocity",
    "scaled_bell",
]


def _require(cond: bool, msg: str) -> None:
    if not cond:
        raise InputError(msg)


def _finite(name: str, **values: float) -> dict[str, float]:
    out = {k: float(v) for k, v in values.items()}
    for k, v in out.items():
        _require(math.isfinite(v), f"{name} {k} must be a finite number; got {v}")
    return out


def reduced_velocity(U, frequency: float, depth: float) -> np.ndarray:
    """Reduced velocity Ur = U / (f1 D).

    Parameters
    ----------
    U : array_like, any shape, m/s
    frequency : float, Hz; the mode's frequency f1
    depth : float, m; the deck depth D

    Returns
    -------
    ndarray, the shape of ``U``, dimensionless
    """
    return np.asarray(U, dtype=float) / (frequency * depth)


@dataclass(frozen=True, kw_only=True)
class Polynomial:
    """A polynomial in the wind speed U (m/s), coefficients in ascending powers."""

    coefficients: tuple[float, ...]

    def __post_init__(self) -> None:
        coefs = tuple(float(c) for c in self.coefficients)
        _require(len(coefs) >= 1, "Polynomial needs at least one coefficient")
        _require(all(math.isfinite(c) for c in coefs), f"Polynomial coefficients must be finite; got {coefs}")
        object.__setattr__(self, "coefficients", coefs)

    @property
    def degree(self) -> int:
        return len(self.coefficients) - 1

    @property
    def lower_bound(self) -> float:
        """Infimum over all U: the constant for degree 0, else -inf (not checked)."""
        return self.coefficients[0] if self.degree == 0 else -math.inf

    def as_polynomial(self) -> Polynomial:
        """The same curve as a polynomial in U (itself)."""
        return self

    def __call__(self, U):
        """Value at wind speed ``U`` (m/s), array of any shape."""
        return np.polynomial.polynomial.polyval(np.asarray(U, dtype=float), self.coefficients)

    def at_wind(self, U, frequency: float, depth: float) -> np.ndarray:
        """Value at wind speed ``U`` (m/s); ``frequency`` (Hz) and ``depth`` (m) are not needed."""
        return self(U)


@dataclass(frozen=True, kw_only=True)
class _ReducedVelocityCurve:
    """A shape in the reduced velocity Ur = U / (f1 D)."""

    def at_wind(self, U, frequency: float, depth: float) -> np.ndarray:
        """Value at wind speed ``U`` (m/s, any shape) for a mode of ``frequency`` Hz and a deck ``depth`` m deep."""
        return self(reduced_velocity(U, frequency, depth))

    def as_polynomial(self) -> Polynomial | None:
        """The curve as a polynomial in U, or None when it is not one."""
        return None


@dataclass(frozen=True, kw_only=True)
class GaussianBell(_ReducedVelocityCurve):
    """baseline + (peak - baseline) exp(-(Ur - center)^2 / (2 width^2)).

    Attributes
    ----------
    peak : value at the centre
    center : reduced velocity of the peak, > 0 (about 1/St for vortex-shedding lock-in)
    width : standard deviation of the bell in reduced velocity, > 0
    baseline : value far from the centre (negative for Y1: damping outside lock-in)
    """

    peak: float
    center: float
    width: float
    baseline: float = 0.0
    kind: str = field(default="gaussian", init=False)

    def __post_init__(self) -> None:
        v = _finite("GaussianBell", peak=self.peak, center=self.center, width=self.width, baseline=self.baseline)
        for k, x in v.items():
            object.__setattr__(self, k, x)
        _require(self.center > 0, f"GaussianBell center must be a positive reduced velocity; got {self.center}")
        _require(self.width > 0, f"GaussianBell width must be positive (reduced velocity); got {self.width}")

    @property
    def lower_bound(self) -> float:
        return min(self.peak, self.baseline)

    def __call__(self, Ur):
        """Value at reduced velocity ``Ur`` (array of any shape)."""
        z = (np.asarray(Ur, dtype=float) - self.center) / self.width
        return self.baseline + (self.peak - self.baseline) * np.exp(-0.5 * z**2)


@dataclass(frozen=True, kw_only=True)
class LorentzianBell(_ReducedVelocityCurve):
    """baseline + (peak - baseline) / (1 + ((Ur - center) / width)^2): a bell with heavy tails.

    Attributes
    ----------
    peak : value at the centre
    center : reduced velocity of the peak, > 0
    width : half width at half height of the bell in reduced velocity, > 0
    baseline : value far from the centre
    """

    peak: float
    center: float
    width: float
    baseline: float = 0.0
    kind: str = field(default="lorentzian", init=False)

    def __post_init__(self) -> None:
        v = _finite("LorentzianBell", peak=self.peak, center=self.center, width=self.width, baseline=self.baseline)
        for k, x in v.items():
            object.__setattr__(self, k, x)
        _require(self.center > 0, f"LorentzianBell center must be a positive reduced velocity; got {self.center}")
        _require(self.width > 0, f"LorentzianBell width must be positive (reduced velocity); got {self.width}")

    @property
    def lower_bound(self) -> float:
        return min(self.peak, self.baseline)

    def __call__(self, Ur):
        """Value at reduced velocity ``Ur`` (array of any shape)."""
        z = (np.asarray(Ur, dtype=float) - self.center) / self.width
        return self.baseline + (self.peak - self.baseline) / (1.0 + z**2)


@dataclass(frozen=True, kw_only=True)
class AsymmetricBell(_ReducedVelocityCurve):
    """A Gaussian bell with different widths on its two sides (a split Gaussian).

    baseline + (peak - baseline) exp(-(Ur - center)^2 / (2 w^2)), with w = ``width_low``
    below the centre and ``width_high`` above it: lock-in that builds up slowly and ends
    abruptly (or the reverse). Continuous with a continuous first derivative at the centre.

    Attributes
    ----------
    peak : value at the centre
    center : reduced velocity of the peak, > 0
    width_low, width_high : standard deviations below and above the centre (reduced velocity), > 0
    baseline : value far from the centre
    """

    peak: float
    center: float
    width_low: float
    width_high: float
    baseline: float = 0.0
    kind: str = field(default="asymmetric", init=False)

    def __post_init__(self) -> None:
        v = _finite("AsymmetricBell", peak=self.peak, center=self.center, width_low=self.width_low,
                    width_high=self.width_high, baseline=self.baseline)
        for k, x in v.items():
            object.__setattr__(self, k, x)
        _require(self.center > 0, f"AsymmetricBell center must be a positive reduced velocity; got {self.center}")
        _require(self.width_low > 0 and self.width_high > 0,
                 f"AsymmetricBell width_low and width_high must be positive (reduced velocity); "
                 f"got {self.width_low}, {self.width_high}")

    @property
    def lower_bound(self) -> float:
        return min(self.peak, self.baseline)

    def __call__(self, Ur):
        """Value at reduced velocity ``Ur`` (array of any shape)."""
        x = np.asarray(Ur, dtype=float) - self.center
        z = x / np.where(x < 0, self.width_low, self.width_high)
        return self.baseline + (self.peak - self.baseline) * np.exp(-0.5 * z**2)


@dataclass(frozen=True, kw_only=True)
class LogisticStep(_ReducedVelocityCurve):
    """A smooth step from ``start`` (low Ur) to ``end`` (high Ur): start + (end - start) (1 + tanh((Ur - center) / width)) / 2.

    It saturates at both ends; ``start > end`` gives a decreasing curve.

    Attributes
    ----------
    start : value for Ur far below the centre
    end : value for Ur far above the centre
    center : reduced velocity of the midpoint, > 0
    width : reduced-velocity scale of the transition, > 0 (76 % of the change within +-width)
    """

    start: float
    end: float
    center: float
    width: float
    kind: str = field(default="logistic", init=False)

    def __post_init__(self) -> None:
        v = _finite("LogisticStep", start=self.start, end=self.end, center=self.center, width=self.width)
        for k, x in v.items():
            object.__setattr__(self, k, x)
        _require(self.center > 0, f"LogisticStep center must be a positive reduced velocity; got {self.center}")
        _require(self.width > 0, f"LogisticStep width must be positive (reduced velocity); got {self.width}")

    @property
    def lower_bound(self) -> float:
        return min(self.start, self.end)

    def __call__(self, Ur):
        """Value at reduced velocity ``Ur`` (array of any shape)."""
        z = (np.asarray(Ur, dtype=float) - self.center) / self.width
        return self.start + (self.end - self.start) * 0.5 * (1.0 + np.tanh(z))


@dataclass(frozen=True, kw_only=True)
class Constant(_ReducedVelocityCurve):
    """The same value at every wind speed."""

    value: float
    kind: str = field(default="constant", init=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "value", _finite("Constant", value=self.value)["value"])

    @property
    def lower_bound(self) -> float:
        return self.value

    def as_polynomial(self) -> Polynomial:
        """A constant is a polynomial of degree 0 in U."""
        return Polynomial(coefficients=(self.value,))

    def __call__(self, Ur):
        """Value at reduced velocity ``Ur`` (array of any shape): the constant."""
        return np.full(np.shape(Ur), self.value)


Curve = Polynomial | GaussianBell | LorentzianBell | AsymmetricBell | LogisticStep | Constant

CURVE_KINDS: dict[str, type] = {
    "polynomial": Polynomial,
    "gaussian": GaussianBell,
    "lorentzian": LorentzianBell,
    "asymmetric": AsymmetricBell,
    "logistic": LogisticStep,
    "constant": Constant,
}


def curve_from_data(value: Any, name: str = "curve") -> Curve:
    """A curve from its plain-data form (TOML, JSON) or the curve itself.

    Parameters
    ----------
    value : curve, mapping or sequence of numbers
        A mapping with ``kind`` (one of :data:`CURVE_KINDS`) and that shape's
        parameters; a mapping without ``kind`` (``{"coefficients": [...]}``) or
        a bare list of coefficients is a :class:`Polynomial` in U.
    name : str
        Name of the function (``Y1``, ...) for error messages.
    """
    if isinstance(value, tuple(CURVE_KINDS.values())):
        return value
    if isinstance(value, dict):
        data = dict(value)
        kind = data.pop("kind", "polynomial")
        _require(kind in CURVE_KINDS, f"{name}: kind must be one of {sorted(CURVE_KINDS)}; got {kind!r}")
        cls = CURVE_KINDS[kind]
        allowed = {f for f in cls.__dataclass_fields__ if f != "kind"}
        unknown = set(data) - allowed
        _require(not unknown, f"{name}: unknown keys {sorted(unknown)} for kind {kind!r}; allowed: {sorted(allowed)}")
        if "coefficients" in data:
            data["coefficients"] = tuple(data["coefficients"])
        try:
            return cls(**data)
        except TypeError as exc:
            raise InputError(f"{name}: kind {kind!r} needs {sorted(allowed)}; {exc}") from None
    if isinstance(value, (list, tuple)):
        return Polynomial(coefficients=tuple(value))
    raise InputError(f"{name} must be a curve table with a 'kind' key or a list of polynomial coefficients; got {value!r}")


_YAW_TARGETS = ("Y1", "e1", "e2", "Y2", "C_L")


#: Shapes of :class:`YawFactor`.
YAW_SHAPES = ("cosine", "gaussian", "sin2", "logistic")


def scaled_bell(bell, factor: float):
    """The lock-in bell (:class:`GaussianBell`, :class:`LorentzianBell` or :class:`AsymmetricBell`) with its peak
    and baseline multiplied by ``factor``; InputError for a curve that is not a bell."""
    if not isinstance(bell, (GaussianBell, LorentzianBell, AsymmetricBell)):
        raise InputError(f"only a bell (peak, baseline) can be scaled; got {type(bell).__name__}")
    return replace(bell, peak=bell.peak * factor, baseline=bell.baseline * factor)


@dataclass(frozen=True, kw_only=True)
class YawFactor:
    """Dependence of the aerodynamic functions on the wind's angle to the span (docs/concepts.md (aeroelastic force)).

    The yaw psi is the angle between the mean wind and the span's normal
    (0 for wind perpendicular to the span), per section. The functions named in
    ``applies_to`` are multiplied by

    - ``shape = "cosine"``: ``|cos psi|^exponent``;
    - ``shape = "gaussian"``: exp(-psi^2 / (2 width_deg^2));
    - ``shape = "sin2"``: 1 - strength sin^2 psi (a gentle fall-off that keeps
      1 - strength at 90 degrees);
    - ``shape = "logistic"``: a cut-off near ``cutoff_deg``,
      ``(1 + exp(-cutoff_deg / width_deg)) / (1 + exp((|psi| - cutoff_deg) / width_deg))``:
      nearly flat below the cut-off, falling to about zero over a few ``width_deg`` above it
      (exactly 1 at psi = 0).

    Vortex-induced vibration weakens as the wind turns away from the normal, so
    by default the factor scales the aerodynamic damping derivative Y1 and the
    locked lift C_L. The factor lies in [0, 1], so C_L stays >= 0.

    Attributes
    ----------
    shape : one of :data:`YAW_SHAPES`
    exponent : exponent n of the cosine shape, >= 0
    width_deg : degrees, > 0; standard deviation of the gaussian shape, transition width
        of the logistic one
    strength : strength c of the sin2 shape, in [0, 1]
    cutoff_deg : degrees, in (0, 90); yaw of the logistic shape's midpoint
    applies_to : names among Y1, e1, e2, Y2, C_L
    """

    shape: str = "cosine"
    exponent: float = 2.0
    width_deg: float = 20.0
    strength: float = 0.5
    cutoff_deg: float = 20.0
    applies_to: tuple[str, ...] = ("Y1", "C_L")

    def __post_init__(self) -> None:
        object.__setattr__(self, "applies_to", tuple(self.applies_to))
        _require(self.shape in YAW_SHAPES,
                 f"YawFactor shape must be one of {', '.join(repr(s) for s in YAW_SHAPES)}; got {self.shape!r}")
        v = _finite("YawFactor", exponent=self.exponent, width_deg=self.width_deg, strength=self.strength,
                    cutoff_deg=self.cutoff_deg)
        for k, x in v.items():
            object.__setattr__(self, k, x)
        _require(self.exponent >= 0, f"YawFactor exponent must be a finite number >= 0; got {self.exponent}")
        _require(self.width_deg > 0, f"YawFactor width_deg must be positive (degrees); got {self.width_deg}")
        _require(0 <= self.strength <= 1, f"YawFactor strength must be in [0, 1] (the factor stays in [0, 1]); "
                 f"got {self.strength}")
        _require(0 < self.cutoff_deg < 90, f"YawFactor cutoff_deg must be in (0, 90) degrees; got {self.cutoff_deg}")
        bad = [n for n in self.applies_to if n not in _YAW_TARGETS]
        _require(self.applies_to and not bad,
                 f"YawFactor applies_to must name some of {list(_YAW_TARGETS)}; got {list(self.applies_to)}")

    def __call__(self, yaw_deg) -> np.ndarray:
        """Factor in [0, 1] at yaw angles ``yaw_deg`` (degrees, array of any shape)."""
        psi = np.asarray(yaw_deg, dtype=float)
        if self.shape == "cosine":
            return np.abs(np.cos(np.radians(psi))) ** self.exponent
        if self.shape == "sin2":
            return 1.0 - self.strength * np.sin(np.radians(psi)) ** 2
        if self.shape == "logistic":
            # 1 / (1 + exp(z)) written with exp(-logaddexp(0, z)): no overflow for large z
            z0, z = -self.cutoff_deg / self.width_deg, (np.abs(psi) - self.cutoff_deg) / self.width_deg
            return np.minimum(1.0, np.exp(np.logaddexp(0.0, z0) - np.logaddexp(0.0, z)))
        return np.exp(-0.5 * (psi / self.width_deg) ** 2)
