"""The campaign-model file ``campaign.pooled.nc``."""

from __future__ import annotations

from pathlib import Path

from vivbench.io.netcdf import write_netcdf_atomic

__all__ = ["POOLED_NAME", "write_pooled"]

POOLED_NAME = "campaign.pooled.nc"


def write_pooled(ds, out_dir) -> Path:
    """Write a pooled result atomically as ``out_dir/campaign.pooled.nc``."""
    return Path(write_netcdf_atomic(ds, Path(out_dir) / POOLED_NAME))
