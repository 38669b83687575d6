"""Regimes of the truth over windows (docs/concepts.md (regimes) applied to the generator's order contributions)."""

from __future__ import annotations

import numpy as np
import xarray as xr

from vivbench.core.regime import classify_regime

__all__ = ["truth_window_regimes"]


def truth_window_regimes(truth: xr.Dataset, window_start: np.ndarray, window_end: np.ndarray, tau: float = 0.2) -> np.ndarray:
    """True regime of each window and section.

    Parameters
    ----------
    truth : the ``/truth`` group of an event (time, A, r)
    window_start, window_end : ndarray, shape (W,), s

    Returns
    -------
    regime : ndarray of int8, shape (W, n_sections); 0 where the window holds no truth sample
    """
    t = truth["time"].values
    A = truth["A"].values
    r = truth["r"].values
    out = np.zeros((len(window_start), A.shape[1]), dtype=np.int8)
    # Windows are few (about 100 per event): one vectorised rule call per window.
    for w, (t0, t1) in enumerate(zip(window_start, window_end)):
        m = (t >= t0) & (t <= t1)
        if m.any():
            out[w] = classify_regime(r[m], A[m], tau=tau, axis=0)
    return out

