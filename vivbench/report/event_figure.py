"""Overview figure of one event: wind, acceleration and (synthetic) truth regimes."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import xarray as xr  # noqa: E402

from vivbench.core.terms import reference_section
from vivbench.io.netcdf import atomic_path

__all__ = ["event_figure"]

_REGIME_COLOURS = {1: "#9e9e9e", 2: "#4c9be8", 3: "#f0a030", 4: "#d62728"}


def event_figure(tree: xr.DataTree, path: str | Path, *, section: str | None = None) -> Path:
    """Write a PNG with wind speed and direction, acceleration, amplitude and regime.

    Parameters
    ----------
    tree : an event (docs/formats.md)
    path : output PNG (written atomically)
    section : which section's acceleration and amplitude to show (default the middle one, S2 of three)

    Returns
    -------
    Path of the figure.
    """
    wind = tree["wind"].ds
    accel = tree["accel"].ds
    names = [str(s) for s in accel["section"].values.tolist()]
    if section is None:
        section = names[reference_section(len(names))]
    elif section not in names:
        raise ValueError(f"section {section!r} is not in the event; its sections are {names}")
    truth = tree["truth"].ds if "truth" in tree.children else None
    az = float(tree.attrs["span_azimuth_deg"])
    tw = wind["time"].values
    u = wind["u"].sel(section=section).values.astype(float)
    v = wind["v"].sel(section=section).values.astype(float)
    speed = np.hypot(u, v)
    direction = np.mod(np.degrees(np.arctan2(-u, -v)), 360.0)
    perp = speed * np.abs(np.sin(np.radians(direction - az)))
    n_rows = 4 if truth is not None else 2
    ratios = [3, 3, 2, 1][:n_rows]
    fig, axes = plt.subplots(n_rows, 1, figsize=(9, 1.9 * n_rows + 0.8), sharex=True, constrained_layout=True,
                             gridspec_kw={"height_ratios": ratios})
    ax = axes[0]
    step = max(1, tw.size // 20000)
    ax.plot(tw[::step] / 60, perp[::step], lw=0.4, color="0.6", label="perpendicular component (32 Hz)")
    if truth is not None:
        ax.plot(truth["time"].values / 60, truth["U"].sel(section=section).values, color="k", lw=1.2, label="true mean U")
    ax.axhspan(5.5, 10.5, color="#4c9be8", alpha=0.08, label="lock-in range (default)")
    ax.set_ylabel("wind speed (m/s)")
    ax.legend(loc="upper right", fontsize=7, ncol=3)
    ax.set_title(f"event {tree.attrs['event_id']} ({tree.attrs.get('scenario', tree.attrs['source'])}), section {section}")
    ax = axes[1]
    ta = accel["time"].values
    a = accel["acc"].sel(section=section).values.astype(float)
    step = max(1, ta.size // 40000)
    ax.plot(ta[::step] / 60, a[::step], lw=0.3, color="#1f4e79")
    ax.set_ylabel("acceleration (m/s$^2$)")
    if truth is not None:
        tt = truth["time"].values / 60
        ax = axes[2]
        ax.plot(tt, truth["A"].sel(section=section).values, color="k")
        ax.set_ylabel("true amplitude A (m)")
        ax = axes[3]
        reg = truth["regime"].sel(section=section).values
        for k, colour in _REGIME_COLOURS.items():
            mask = reg == k
            ax.fill_between(tt, 0, 1, where=mask, color=colour, step="mid", label=f"regime {k}")
        ax.set_yticks([])
        ax.set_ylabel("regime")
        ax.legend(loc="center left", bbox_to_anchor=(1.0, 0.5), fontsize=7, ncol=1, frameon=False)
    axes[-1].set_xlabel("time since event start (min)")
    path = Path(path)
    try:
        with atomic_path(path, suffix=".png") as tmp:
            # No software tag or date in the PNG: the same event gives the same bytes.
            fig.savefig(tmp, dpi=110, metadata={"Software": None})
    finally:
        plt.close(fig)
    return path
