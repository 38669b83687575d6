"""Simulations of :class:`vivbench.models.VaryingCoefficientSINDy`: many runs integrated at once by RK4.

Each run's curves are evaluated at every sample and step midpoint of its span at
once (the wind is linear between samples); the runs are then integrated together,
one batched RK4 step at a time (:func:`vivbench.models.rk4`, each run on its own
time grid and with its own bounds), so that held-out scoring of many events costs
the steps of the longest run, not the sum of all runs' steps. A run's trajectory
does not depend on the others in its batch.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from vivbench.core.record import Record
from vivbench.models.integrate import StopRule, rk4
from vivbench.models.simulate import Simulation, gap_reason, nmse
from vivbench.preprocess.runs import first_gap

__all__ = ["simulate_runs"]


def _run_inputs(model, record: Record, t0, t1, A0, bound_factor: float) -> dict:
    """One run's grid, curves at the samples and midpoints (n, S, 4), measured A, start and upper bound."""
    t = record.t
    i0 = int(np.argmin(np.abs(t - (t[0] if t0 is None else float(t0)))))
    i1 = int(np.argmin(np.abs(t - (t[-1] if t1 is None else float(t1))))) + 1
    tt = t[i0:i1]
    S = model.n_sections_
    U = record.U[i0:i1]
    Umid = 0.5 * (U[:-1] + U[1:])
    yaw = model.record_yaw(record)
    yaw = None if yaw is None else yaw[i0:i1]
    ymid = None if yaw is None else 0.5 * (yaw[:-1] + yaw[1:])
    a = model.coefficient_values(U, yaw=yaw)  # (n, S, 4)
    am = model.coefficient_values(Umid, yaw=ymid) if tt.size > 1 else np.zeros((0, S, 4))
    x = np.asarray(record.A[i0] if A0 is None else A0, dtype=float).copy()
    if x.shape != (S,):
        raise ValueError(f"A0 must have shape ({S},) (one amplitude per section, m); got {x.shape}")
    top = bound_factor * np.nanmax(np.abs(record.A)) if np.isfinite(record.A).any() else np.inf
    gap = first_gap(t, i0, i1)  # no wind across a gap in the record: the run stops at its far side
    gap = None if gap is None else gap - i0
    if gap is not None:
        am = am.copy()
        am[gap:] = np.nan
    return {"t": tt, "a": a, "am": am, "A_meas": record.A[i0:i1], "x0": x, "top": top, "gap": gap}


def simulate_runs(model, runs: Sequence[tuple], bound_factor: float = 10.0) -> list[Simulation]:
    """Integrate a fitted varying-coefficient model over several spans of records at once (classical RK4).

    Parameters
    ----------
    model : VaryingCoefficientSINDy, fitted
    runs : sequence of (record, t0, t1, A0)
        Each a Record (checked by the model), the span's start and end in s (snapped to the
        record's samples; None: the record's first or last) and the initial amplitudes, shape
        (S,) in m (None: the record's A at t0).
    bound_factor : float
        A run stops when an amplitude leaves [-0.05, bound_factor] x its record's largest amplitude.

    Returns
    -------
    list of Simulation, one per run, in order
    """
    inputs = [_run_inputs(model, record, t0, t1, A0, bound_factor) for record, t0, t1, A0 in runs]
    if not inputs:
        return []
    S, B = model.n_sections_, len(inputs)
    T = max(r["t"].size for r in inputs)
    grid = np.full((T, B), np.nan)  # each run's grid, NaN after its end (the run stops there)
    a = np.full((T, B, S, 4), np.nan)
    am = np.full((max(T - 1, 0), B, S, 4), np.nan)
    for b, r in enumerate(inputs):  # runs, not samples
        n = r["t"].size
        grid[:n, b], a[:n, b], am[:n - 1, b] = r["t"], r["a"], r["am"]
    top = np.array([r["top"] for r in inputs])
    coef = (a, am, a)  # the curves at a step's start, midpoint and end (index n + 1)

    def f(y, n, stage):
        c = coef[stage][n + (stage == 2)]
        return c[..., 0] + y * (c[..., 1] + y * (c[..., 2] + y * c[..., 3]))

    run = rk4(f, np.stack([r["x0"] for r in inputs]), grid,
              stop=StopRule(upper=top, lower=-0.05 * top / bound_factor))
    out = []
    for b, r in enumerate(inputs):
        tt, n = r["t"], r["t"].size
        stop = int(run.stop[b])
        stopped = None if stop < 0 or stop >= n else float(tt[stop])  # past its grid's end: not stopped
        at_gap = r["gap"] is not None and stop == r["gap"] + 1
        reason = None if stopped is None else (gap_reason(tt, r["gap"]) if at_gap
                                                else "non-finite or out-of-bounds amplitude")
        covered = 1.0 if stopped is None else float((stopped - tt[0]) / max(tt[-1] - tt[0], 1e-12))
        x = run.x[:n, b]
        out.append(Simulation(t=tt, A_sim=x, A_meas=r["A_meas"], stopped_at=stopped, reason=reason,
                              nmse=nmse(x, r["A_meas"]), covered=covered,
                              windows=np.zeros(max(n - 1, 0), dtype=int)))
    return out
