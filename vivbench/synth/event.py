"""One synthetic event: wind, full aeroelastic simulation, sensors and truth."""

from __future__ import annotations

import json
import math
from dataclasses import asdict, dataclass, replace

import numpy as np
import xarray as xr
from scipy.integrate import cumulative_trapezoid

from vivbench.io.event import build_event
from vivbench.core.regime import classify_regime
from vivbench.synth.aero import (
    amplitude_coefficients,
    exact_coefficients,
    modal_coefficients,
    order_contributions,
    truth_curves,
)
from vivbench.synth.config import ChangesConfig, GeneratorConfig, StructureConfig, config_to_dict
from vivbench.synth.sensors import accelerometer, add_dropouts, add_spikes, sample_times
from vivbench.synth.structure import modal_acceleration, simulate_amplitude, simulate_modal
from vivbench.synth.wind import (MeanWind, WindScript, anemometer_layout, at_anemometers, felt_mean_wind, mean_wind,
                                 measure_wind, section_records, wind_field)
from vivbench.core.terms import feature_exponents, feature_names
from vivbench.core.errors import InputError

__all__ = ["EventSpec", "SimulatedEvent", "simulate_event", "generate_event", "event_truth_curves",
           "TRUTH_CURVE_WIND"]

#: Wind grid of the truth's coefficient curves (docs/concepts.md (coefficient curves)), m/s: 2 to 16 m/s in steps of 0.1 m/s.
TRUTH_CURVE_WIND = np.arange(20, 161) / 10.0


@dataclass(frozen=True, kw_only=True)
class EventSpec:
    """What distinguishes one event of a campaign.

    Attributes
    ----------
    event_id : file stem, e.g. "E001"
    start_time : ISO 8601 UTC
    kind : name of the scenario the script was drawn from (informational)
    script : the scripted mean wind
    number : event number in its campaign, counted from 1 (E001 is 1); selects the
        slow changes' steps (:class:`~vivbench.synth.config.ChangesConfig`)
    campaign_time : s; start of the event since the campaign's start, the time
        origin of the damping drift
    """

    event_id: str
    start_time: str
    kind: str
    script: WindScript
    number: int = 1
    campaign_time: float = 0.0


@dataclass(frozen=True)
class SimulatedEvent:
    """Everything the generator computed for one event, before it becomes a file.

    Arrays (S sections): ``wind_time`` (n_w,) s; ``u, v, w`` (n_w, S) m/s float32; ``accel_time``
    (n_a,) s; ``acc`` (n_a, S) m/s^2 float32; ``acc_true`` (n_a, S) m/s^2 noise-free;
    ``q``, ``qd`` (n_a,) modal displacement (m) and velocity (m/s) at the accelerometer samples; ``truth_time``
    (n_t,) s; ``U`` (n_t, S) m/s; ``Q`` (n_t,) m averaged modal amplitude; ``r``
    (n_t, S, 4) m/s; ``regime`` (n_t, S); ``coef`` (S, 23 S) or None; ``defects`` dict; ``yaw``
    (n_t, S) degrees in [0, 90], the yaw's magnitude the averaged truth sees, when the aerodynamics depend on it
    (else None).
    With slow changes configured (else None): ``damping_ratio`` (n_t,) structural damping
    ratio, ``mass_factor`` (n_t,) mass multiplier and ``aero_factor`` (n_t, 4) multipliers of
    the aerodynamic parts of the orders 0..3, all dimensionless, on the truth grid.
    """

    wind_time: np.ndarray
    u: np.ndarray
    v: np.ndarray
    w: np.ndarray
    accel_time: np.ndarray
    acc: np.ndarray
    acc_true: np.ndarray
    q: np.ndarray
    qd: np.ndarray
    truth_time: np.ndarray
    U: np.ndarray
    Q: np.ndarray
    r: np.ndarray
    regime: np.ndarray
    coef: np.ndarray | None
    defects: dict
    damping_ratio: np.ndarray | None = None
    mass_factor: np.ndarray | None = None
    aero_factor: np.ndarray | None = None
    yaw: np.ndarray | None = None


