"""A record that also carries the mean wind's yaw, the second covariate of the varying-coefficient model."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from vivbench.core.record import Record

__all__ = ["YawRecord", "record_yaw"]


@dataclass(frozen=True, kw_only=True, eq=False)
class YawRecord(Record):
    """A :class:`~vivbench.core.Record` with the yaw of the mean wind at every sample.

    Parameters
    ----------
    yaw : array_like, shape (n_samples, n_sections), degrees
        Angle between the low-passed mean wind and the span's normal (0:
        perpendicular), e.g. from :func:`vivbench.preprocess.mean_yaw`; NaN
        where unknown. The realistic aerodynamics fall off with it, and
        U = V |sin theta| does not carry it.
    """

    yaw: np.ndarray | None = None

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.yaw is not None:
            y = np.array(self.yaw, dtype=float)
            if y.shape != self.A.shape:
                raise ValueError(f"YawRecord.yaw must have shape {self.A.shape} like A; got {y.shape}")
            y.setflags(write=False)
            object.__setattr__(self, "yaw", y)

    @classmethod
    def from_record(cls, record: Record, yaw) -> "YawRecord":
        """The record's data with ``yaw`` (degrees, shape (n_samples, n_sections)) added."""
        return cls(event_id=record.event_id, t=record.t, A=record.A, U=record.U, dA=record.dA,
                   noise_std=record.noise_std, yaw=yaw)


def record_yaw(record: Record) -> np.ndarray | None:
    """The record's yaw (degrees, (n_samples, n_sections)) or None when it carries none."""
    return getattr(record, "yaw", None)
