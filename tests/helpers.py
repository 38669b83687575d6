"""The shared tolerance helper: every test compares numbers through it.

A tolerance looser than the defaults must come with a ``reason`` saying why
(noise level, record length, discretisation), so that loosening is deliberate.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

#: The repository's root (this file is tests/helpers.py): where docs/, examples/ and reports/ are found.
REPO = Path(__file__).resolve().parents[1]

DEFAULT_RTOL = 1e-9
DEFAULT_ATOL = 0.0


def assert_close(actual, desired, *, rtol: float = DEFAULT_RTOL, atol: float = DEFAULT_ATOL, reason: str | None = None, what: str = "") -> None:
    """``numpy.testing.assert_allclose`` with a mandatory reason for loose tolerances."""
    _check_reason(rtol, atol, reason)
    np.testing.assert_allclose(actual, desired, rtol=rtol, atol=atol, err_msg=f"{what} (tolerance: {reason or 'default'})")


def _check_reason(rtol: float, atol: float, reason: str | None) -> None:
    if (rtol > DEFAULT_RTOL or atol > DEFAULT_ATOL) and not reason:
        raise AssertionError("a tolerance looser than the default needs a reason")


def is_close(actual, desired, *, rtol: float = DEFAULT_RTOL, atol: float = DEFAULT_ATOL, reason: str | None = None) -> bool:
    """True where every element of ``actual`` is within ``atol + rtol |desired|`` of ``desired`` (NaN equal to NaN).

    For a closeness test inside an expression (say, "one of these"); a bare check is :func:`assert_close`.
    """
    _check_reason(rtol, atol, reason)
    return bool(np.all(close_mask(actual, desired, rtol=rtol, atol=atol, reason=reason)))


def close_mask(actual, desired, *, rtol: float = DEFAULT_RTOL, atol: float = DEFAULT_ATOL, reason: str | None = None):
    """Elementwise closeness of broadcast ``actual`` and ``desired`` (bool array; NaN equal to NaN)."""
    _check_reason(rtol, atol, reason)
    a = np.asarray(actual, dtype=float)
    d = np.asarray(desired, dtype=float)
    with np.errstate(invalid="ignore"):
        near = np.abs(a - d) <= atol + rtol * np.abs(d)
    return near | (np.isnan(a) & np.isnan(d)) | ((a == d) & np.isinf(a))


def assert_not_close(actual, desired, *, rtol: float = DEFAULT_RTOL, atol: float = DEFAULT_ATOL,
                     reason: str | None = None, what: str = "") -> None:
    """Fail unless some element of ``actual`` differs from ``desired`` by more than ``atol + rtol |desired|``.

    NaN at the same place in both counts as equal. A tolerance looser than the defaults needs a
    ``reason``, as in :func:`assert_close` (a loose tolerance makes this check stricter).
    """
    if is_close(actual, desired, rtol=rtol, atol=atol, reason=reason):
        raise AssertionError(f"{what}: expected a difference beyond rtol={rtol}, atol={atol}; the two agree "
                             f"(tolerance: {reason or 'default'})")


def relative_rms(actual, desired) -> float:
    """RMS of the difference relative to the RMS of ``desired``."""
    actual = np.asarray(actual, dtype=float)
    desired = np.asarray(desired, dtype=float)
    return float(np.sqrt(np.mean((actual - desired) ** 2)) / np.sqrt(np.mean(desired**2)))


def change_records(n: int = 12, change_at: int | None = None, *, scale: float = 1.0, shift: float = 0.0,
                   seed: int = 0) -> list:
    """Single-section records of dA/dt = a1(U) A - 2 A^3 + noise with a change the wind does not carry.

    a1(U) = -0.01 + 0.05 exp(-((U - 9) / 1.5)^2 / 2) (1/s, U in m/s); from event
    ``change_at`` on, its self-excitation is multiplied by ``scale`` and ``shift``
    (1/s, negative: more damped) is added. ``change_at=None``: no change.
    """
    from vivbench.core import Record

    rng = np.random.default_rng(seed)
    out = []
    for e in range(n):
        t = np.arange(0.0, 900.0, 1.0)
        U = 6.0 + 6.0 * rng.random() + 2.0 * np.sin(2 * np.pi * t / (500 + 60 * e) + e)
        A = 0.05 + 0.1 * rng.random() * (1 + np.sin(2 * np.pi * t / 300 + e))
        changed = change_at is not None and e >= change_at
        a1 = -0.01 + (scale if changed else 1.0) * 0.05 * np.exp(-0.5 * ((U - 9.0) / 1.5) ** 2) + (shift if changed else 0.0)
        dA = a1 * A - 2.0 * A**3 + 2e-4 * rng.standard_normal(t.size)
        out.append(Record(event_id=f"E{e + 1:03d}", t=t, A=A[:, None], U=U[:, None], dA=dA[:, None]))
    return out


def bell(U, centre_m_s: float = 10.0):
    """Net linear coefficient a_1(U) with a Gaussian lock-in bell, 1/s.

    Parameters
    ----------
    U : array_like, m/s
        Wind speed.
    centre_m_s : float, m/s
        Wind at the bell's top.

    Returns
    -------
    ndarray, shape of ``U``, 1/s
        -0.01 + 0.05 exp(-((U - centre_m_s) / 1.5)^2 / 2): damped (-0.01 1/s) off lock-in,
        self-excited (+0.04 1/s) at its centre, 1.5 m/s wide.
    """
    return -0.01 + 0.05 * np.exp(-0.5 * ((U - centre_m_s) / 1.5) ** 2)


def bell_records(n_events: int, *, seed: int, duration_s: float, dt_s: float, mode_shape,
                 wind_period_s: tuple[float, float], amplitude_period_s: float,
                 wind_low_m_s: float = 7.0, wind_spread_m_s: float = 6.0,
                 wind_offsets_m_s: float = 0.0, wind_walk_m_s: float = 0.0,
                 section_swing_m_s: float = 0.0, section_swing_period_s: tuple[float, float, float] = (170.0, 37.0, 11.0),
                 section_swing_phased: bool = True,
                 yaw_deg: float = 0.0, yaw_period_s: float = 700.0, yaw_in_truth: bool = False,
                 bell_centre_m_s: float = 10.0, wind_shares=None, wind_weights=None,
                 a0: float = 0.0, a3: float = -2.0, modal: bool = False, noise_m_s: float = 0.0) -> list:
    """Synthetic records of dA/dt = a0 + a_1 A + a3 A^3 (+ noise) whose a_1 is a lock-in :func:`bell` of the wind.

    Event e (0-based, ``event_id`` ``f"E{e:03d}"``) has samples ``arange(0, duration_s, dt_s)`` and

    * a deck wind U0(t) = wind_low_m_s + wind_spread_m_s r + 2 sin(2 pi t / (P0 + P1 e) + e) m/s,
      (P0, P1) = ``wind_period_s``;
    * section k's wind U0 plus, in this order, a persistent offset drawn uniformly in
      +-``wind_offsets_m_s``, a swing ``section_swing_m_s`` sin(2 pi t / (S0 + S1 k + S2 e) [+ k + e]),
      (S0, S1, S2) = ``section_swing_period_s`` (the phase k + e where ``section_swing_phased``), and a
      random walk ``wind_walk_m_s`` cumsum(N(0, 1)) / 30 (its standard deviation after 900 samples is
      ``wind_walk_m_s``);
    * a modal amplitude Q(t) = 0.05 + 0.1 r' (1 + sin(2 pi t / ``amplitude_period_s`` + e)) m and
      section amplitudes A_k = ``mode_shape``_k Q;
    * where ``yaw_deg``: a yaw ``yaw_deg`` sin(2 pi t / ``yaw_period_s`` + e) degrees at every section,
      stored in the record; ``yaw_in_truth`` multiplies a_1 by cos^2(yaw).

    a_1 is ``bell(U_k, bell_centre_m_s)`` at each section's own wind; with ``wind_shares`` s_j, the
    sum over sections sum_j s_j bell(U_j) in every equation; with ``wind_weights`` w_j, bell(sum_j w_j U_j).
    ``modal=False``: each section's A_k follows the equation; ``modal=True``: Q follows it and
    dA_k/dt = ``mode_shape``_k dQ/dt. Random numbers are drawn per event in the order r, offsets,
    walk, r', noise, so each option leaves the other draws where they were.

    Parameters
    ----------
    n_events : int
        Number of events.
    seed : int
        Seed of ``numpy.random.default_rng``.
    duration_s, dt_s : float, s
        Record length and sample step.
    mode_shape : array_like, shape (n_sections,)
        Each section's amplitude relative to Q (also fixes the number of sections).
    wind_period_s : (float, float), s
        The deck wind's swing period P0 + P1 e.
    amplitude_period_s : float, s
        Period of Q's swing.
    wind_low_m_s, wind_spread_m_s : float, m/s
        Event mean wind uniform in [low, low + spread) (before the +-2 m/s swing).
    wind_offsets_m_s, wind_walk_m_s, section_swing_m_s : float, m/s
        Section winds' departures from the deck wind (0: none, and nothing drawn for it).
    section_swing_period_s : (float, float, float), s
        Swing period S0 + S1 k + S2 e.
    section_swing_phased : bool
        Add the phase k + e (rad) to the section swing.
    yaw_deg : float, degrees
        Yaw amplitude (0: the records carry no yaw).
    yaw_period_s : float, s
        Yaw period.
    yaw_in_truth : bool
        a_1 falls off as cos^2(yaw).
    bell_centre_m_s : float, m/s
        The bell's centre.
    wind_shares, wind_weights : array_like, shape (n_sections,), optional
        At most one of them: see above.
    a0 : float, m/s
        Constant term (0: none added).
    a3 : float, 1/(m^2 s)
        Cubic coefficient.
    modal : bool
        Q, not each A_k, follows the equation (needs ``wind_weights``: one a_1 for the mode).
    noise_m_s : float, m/s
        Standard deviation of white noise added to dA/dt (0: noise-free, nothing drawn).

    Returns
    -------
    list of Record
        ``n_events`` records with ``dA`` (and ``yaw`` where ``yaw_deg``).
    """
    from vivbench.core import Record

    if wind_shares is not None and wind_weights is not None:
        raise ValueError("give wind_shares or wind_weights, not both")
    if modal and wind_weights is None:
        raise ValueError("modal=True needs wind_weights: the mode follows one linear coefficient")
    if yaw_in_truth and (modal or not yaw_deg):
        raise ValueError("yaw_in_truth needs yaw_deg and modal=False")
    shape = np.asarray(mode_shape, dtype=float)
    S = shape.size
    rng = np.random.default_rng(seed)
    out = []
    for e in range(n_events):
        t = np.arange(0.0, duration_s, dt_s)
        base = wind_low_m_s + wind_spread_m_s * rng.random() + 2.0 * np.sin(
            2 * np.pi * t / (wind_period_s[0] + wind_period_s[1] * e) + e)
        U = np.repeat(base[:, None], S, axis=1)
        if wind_offsets_m_s:
            U = U + rng.uniform(-wind_offsets_m_s, wind_offsets_m_s, S)[None, :]
        if section_swing_m_s:
            p0, p1, p2 = section_swing_period_s
            phases = [2 * np.pi * t / (p0 + p1 * k + p2 * e) for k in range(S)]
            if section_swing_phased:
                phases = [x + k + e for k, x in enumerate(phases)]
            U = U + section_swing_m_s * np.stack([np.sin(x) for x in phases], axis=1)
        if wind_walk_m_s:
            U = U + wind_walk_m_s * rng.standard_normal((t.size, S)).cumsum(axis=0) / 30.0
        Q = 0.05 + 0.1 * rng.random() * (1 + np.sin(2 * np.pi * t / amplitude_period_s + e))
        yaw = np.repeat((yaw_deg * np.sin(2 * np.pi * t / yaw_period_s + e))[:, None], S, axis=1) if yaw_deg else None
        if wind_weights is not None:
            a1 = bell(U @ np.asarray(wind_weights), bell_centre_m_s)
            a1 = a1 if modal else a1[:, None]
        elif wind_shares is not None:
            a1 = (bell(U, bell_centre_m_s) * np.asarray(wind_shares)).sum(axis=1, keepdims=True)
        else:
            a1 = bell(U, bell_centre_m_s)
        if yaw_in_truth:
            a1 = a1 * np.cos(np.radians(yaw)) ** 2
        x = Q if modal else Q[:, None] * shape[None, :]  # the amplitude the equation is written in
        linear = a1 * x
        if a0:
            linear = a0 + linear
        dx = linear + a3 * x**3
        A, dA = (Q[:, None] * shape, dx[:, None] * shape) if modal else (x, dx)
        if noise_m_s:
            dA = dA + noise_m_s * rng.standard_normal(A.shape)
        out.append(Record(event_id=f"E{e:03d}", t=t, A=A, U=U, dA=dA, yaw=yaw))
    return out


def run_cli(*argv):
    """``vivbench <argv>`` in this process (no interpreter start-up): its exit code and its output.

    Returns an object with ``returncode``, ``stdout`` and ``stderr`` as ``subprocess.run(...,
    capture_output=True, text=True)`` gives them. argparse's refusals (SystemExit) give their exit code.
    """
    import contextlib
    import io
    from types import SimpleNamespace

    from vivbench.cli import main

    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            code = main([str(a) for a in argv])
        except SystemExit as exc:
            code = exc.code if isinstance(exc.code, int) else 1
    return SimpleNamespace(returncode=code, stdout=out.getvalue(), stderr=err.getvalue())


def with_gap(record, start: int, length: int):
    """``record`` without its samples start..start + length - 1 (missing without NaN: a gap in its time), and the
    times just before and after the gap, s."""
    import dataclasses

    keep = np.ones(record.n_samples, dtype=bool)
    keep[start:start + length] = False
    fields = {name: getattr(record, name)[keep] for name in ("t", "A", "U", "dA") if getattr(record, name) is not None}
    yaw = None if record.yaw is None else record.yaw[keep]
    return dataclasses.replace(record, **fields, yaw=yaw), float(record.t[start - 1]), float(record.t[start + length])


def assert_stops_at_the_gap(model, record, start: int = 300, length: int = 200):
    """A simulation over a record with a gap stops at its far side, saying so, and matches the run that ends before
    it: no model integrates across samples it has no wind for."""
    gapped, before, after = with_gap(record, start, length)
    sim = model.simulate(gapped)
    assert sim.stopped_at == after and "a gap" in sim.reason, (sim.stopped_at, sim.reason)
    alone = model.simulate(gapped, gapped.t[0], before)
    n = alone.t.size
    assert np.array_equal(sim.A_sim[:n], alone.A_sim, equal_nan=True)
    assert np.isnan(sim.A_sim[n:]).all()
    assert sim.covered < 1.0
