"""NetCDF-4 files written atomically (temp file, fsync, rename) with light compression."""

from __future__ import annotations

import os
import secrets
from contextlib import contextmanager
from pathlib import Path

import numpy as np
import xarray as xr

__all__ = ["NETCDF_ENGINE", "atomic_path", "write_netcdf_atomic"]


# Compression: deflate level 1 gets most of level 4's size reduction for less CPU
# time. The byte-shuffle filter makes quantised float32 samples compress worse but
# float64 times much better, so it is used for 8-byte types only. Deflate rather
# than lzf because every netCDF-C/HDF5 reader can decode it.
_DEFLATE_LEVEL = 1


# The netCDF-C library (netCDF4-python) reads and writes these files faster than
# h5netcdf, whose per-variable bookkeeping in Python dominates the identification
# of short events.
NETCDF_ENGINE = "netcdf4"


_MIN_COMPRESSED_SIZE = 4096  # elements; smaller arrays are not worth a chunk index


_CHUNK_BYTES = 1 << 18


@contextmanager
def atomic_path(path, suffix: str = ""):
    """Yield a temporary path beside ``path``; on success it replaces ``path``.

    The temporary file is fsynced before the rename and the directory after
    it; on any failure it is removed and an existing file at ``path`` is
    untouched. Its name starts with a dot and does not end in ``.nc``, so
    globbing for event files never sees it. ``suffix`` keeps writers that
    choose a format by extension (matplotlib) happy.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.parent / f".{path.name}.tmp-{os.getpid()}-{secrets.token_hex(4)}{suffix}"
    try:
        yield tmp
        fd = os.open(tmp, os.O_RDONLY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    _fsync_directory(path.parent)


def write_netcdf_atomic(data: xr.Dataset | xr.DataTree, path) -> Path:
    """Write a Dataset or DataTree as NetCDF-4 atomically (see :func:`atomic_path`).

    Used for event files and for results (``*.identify.nc``).
    """
    path = Path(path)
    tree = data if isinstance(data, xr.DataTree) else xr.DataTree(dataset=data)
    with atomic_path(path) as tmp:
        tree.to_netcdf(tmp, mode="w", engine=NETCDF_ENGINE, encoding=_encoding(tree))
    return path


def _encoding(tree: xr.DataTree) -> dict:
    """Per-group encodings: no fill values (NaN is stored as is), deflate for big arrays."""
    out = {}
    for node in tree.subtree:
        ds = node.to_dataset(inherit=False)
        enc = {}
        for name, var in ds.variables.items():
            if var.dtype.kind in "OUS":
                enc[name] = {}
                continue
            e = {"_FillValue": None}
            if var.size >= _MIN_COMPRESSED_SIZE:
                row_bytes = var.dtype.itemsize * int(np.prod(var.shape[1:], dtype=np.int64))
                rows = max(1, min(var.shape[0], _CHUNK_BYTES // max(row_bytes, 1)))
                e.update(
                    zlib=True,
                    complevel=_DEFLATE_LEVEL,
                    shuffle=var.dtype.itemsize >= 8,
                    chunksizes=(rows, *var.shape[1:]),
                )
            enc[name] = e
        out[node.path] = enc
    return out


def _fsync_directory(directory: Path) -> None:
    # Makes the rename itself durable on POSIX; some platforms cannot open a
    # directory, and the file's content is already on disk then.
    try:
        fd = os.open(directory, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)

