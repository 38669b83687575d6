"""Wind of field records: instrument formats to east/north/up, and anemometers to deck sections.

An anemometer reports either the event format's components (``"enu"``: u
towards east, v towards north, w up), components in its own frame
(``"instrument"``: u along the instrument's x axis, which points at
``heading_deg`` degrees clockwise from north, v along its y axis 90 degrees
counter-clockwise from x seen from above, w up), or the horizontal speed and
the direction the wind comes from (``"speed_direction"``: meteorological
convention, degrees clockwise from north; w optional). The wind at a deck
section is taken from the anemometers along the span by a rule: the nearest
anemometer, or linear interpolation between the two that bracket the section
(the nearest beyond the outermost ones).
"""

from __future__ import annotations

import numpy as np

__all__ = ["WIND_FORMATS", "WIND_RULES", "to_east_north_up", "span_weights"]

#: Channels of each wind format: (required, optional).
WIND_FORMATS = {
    "enu": (("u", "v", "w"), ()),
    "instrument": (("u", "v", "w"), ()),
    "speed_direction": (("speed", "direction"), ("w",)),
}
#: Rules that give the wind at a deck section from the anemometers along the span.
WIND_RULES = ("nearest", "interpolation")


def to_east_north_up(fmt: str, channels: dict, heading_deg: float | None = None):
    """East, north and up wind components from an anemometer's channels.

    Parameters
    ----------
    fmt : {"enu", "instrument", "speed_direction"}
    channels : dict of numpy.ndarray, each shape (n,)
        ``u, v, w`` (enu, instrument) or ``speed, direction`` and optionally
        ``w`` (speed_direction); speeds in one unit, direction in degrees.
    heading_deg : float, optional
        Direction of the instrument's x axis, degrees clockwise from north
        (``"instrument"`` only).

    Returns
    -------
    tuple of numpy.ndarray
        ``(east, north, up)``, each shape (n,), in the channels' speed unit;
        ``up`` is NaN when a speed_direction record has no ``w``.
    """
    if fmt == "enu":
        return channels["u"], channels["v"], channels["w"]
    if fmt == "instrument":
        h = np.deg2rad(heading_deg)
        u, v = channels["u"], channels["v"]
        # x axis (sin h, cos h) in (east, north); y axis 90 degrees counter-clockwise: (-cos h, sin h).
        return u * np.sin(h) - v * np.cos(h), u * np.cos(h) + v * np.sin(h), channels["w"]
    if fmt == "speed_direction":
        s, d = channels["speed"], np.deg2rad(channels["direction"])
        # The wind blows towards direction + 180 degrees.
        up = channels["w"] if "w" in channels else np.full(s.shape, np.nan)
        return -s * np.sin(d), -s * np.cos(d), up
    raise ValueError(f"unknown wind format {fmt!r}; allowed: {', '.join(WIND_FORMATS)}")


def span_weights(anemometers_m, sections_m, rule: str = "nearest"):
    """Weights that give the wind at each section from the anemometers, and each section's distance to its nearest one.

    Parameters
    ----------
    anemometers_m : array_like, shape (n_anem,)
        Anemometer positions along the span, m.
    sections_m : array_like, shape (n_sec,)
        Section positions along the span, m.
    rule : {"nearest", "interpolation"}
        Nearest anemometer (the first of equally near ones), or linear
        interpolation between the two that bracket the section (the nearest
        outside the outermost anemometers).

    Returns
    -------
    weights : numpy.ndarray, shape (n_anem, n_sec)
        Non-negative, each column sums to 1: ``wind_sec = wind_anem @ weights``.
    distance_m : numpy.ndarray, shape (n_sec,)
        Distance from each section to its nearest anemometer, m.
    """
    a = np.asarray(anemometers_m, dtype=np.float64)
    s = np.asarray(sections_m, dtype=np.float64)
    if rule not in WIND_RULES:
        raise ValueError(f"unknown wind rule {rule!r}; allowed: {', '.join(WIND_RULES)}")
    gap = np.abs(a[:, None] - s[None, :])
    nearest = np.argmin(gap, axis=0)
    distance = gap[nearest, np.arange(s.size)]
    weights = np.zeros((a.size, s.size))
    weights[nearest, np.arange(s.size)] = 1.0
    if rule == "interpolation" and a.size > 1:
        order = np.argsort(a, kind="stable")
        pos = a[order]
        inside = (s > pos[0]) & (s < pos[-1])
        hi = np.clip(np.searchsorted(pos, s, side="right"), 1, pos.size - 1)
        lo = hi - 1
        frac = (s - pos[lo]) / np.where(pos[hi] > pos[lo], pos[hi] - pos[lo], 1.0)
        cols = np.flatnonzero(inside)
        weights[:, cols] = 0.0
        weights[order[lo[cols]], cols] = 1.0 - frac[cols]
        weights[order[hi[cols]], cols] += frac[cols]
    return weights, distance
