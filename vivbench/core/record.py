"""One preprocessed record: the unit of data every model of the protocol (docs/methods.md) fits and evaluates."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["Record"]


def _frozen_array(name: str, x, shape: tuple[int, ...] | None = None) -> np.ndarray:
    try:
        arr = np.array(x, dtype=float)  # a copy: the record owns its data
    except (TypeError, ValueError) as exc:
        raise ValueError(f"Record.{name} must be an array of numbers; {exc}") from None
    if shape is not None and arr.shape != shape:
        raise ValueError(f"Record.{name} must have shape {shape} (n_samples, n_sections) like A; got {arr.shape}")
    arr.setflags(write=False)
    return arr


@dataclass(frozen=True, kw_only=True, eq=False)
class Record:
    """A campaign's preprocessed record of one event (or segment).

    Parameters
    ----------
    event_id : str
        Identifier of the event (window models look their coefficients up by it).
    t : array_like, shape (n_samples,), s
        Finite, strictly increasing sample times.
    A : array_like, shape (n_samples, n_sections), m
        Vibration amplitudes (envelopes) of the instrumented sections.
    U : array_like, shape (n_samples, n_sections), m/s
        Mean wind speed at each section.
    dA : array_like, shape (n_samples, n_sections), m/s, optional
        dA/dt; needed to fit, not to predict or simulate (None: absent).
    noise_std : array_like, shape (n_sections,), m, optional
        Noise floor of A per section (the identification's ``noise_std_m``;
        NaN: unknown). Identifiability verdicts use it: below a few times the
        floor A is the envelope of noise and no model can give its regime.
        None: not known.
    yaw : array_like, shape (n_samples, n_sections), degrees, optional
        Angle between the low-passed mean wind and the span's normal (0:
        perpendicular), e.g. the identification result's ``yaw``
        (:func:`vivbench.preprocess.mean_yaw`); NaN where unknown, None: not
        measured. The realistic aerodynamics fall off with it, and
        U = V ``|sin theta|`` does not carry it.
    wind_distance : array_like, shape (n_sections,), m, optional
        Distance from each section to the anemometer its wind was taken from
        (the event's ``wind_distance_m_<section>``; 0: measured there). None:
        not recorded (one anemometer per section). The varying campaign
        model's errors-in-variables treatment adds the wind's spanwise
        decorrelation over this distance to the wind's error.

    Notes
    -----
    NaN in ``A``, ``U`` or ``dA`` means "no sample": models skip such samples
    when fitting and return NaN there when evaluating. The arrays are copied
    and made read-only. Records compare by identity (arrays have no single
    truth value).
    """

    event_id: str
    t: np.ndarray
    A: np.ndarray
    U: np.ndarray
    dA: np.ndarray | None = None
    noise_std: np.ndarray | None = None
    yaw: np.ndarray | None = None
    wind_distance: np.ndarray | None = None

    def __post_init__(self) -> None:
        if not isinstance(self.event_id, str) or not self.event_id:
            raise ValueError(f"Record.event_id must be a non-empty string; got {self.event_id!r}")
        t = _frozen_array("t", self.t)
        if t.ndim != 1 or t.size < 1:
            raise ValueError(f"Record.t must have shape (n_samples,) with n_samples >= 1; got {t.shape}")
        if not np.all(np.isfinite(t)):
            raise ValueError("Record.t must be finite everywhere (NaN is allowed in A, U and dA only)")
        if np.any(np.diff(t) <= 0):
            raise ValueError("Record.t must be strictly increasing")
        A = _frozen_array("A", self.A)
        if A.ndim != 2 or A.shape[0] != t.size or A.shape[1] < 1:
            raise ValueError(f"Record.A must have shape (n_samples, n_sections) = ({t.size}, S >= 1); got {A.shape}")
        U = _frozen_array("U", self.U, A.shape)
        dA = None if self.dA is None else _frozen_array("dA", self.dA, A.shape)
        noise = None if self.noise_std is None else _frozen_array("noise_std", self.noise_std, (A.shape[1],))
        if noise is not None and np.any(noise < 0):
            raise ValueError("Record.noise_std must be >= 0 (m) or NaN (unknown)")
        yaw = None if self.yaw is None else _frozen_array("yaw", self.yaw, A.shape)
        dist = None if self.wind_distance is None else _frozen_array("wind_distance", self.wind_distance, (A.shape[1],))
        if dist is not None and not np.all(np.isfinite(dist) & (dist >= 0)):
            raise ValueError("Record.wind_distance must be finite distances >= 0 (m)")
        for name, value in (("t", t), ("A", A), ("U", U), ("dA", dA), ("noise_std", noise), ("yaw", yaw),
                            ("wind_distance", dist)):
            object.__setattr__(self, name, value)

    @property
    def n_samples(self) -> int:
        """Number of samples."""
        return int(self.t.size)

    @property
    def n_sections(self) -> int:
        """Number of instrumented sections S."""
        return int(self.A.shape[1])

    def valid(self, *, need_dA: bool = False) -> np.ndarray:
        """Samples with finite A and U in every section (and dA if ``need_dA``), shape (n_samples,)."""
        ok = np.isfinite(self.A).all(axis=1) & np.isfinite(self.U).all(axis=1)
        if need_dA:
            if self.dA is None:
                raise ValueError(f"record {self.event_id!r} has no dA (needed to fit)")
            ok &= np.isfinite(self.dA).all(axis=1)
        return ok

    def __repr__(self) -> str:
        span = f"{self.t[0]:g}..{self.t[-1]:g} s"
        return (f"Record(event_id={self.event_id!r}, n_samples={self.n_samples}, n_sections={self.n_sections}, "
                f"t={span}, dA={'yes' if self.dA is not None else 'no'}, yaw={'yes' if self.yaw is not None else 'no'})")