_WIND_PAD = 64.0  # s


def _interp_wind(mw: MeanWind, t: np.ndarray) -> np.ndarray:
    return np.stack([np.interp(t, mw.t, mw.U[:, k]) for k in range(mw.U.shape[1])], axis=1)


def _interp_yaw(mw: MeanWind, t: np.ndarray, config: GeneratorConfig) -> np.ndarray | None:
    """Each section's yaw (degrees, shape (n, S)) at times t when the aerodynamics depend on it, else None."""
    if config.aero.yaw is None or mw.yaw is None:
        return None
    return np.stack([np.interp(t, mw.t, mw.yaw[:, k]) for k in range(mw.yaw.shape[1])], axis=1)


def _external_force(t: np.ndarray, mw: MeanWind, turb: np.ndarray, shedding_phase: np.ndarray,
                    config: GeneratorConfig) -> np.ndarray:
    """Buffeting plus unlocked Strouhal shedding, modal force per unit modal mass (m/s^2).

    ``mw`` is the felt mean wind (U_k) and ``turb`` (n_w, S, 3) the turbulence the deck
    feels (``WindField.deck``: the tributary average, or the anemometer's own turbulence
    in the ``in_library`` mode), both on the anemometer grid.
    """
    s, a = config.structure, config.aero
    rho, D, m = s.air_density, s.depth, s.mass
    beta = s.participation
    U = _interp_wind(mw, t)
    n_sec = U.shape[1]
    up = np.stack([np.interp(t, mw.t, turb[:, k, 0]) for k in range(n_sec)], axis=1)
    wp = np.stack([np.interp(t, mw.t, turb[:, k, 2]) for k in range(n_sec)], axis=1)
    phase = np.stack([np.interp(t, mw.t, shedding_phase[:, k]) for k in range(n_sec)], axis=1)
    buffet = rho * U * D * (a.buffeting_u * up + a.buffeting_w * wp)
    detuning = a.strouhal * U / D - s.frequency
    # Shedding near resonance is locked (counted in r0); the rest runs free and averages out.
    gate = 1.0 - np.exp(-((detuning / a.lock_bandwidth) ** 2))
    free = 0.5 * rho * D * U**2 * a.cl_unlocked * gate * np.sin(phase)
    return ((buffet + free) * beta).sum(axis=1) / m


def _modal_params(t: np.ndarray, mw: MeanWind, turb, shedding_phase, config: GeneratorConfig) -> np.ndarray:
    c = modal_coefficients(_interp_wind(mw, t), config.structure, config.aero, _interp_yaw(mw, t, config))
    f_ext = _external_force(t, mw, turb, shedding_phase, config)
    return np.stack([c["c_lin"], c["n1"], c["n2"], c["k_aero"], c["f_lock"], f_ext], axis=1)


# ------------------------------------------------------------ slow changes (docs/concepts.md (no inverse crime))


def _changed_structure(structure: StructureConfig, changes: ChangesConfig, number: int) -> StructureConfig:
    """The structure of event ``number`` after the steps: damping and mass scaled, frequency / sqrt(mass factor)."""
    mf = changes.mass_factor(number)
    return replace(structure, damping_ratio=structure.damping_ratio * changes.damping_factor(number),
                   mass=structure.mass * mf, frequency=structure.frequency / math.sqrt(mf))


def _drift(t: np.ndarray, spec: EventSpec, changes: ChangesConfig) -> np.ndarray:
    """Relative damping drift zeta(t) / zeta_e at event times t (s), shape of t."""
    return changes.drift(spec.campaign_time + np.asarray(t, dtype=float))


