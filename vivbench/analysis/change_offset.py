"""The offset statistic of the model change scan: a step of the linear coefficient after a split of the events.

A step of the structural damping ratio by delta zeta between events shifts the amplitude
equation's net linear coefficient by -2 pi f delta zeta (1/s) at every wind speed and
amplitude: one number per equation, not a change of every coefficient curve. The scan
(:func:`vivbench.analysis.changes.statistics_change_scan` with ``statistic="offset"``) asks,
for every split of the events, how much the campaign model's penalised residual sum of
squares drops when the events after the split get that one extra, unpenalised column
x = A / a_ref over their samples. With the whole campaign's fit c0 (system H = G + mu P), the
drop of a column z is (z' e)^2 / (z'z - z'X H^-1 X'z), e = y - X c0: sums over the events after
the split of per-event scalars and vectors, so every split of every permuted ordering costs
a few additions, where the refits of the ``max`` statistic solve a system per split.

The column needs no new statistics: the wind basis is a B-spline basis, whose functions sum
to one, so x is the sum of the linear order's yaw-free columns of the first wind input.
"""

from __future__ import annotations

import numpy as np
from scipy.linalg import cho_factor, cho_solve, solve_triangular

from vivbench.regression.penalised import penalty_scale

__all__ = ["linear_columns", "offset_gain", "offset_parts"]


def linear_columns(st: dict) -> np.ndarray:
    """Columns whose sum is the design's own A column, shape (p,) bool: the linear order's yaw-free B-splines
    of the first wind input (B-splines sum to one, so the sum over m of B_m(U) A / a_ref is A / a_ref)."""
    M = int(st["n_basis"])
    L = M * int(st.get("n_inputs", 1))
    p = st["G"].shape[-1]
    out = np.zeros(p, dtype=bool)
    out[L * (p // (4 * L)):L * (p // (4 * L)) + M] = True  # order 1 starts after order 0's (J + 1) L columns
    return out


def offset_parts(stats: list[dict]) -> list[dict]:
    """Per equation, what the offset statistic needs of every event: the whole campaign's penalised fit c0 on
    the kept columns, then r_e = x'(y - X c0) over the event, w_e = L^-1 X' x (L the Cholesky factor of the
    penalised system) and x'x over the event, with x = A / a_ref (:func:`linear_columns`), and the fit's RSS."""
    out = []
    for st in stats:
        idx = np.flatnonzero(st["keep"])
        v = linear_columns(st)
        G, b = st["G"], st["b"]
        Gs, bs = G.sum(axis=0), b.sum(axis=0)
        Gk = Gs[idx[:, None], idx]
        # the scan's penalised system (as its refits build it): relative penalty times trace(G) / trace(P)
        H = Gk + float(st["penalty"]) * float(penalty_scale(Gs, st["P"])) * st["P"][idx[:, None], idx]
        H[np.diag_indices_from(H)] += 1e-10 * float(np.trace(Gk)) / max(idx.size, 1)
        chol = cho_factor(H, lower=True)
        c0 = cho_solve(chol, bs[idx])
        full = float(st["yy"].sum() - 2.0 * c0 @ bs[idx] + c0 @ Gk @ c0)
        Gv = G[:, :, v].sum(axis=2)  # (E, p): X_e' x
        r = b[:, v].sum(axis=1) - Gv[:, idx] @ c0  # (E,)
        w = solve_triangular(chol[0], Gv[:, idx].T, lower=True).T  # (E, q)
        xx = Gv[:, v].sum(axis=1)  # (E,)
        out.append({"r": r, "w": w, "xx": xx, "full": max(full, 1e-300)})
    return out


def offset_gain(parts: list[dict], order: np.ndarray, splits: np.ndarray) -> np.ndarray:
    """Relative drop of the penalised RSS when the events after each split get their own offset of the linear
    coefficient (one more unpenalised column, x = A over those events), summed over equations.

    parts: :func:`offset_parts`; order (R, E) event orderings; splits (K,) numbers of events before the split;
    returns (R, K). The drop of a column z added to a penalised fit is (z' e)^2 / (z'z - z'X H^-1 X'z), e the
    fit's residual: sums over the events after the split of the events' r, w and x'x.
    """
    R, E = order.shape
    gain = np.zeros((R, splits.size))
    for part in parts:
        # running sums from the end of every ordering: entry k holds the sum over positions k, ..., E - 1
        r = np.cumsum(part["r"][order][:, ::-1], axis=1)[:, ::-1][:, splits]
        w = np.cumsum(part["w"][order][:, ::-1], axis=1)[:, ::-1][:, splits]
        xx = np.cumsum(part["xx"][order][:, ::-1], axis=1)[:, ::-1][:, splits]
        denom = xx - (w * w).sum(axis=-1)
        with np.errstate(invalid="ignore", divide="ignore"):
            g = np.where(denom > 1e-12 * np.maximum(xx, 1e-300), r * r / denom, 0.0)
        gain += g / part["full"]
    return gain