def _changed_modal_params(params: np.ndarray, t: np.ndarray, spec: EventSpec, changes: ChangesConfig,
                          structure: StructureConfig) -> np.ndarray:
    """Modal coefficients (n, 6) with the retrofit's aero factors and the drift's extra damping.

    The integrator holds the event's constant damping ratio zeta_e; the drift adds
    -2 zeta_e (drift(t) - 1) w1 to c_lin, so the total is -2 zeta(t) w1.
    """
    f = changes.aero_factors(spec.number)
    out = params.copy()
    out[:, 0] *= f[1]  # c_lin ~ Y1
    out[:, 1] *= f[2]  # n1 ~ Y1 e1
    out[:, 2] *= f[3]  # n2 ~ Y1 e2
    out[:, 4] *= f[0]  # f_lock ~ C_L
    if changes.drift_amplitude:
        out[:, 0] -= 2.0 * structure.damping_ratio * structure.omega * (_drift(t, spec, changes) - 1.0)
    return out


def _changed_amplitude_coefficients(U: np.ndarray, t: np.ndarray, spec: EventSpec, changes: ChangesConfig,
                                    structure: StructureConfig, config: GeneratorConfig,
                                    yaw: np.ndarray | None = None) -> np.ndarray:
    """p_0..p_3 of the averaged equation (n, 4) with the same aero factors, yaw and zeta(t) as the full model."""
    aero = amplitude_coefficients(U, replace(structure, damping_ratio=0.0), config.aero, yaw)
    coefs = aero * changes.aero_factors(spec.number)[None, :]
    coefs[:, 1] -= structure.damping_ratio * _drift(t, spec, changes) * structure.omega
    return coefs


def _changed_exact_coefficients(structure: StructureConfig, changes: ChangesConfig, spec: EventSpec,
                                config: GeneratorConfig) -> np.ndarray | None:
    """Exact coefficient matrix (S, 23 S) of an event with steps or a retrofit; None with a drift.

    A damping that drifts within the event has no constant coefficient matrix
    (the truth's r and damping_ratio stay exact).
    """
    Xi = exact_coefficients(replace(structure, damping_ratio=0.0), config.aero)
    if Xi is None or changes.drift_amplitude:
        return None
    ex = feature_exponents(structure.n_sections)
    Xi = Xi * changes.aero_factors(spec.number)[ex[:, 1]][None, :]
    for m in range(structure.n_sections):
        col = int(np.flatnonzero((ex[:, 0] == m) & (ex[:, 1] == 1) & (ex[:, 2] == 0))[0])
        Xi[m, col] -= structure.damping_ratio * structure.omega
    return Xi


def event_truth_curves(config: GeneratorConfig, number: int = 1, wind=TRUTH_CURVE_WIND) -> xr.DataArray | None:
    """The exact coefficient curves a_ki(U) of one event (docs/concepts.md (coefficient curves)), where they are well defined.

    Parameters
    ----------
    config : GeneratorConfig
        The campaign's configuration (before the event's slow changes).
    number : int
        The event's number in its campaign (from 1): selects the steps of the
        slow changes, if any.
    wind : array_like, shape (n_wind,), m/s
        Default :data:`TRUTH_CURVE_WIND`.

    Returns
    -------
    xarray.DataArray ``curves`` (equation, order, wind), m^(1-i)/s, or None
        :func:`vivbench.synth.truth_curves` of the event's structure. With slow
        changes, the event's own structure (damping, mass and frequency after
        the steps) and its aero factors on the aerodynamic part of each order;
        None with a damping drift (the curves would change within the event).
    """
    changes = config.changes
    if not changes.any:
        return truth_curves(config.structure, config.aero, wind)
    if changes.drift_amplitude:
        return None
    s = _changed_structure(config.structure, changes, number)
    curves = truth_curves(replace(s, damping_ratio=0.0), config.aero, wind)
    values = curves.values * changes.aero_factors(number)[None, :, None]
    values[:, 1, :] -= s.damping_ratio * s.omega
    return curves.copy(data=values)


def simulate_event(spec: EventSpec, config: GeneratorConfig, seed: np.random.SeedSequence | int) -> SimulatedEvent:
    """Simulate one event (no file written).

    Parameters
    ----------
    spec : EventSpec
    config : GeneratorConfig
    seed : SeedSequence or int
        Independent child streams are drawn for the mean wind, the turbulence,
        the shedding phases, the sensors and the defects, so switching on a
        defect does not change the wind or the structure's response. The
        turbulence stream draws the phases of the whole field (anemometers and,
        with ``felt_wind = "tributary"``, the tributary points, in one coherent
        simulation) and then the anemometer errors; no stream is added for the
        tributary field, so the other streams are the same in both modes.

    With slow changes (``config.changes``), the event's steps (``spec.number``)
    give its damping ratio, mass and frequency and its aero factors, and the
    damping drift runs on the campaign time ``spec.campaign_time + t``; the full
    simulation and the averaged truth use the same parameters.
    """
    ss = seed if isinstance(seed, np.random.SeedSequence) else np.random.SeedSequence(seed)
    changes = config.changes
    if changes.any:
        config = replace(config, structure=_changed_structure(config.structure, changes, spec.number))
    rng_mean, rng_turb, rng_shed, rng_sens, rng_def = (np.random.default_rng(c) for c in ss.spawn(5))
    s, wcfg, sens = config.structure, config.wind, config.sensors
    T = spec.script.duration
    defects = sens.defects

    # The anemometer grid doubles as the fine grid for the slowly varying inputs;
    # it extends past the record so that a late accelerometer clock is covered.
    accel_period = 1.0 / sens.rate
    n_acc = sample_times(T, sens.rate).size
    drift = 1.0 + defects.clock_drift_ppm * 1e-6
    t_first = defects.clock_offset
    # A fixed pad keeps the wind realisation independent of the clock defects
    # (beyond it, np.interp holds the last value).
    pad = _WIND_PAD
    n_w = sample_times(T, wcfg.anemometer_rate).size
    n_w_ext = int(np.ceil((T + pad) * wcfg.anemometer_rate))
    t_w_ext = np.arange(n_w_ext) / wcfg.anemometer_rate
    mw = mean_wind(spec.script, t_w_ext, wcfg, rng_mean, s.n_sections)
    # One coherent field for the anemometers (single points) and, with felt_wind = "tributary",
    # the points of each section's tributary length; the anemometer records carry the former
    # plus the sensor errors, the deck (buffeting and the felt mean wind U_k of the aeroelastic
    # force and of the truth) the latter's average per section.
    field = wind_field(mw, s, wcfg, rng_turb)
    # Each anemometer records its own point; the event's wind at a section is taken from them by the
    # layout's rule (the identity with one anemometer per section).
    layout = anemometer_layout(s, wcfg)
    u, v, w = section_records(*measure_wind(at_anemometers(mw, layout), field.anemometer, wcfg, rng_turb), layout)
    turb = field.deck
    mw = felt_mean_wind(mw, turb, wcfg)
    f_shed = config.aero.strouhal * mw.U / s.depth
    shedding_phase = 2 * np.pi * cumulative_trapezoid(f_shed, mw.t, axis=0, initial=0.0) + rng_shed.uniform(0, 2 * np.pi, s.n_sections)

    # Full simulation on the accelerometer's own (possibly offset and drifting) clock.
    # The integration starts at (or just before) true time 0, so the bridge moves
    # the same whatever the logger's clock; the samples are every `sub`-th step.
    sub = max(1, int(round(accel_period / config.integration_step)))
    h = accel_period * drift / sub
    lead = int(np.ceil(max(t_first, 0.0) / h - 1e-9))
    n_steps = lead + (n_acc - 1) * sub
    t_grid = t_first - lead * h + h * np.arange(n_steps + 1)
    params_mid = _modal_params(t_grid[:-1] + h / 2, mw, turb, shedding_phase, config)
    if changes.any:
        params_mid = _changed_modal_params(params_mid, t_grid[:-1] + h / 2, spec, changes, s)
    x = simulate_modal((config.initial_amplitude, 0.0), params_mid, h, s.omega, s.damping_ratio)[lead::sub]
    t_acc_true = t_grid[lead::sub]
    params_acc = _modal_params(t_acc_true, mw, turb, shedding_phase, config)
    if changes.any:
        params_acc = _changed_modal_params(params_acc, t_acc_true, spec, changes, s)
    qdd = modal_acceleration(x, params_acc, s.omega, s.damping_ratio)
    phi = np.array(s.mode_shape)
    acc_true = qdd[:, None] * phi[None, :]
    acc = accelerometer(acc_true, sens, rng_sens)

    # Averaged truth on its own grid, integrated with 5 RK4 substeps per truth step.
    truth_time = np.arange(int(np.floor(T / config.truth_step + 1e-9)) + 1) * config.truth_step
    n_sub = 5
    ht = config.truth_step / n_sub
    t_mid = ht * (np.arange((truth_time.size - 1) * n_sub) + 0.5)
    U_mid = _interp_wind(mw, t_mid)
    # the truth sees the wind speed and yaw the full simulation sees
    yaw_mid = _interp_yaw(mw, t_mid, config)
    if changes.any:
        coefs = _changed_amplitude_coefficients(U_mid, t_mid, spec, changes, s, config, yaw_mid)
    else:
        coefs = amplitude_coefficients(U_mid, s, config.aero, yaw_mid)
    Q = simulate_amplitude(config.initial_amplitude, coefs, ht)[::n_sub]
    if not np.all(Q > 0):
        bad = float(np.min(U_mid[np.argmax(coefs[:, 0] < 0)])) if np.any(coefs[:, 0] < 0) else float("nan")
        raise InputError(
            f"event {spec.event_id}: the averaged amplitude reached zero or below at t = "
            f"{truth_time[np.argmax(Q <= 0)]:.0f} s; the locked lift C_L(U) must stay >= 0 over the wind "
            f"range (it is negative near U = {bad:.2f} m/s)")
    U_truth = _interp_wind(mw, truth_time)
    yaw_truth = _interp_yaw(mw, truth_time, config)
    if changes.any:
        r_modal = (_changed_amplitude_coefficients(U_truth, truth_time, spec, changes, s, config, yaw_truth)
                   * Q[:, None] ** np.arange(4))
    else:
        r_modal = order_contributions(Q, U_truth, s, config.aero, yaw_truth)  # (n_t, 4)
    r = phi[None, :, None] * r_modal[:, None, :]
    A_truth = Q[:, None] * phi[None, :]
    regime = classify_regime(r[None], A_truth[None], tau=config.tau, axis=0)

    wind_time = t_w_ext[:n_w]
    u, v, w = u[:n_w], v[:n_w], w[:n_w]
    info = {"wind_dropouts": [], "accel_dropouts": [], "wind_spikes": 0, "accel_spikes": 0}
    if defects.any:
        wind = np.stack([u, v, w])
        wind_nan, info["wind_dropouts"] = add_dropouts(np.moveaxis(wind, 0, 1), wcfg.anemometer_rate, defects, rng_def)
        u, v, w = (np.ascontiguousarray(c) for c in np.moveaxis(wind_nan, 1, 0))
        acc, info["accel_dropouts"] = add_dropouts(acc, sens.rate, defects, rng_def)
        acc, info["accel_spikes"] = add_spikes(acc, sens.rate, defects, rng_def)
        spiked = [add_spikes(c, wcfg.anemometer_rate, defects, rng_def) for c in (u, v, w)]
        (u, n1), (v, n2), (w, n3) = spiked
        info["wind_spikes"] = n1 + n2 + n3

    recorded = {}
    if changes.any:
        n_t = truth_time.size
        recorded = {
            "damping_ratio": s.damping_ratio * _drift(truth_time, spec, changes),
            "mass_factor": np.full(n_t, changes.mass_factor(spec.number)),
            "aero_factor": np.repeat(changes.aero_factors(spec.number)[None, :], n_t, axis=0),
        }
        coef = _changed_exact_coefficients(s, changes, spec, config)
    else:
        coef = exact_coefficients(s, config.aero)
    return SimulatedEvent(
        wind_time=wind_time, u=u, v=v, w=w,
        accel_time=np.arange(n_acc) * accel_period, acc=acc, acc_true=acc_true, q=x[:, 0], qd=x[:, 1],
        truth_time=truth_time, U=U_truth, Q=Q, r=r, regime=regime,
        coef=coef, defects=info, yaw=yaw_truth, **recorded,
    )


def _script_dict(spec: EventSpec, with_place: bool) -> dict:
    """The spec as plain data; its place in the campaign only when slow changes use it."""
    data = json.loads(json.dumps(asdict(spec)))
    if data["script"].get("yaws") is None:  # files without a scripted yaw history save as before it existed
        data["script"].pop("yaws", None)
    if not with_place:
        del data["number"], data["campaign_time"]
    return data


def _wind_distance_attrs(config: GeneratorConfig) -> dict:
    """``wind_distance_m_<section>`` (m) of the event files, as field import records them: each section's
    distance to its nearest anemometer when ``config.wind.anemometer_span`` places them; empty otherwise."""
    layout = anemometer_layout(config.structure, config.wind)
    if layout.per_section:
        return {}
    return {f"wind_distance_m_{sec}": float(d) for sec, d in zip(config.structure.sections, layout.distance)}


def generate_event(spec: EventSpec, config: GeneratorConfig, seed: np.random.SeedSequence | int,
                   *, campaign_seed: int | None = None) -> xr.DataTree:
    """Simulate one event and assemble it in the event file format (docs/formats.md).

    The generator configuration, the event's script and its seed are stored as
    JSON in the ``/truth`` attribute ``config_json`` so that the file says how
    it was made. With a yaw factor, ``/truth/yaw`` holds the yaw the truth sees. With slow changes,
    ``/truth`` also records the damping ratio,
    the mass factor and the aero factors on the truth grid. ``/truth/curves``
    holds the exact coefficient curves on :data:`TRUTH_CURVE_WIND`
    (:func:`event_truth_curves`; left out with a damping drift).
    """
    ss = seed if isinstance(seed, np.random.SeedSequence) else np.random.SeedSequence(seed)
    ev = simulate_event(spec, config, ss)
    meta = {
        "generator": config_to_dict(config),
        "event": _script_dict(spec, config.changes.any),
        "seed": {"entropy": str(ss.entropy), "spawn_key": list(ss.spawn_key), "campaign_seed": campaign_seed},
        "defects": ev.defects,
    }
    truth = {
        "time": ev.truth_time, "U": ev.U, "A": ev.Q[:, None] * np.array(config.structure.mode_shape)[None, :],
        "r": ev.r, "regime": ev.regime, "config": json.dumps(meta, sort_keys=True), "tau": config.tau,
    }
    if ev.yaw is not None:  # unsigned: the aerodynamics depend on the yaw's magnitude only
        truth["yaw"] = ev.yaw
    if ev.damping_ratio is not None:
        truth.update(damping_ratio=ev.damping_ratio, mass_factor=ev.mass_factor, aero_factor=ev.aero_factor)
    if ev.coef is not None:
        truth["coef"] = ev.coef
        truth["feature"] = feature_names(config.structure.n_sections)
    curves = event_truth_curves(config, spec.number)
    if curves is not None:
        truth["curves"] = curves.values
        truth["wind"] = curves["wind"].values
    return build_event(
        event_id=spec.event_id, start_time=spec.start_time, source="synthetic",
        span_azimuth_deg=config.wind.span_azimuth_deg,
        wind_time=ev.wind_time, u=ev.u, v=ev.v, w=ev.w,
        accel_time=ev.accel_time, acc=ev.acc, truth=truth,
        attrs={"scenario": spec.kind, "generator": "vivbench.synth", **_wind_distance_attrs(config)},
        sections=config.structure.sections,
    )
