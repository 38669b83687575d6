"""Hypothesis strategies for users' property tests (docs/methods.md).

As in ``hypothesis.extra.numpy`` (and unlike ``xarray.testing.strategies``,
which accepts strategies only): every argument is keyword-only and is either a
strategy or a plain value (a plain value is used as it is). The strategies build on the generator's own
configuration classes and simulation (:mod:`vivbench.synth`), so what they draw
is what ``vivbench synth`` would write: physically sensible bridges, lock-in
curves and wind scripts, and events with their exact averaged truth.

========================  ===================================================
:func:`bridges`           :class:`~vivbench.synth.StructureConfig`: one
                          vertical mode seen at 1-4 sections
:func:`aero_curves`       :class:`~vivbench.synth.AeroConfig` drawn by
                          :func:`vivbench.synth.draw_aero`
:func:`wind_scripts`      :class:`~vivbench.synth.WindScript` of a scenario
:func:`generators`        :class:`~vivbench.synth.GeneratorConfig`
:func:`events`            an event in memory: an :class:`xarray.DataTree` in
                          the layout of docs/formats.md with its ``/truth``
:func:`campaign_configs`  :class:`~vivbench.synth.CampaignConfig`
:func:`campaigns`         a tuple of events of one bridge, in memory
:func:`corruptions`       a :class:`Corruption` (dropouts, spikes, clock
                          offset or drift, extra noise) to apply to an event
========================  ===================================================

Events are short by default (4-6 min, a fraction of a second to simulate), so
that a property test runs a handful of examples in seconds. Shrinking works on
the drawn parameters; within an example the random streams (turbulence,
sensor noise, positions of dropouts) come from one drawn seed, so a failing
example is reproduced exactly by hypothesis's database or its printed seed.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np
import xarray as xr
from hypothesis import strategies as st
from hypothesis.strategies import SearchStrategy

from vivbench.core.errors import InputError
from vivbench.io.event import NOMINAL_RATES, validate_event
from vivbench.synth import (
    SCENARIOS,
    AeroConfig,
    CampaignConfig,
    EventSpec,
    GeneratorConfig,
    SensorConfig,
    StructureConfig,
    WindConfig,
    campaign_specs,
    draw_aero,
    draw_script,
    generate_event,
)
from vivbench.synth.campaign import script_lock_in

__all__ = ["bridges", "aero_curves", "wind_scripts", "generators", "events", "campaign_configs", "campaigns",
           "corruptions", "Corruption", "CORRUPTION_KINDS", "SCENARIOS"]

#: Kinds of :class:`Corruption` (the sensor defects of docs/concepts.md (the bridge and the wind), plus extra noise).
CORRUPTION_KINDS = ("dropouts", "spikes", "clock_offset", "clock_drift", "noise")
_SEEDS = st.integers(0, 2**32 - 1)


def _draw(draw, value):
    """A strategy is drawn from; a plain value is used as it is."""
    return draw(value) if isinstance(value, SearchStrategy) else value


@st.composite
def bridges(draw, *, n_sections=st.integers(1, 4), frequency=st.floats(0.2, 0.6), damping_ratio=st.floats(0.002, 0.006),
            depth=st.floats(3.0, 4.5), mass=st.floats(2.0e4, 3.5e4), span_length=st.floats(800.0, 2000.0),
            mode_shape=None) -> StructureConfig:
    """Long-span bridges: one vertical bending mode seen at ``n_sections`` deck sections.

    Parameters
    ----------
    n_sections : int or strategy of int
        Instrumented sections S1..Sn at k / (n + 1) of the span.
    frequency : float or strategy, Hz
    damping_ratio : float or strategy
        Structural damping ratio zeta.
    depth : float or strategy, m
        Deck depth D.
    mass : float or strategy, kg/m
    span_length : float or strategy, m
    mode_shape : sequence of float, strategy, or None
        phi_k > 0 at the sections (its length then sets ``n_sections``). None:
        the first half-sine sin(pi x / L) at the sections' positions, the
        default bridge's shape (0.707, 1, 0.707 for three sections).

    Returns
    -------
    strategy of :class:`vivbench.synth.StructureConfig`
        Tributary lengths are the span shared equally.
    """
    shape = _draw(draw, mode_shape)
    if shape is None:
        n = int(_draw(draw, n_sections))
        shape = tuple(float(np.round(np.sin(np.pi * (k + 1) / (n + 1)), 3)) for k in range(n))
    shape = tuple(float(x) for x in shape)
    span = float(_draw(draw, span_length))
    return StructureConfig(frequency=float(_draw(draw, frequency)), damping_ratio=float(_draw(draw, damping_ratio)),
                           mode_shape=shape, span_length=span, tributary_lengths=(span / len(shape),) * len(shape),
                           depth=float(_draw(draw, depth)), mass=float(_draw(draw, mass)))


@st.composite
def aero_curves(draw, *, kind=st.sampled_from(("realistic", "in_library")), yaw=st.booleans(),
                seed=_SEEDS) -> AeroConfig:
    """Aerodynamic functions Y1, e1, e2, Y2, C_L of a box girder (docs/concepts.md (aeroelastic force), 2.8).

    Parameters
    ----------
    kind : {"realistic", "in_library"} or strategy
        ``realistic``: non-polynomial functions of the reduced velocity (the
        truth lies outside the identification's library); ``in_library``:
        polynomials in U (an exact coefficient matrix exists).
    yaw : bool or strategy
        Whether the realistic functions also depend on the wind's angle to the span.
    seed : int or strategy
        Seed of :func:`vivbench.synth.draw_aero`, which draws the shapes and
        parameters within ranges typical of streamlined box girders.

    Returns
    -------
    strategy of :class:`vivbench.synth.AeroConfig`
    """
    k = _draw(draw, kind)
    return draw_aero(np.random.default_rng(int(_draw(draw, seed))), kind=k, yaw=bool(_draw(draw, yaw)))


@st.composite
def wind_scripts(draw, *, kind=st.sampled_from(SCENARIOS), duration=st.floats(240.0, 360.0), lock_in=None,
                 seed=_SEEDS):
    """Scripted mean wind of one event (docs/concepts.md (the bridge and the wind)), as the campaign generator draws it.

    Parameters
    ----------
    kind : one of :data:`vivbench.synth.SCENARIOS` or strategy
        ``pass_high``, ``pass_low`` (into lock-in, a plateau, out), ``brief``
        (a short passage) or ``outside`` (never in lock-in).
    duration : float or strategy, s (at least 120)
    lock_in : (low, high) m/s, strategy, or None
        Lock-in range the script follows (:func:`vivbench.synth.draw_script`);
        None: the default bridge's, 5.5-10.5 m/s.
    seed : int or strategy

    Returns
    -------
    strategy of :class:`vivbench.synth.WindScript`
    """
    T = float(_draw(draw, duration))
    if T < 120.0:
        raise InputError(f"duration must be at least 120 s; got {T}")
    return draw_script(_draw(draw, kind), T, np.random.default_rng(int(_draw(draw, seed))),
                       lock_in=_draw(draw, lock_in))


@st.composite
def generators(draw, *, bridge=bridges(), aero=aero_curves(), felt_wind=None, noise_density=st.floats(10.0, 60.0),
               turbulence_intensity=None, initial_amplitude=st.floats(0.002, 0.05)) -> GeneratorConfig:
    """Generator configurations: a bridge, its aerodynamics, its wind and its sensors.

    Parameters
    ----------
    bridge : StructureConfig or strategy (default :func:`bridges`)
    aero : AeroConfig or strategy (default :func:`aero_curves`)
    felt_wind : {"anemometer", "tributary"}, strategy, or None
        Which wind the deck feels (docs/concepts.md (no inverse crime)). None: the mode of ``aero``
        (``anemometer`` for polynomial aerodynamics, the ``in_library`` mode;
        ``tributary`` otherwise).
    noise_density : float or strategy, micro-g per sqrt(Hz)
        Accelerometer noise floor.
    turbulence_intensity : float, strategy, or None
        Longitudinal turbulence intensity (None: the generator's default).
    initial_amplitude : float or strategy, m
        Modal amplitude at the start of each event. Above the generator's
        default (2 mm), events may start while the deck already vibrates and
        reach the nonlinear regimes sooner. Short events seldom grow to a
        strong plateau: of 30 events drawn with the defaults (4-6 min), 17 had
        regime 3 and 1 had regime 4 somewhere; of 10 of 25 min, 7 and 4
        (median 0.3 s and 1.3 s to build one).

    Returns
    -------
    strategy of :class:`vivbench.synth.GeneratorConfig`
        No sensor defects (apply :func:`corruptions` for those), no slow changes.
    """
    a = _draw(draw, aero)
    fw = _draw(draw, felt_wind)
    if fw is None:
        fw = "anemometer" if a.polynomials() is not None else "tributary"
    wind = WindConfig(felt_wind=fw)
    ti = _draw(draw, turbulence_intensity)
    if ti is not None:
        wind = dataclasses.replace(wind, turbulence=dataclasses.replace(wind.turbulence, intensity=float(ti)))
    return GeneratorConfig(structure=_draw(draw, bridge), aero=a, wind=wind,
                           sensors=SensorConfig(noise_density=float(_draw(draw, noise_density))),
                           initial_amplitude=float(_draw(draw, initial_amplitude)))


@st.composite
def events(draw, *, generator=generators(), kind=st.sampled_from(SCENARIOS), duration=st.floats(240.0, 360.0),
           script=None, seed=_SEEDS, event_id="E001", start_time="2026-01-01T00:00:00Z") -> xr.DataTree:
    """Events in memory: the full simulation's sensor records and the exact averaged truth.

    Parameters
    ----------
    generator : GeneratorConfig or strategy (default :func:`generators`)
    kind, duration : see :func:`wind_scripts`; used when ``script`` is None
    script : WindScript, strategy, or None
        The mean wind. None: a script of ``kind`` drawn for the generator's
        own lock-in range (so that lock-in passes meet the bridge's lock-in).
    seed : int or strategy
        Seed of the event's random streams (wind, turbulence, sensors).
    event_id, start_time : str or strategy
        Root attributes of the event.

    Returns
    -------
    strategy of xarray.DataTree
        The layout of docs/formats.md (``/wind`` at 32 Hz, ``/accel`` at 50 Hz,
        ``/truth`` with time, U, A, r, regime, the generator configuration and,
        when the aerodynamics are in the library, the exact coefficients);
        what :func:`vivbench.synth.generate_event` builds and
        :func:`vivbench.io.write_event` would write.
    """
    config = _draw(draw, generator)
    s = int(_draw(draw, seed))
    sc = _draw(draw, script)
    k = "scripted"
    if sc is None:
        k = _draw(draw, kind)
        sc = draw_script(k, float(_draw(draw, duration)), np.random.default_rng(s), lock_in=script_lock_in(config))
    spec = EventSpec(event_id=_draw(draw, event_id), start_time=_draw(draw, start_time), kind=k, script=sc)
    return generate_event(spec, config, np.random.SeedSequence(s))


@st.composite
def campaign_configs(draw, *, generator=generators(), n_events=st.integers(1, 3), duration=st.floats(240.0, 360.0),
                     seed=st.integers(0, 2**31 - 1)) -> CampaignConfig:
    """Campaign configurations (docs/concepts.md (the bridge and the wind)): events of one bridge, with a seed.

    Parameters
    ----------
    generator : GeneratorConfig or strategy
    n_events : int or strategy
    duration : float, (min, max) tuple, or strategy of either, s (at least 120)
        Event durations; one number makes every event that long.
    seed : int or strategy
        The campaign seed (event seeds are spawned from it).

    Returns
    -------
    strategy of :class:`vivbench.synth.CampaignConfig`
        Write it with :func:`vivbench.synth.generate_campaign` or build it in
        memory with :func:`campaigns`.
    """
    d = _draw(draw, duration)
    d = (float(d), float(d)) if np.ndim(d) == 0 else tuple(float(x) for x in d)
    return CampaignConfig(n_events=int(_draw(draw, n_events)), seed=int(_draw(draw, seed)), duration=d,
                          generator=_draw(draw, generator))


@st.composite
def campaigns(draw, *, config=None, generator=generators(), n_events=st.integers(1, 3),
              duration=st.floats(240.0, 360.0), seed=st.integers(0, 2**31 - 1)) -> tuple[xr.DataTree, ...]:
    """Campaigns in memory: the events of one bridge, E001, E002, ... (the scenario cycle of
    :func:`vivbench.synth.campaign_specs`: the first is a lock-in pass).

    Parameters
    ----------
    config : CampaignConfig, strategy, or None
        The campaign; None: drawn by :func:`campaign_configs` from the other arguments.
    generator, n_events, duration, seed : see :func:`campaign_configs`

    Returns
    -------
    strategy of tuple of xarray.DataTree
        The same events, byte for byte, as ``vivbench synth`` writes for this
        configuration.
    """
    c = _draw(draw, config)
    if c is None:
        c = draw(campaign_configs(generator=generator, n_events=n_events, duration=duration, seed=seed))
    return tuple(generate_event(spec, c.generator, ss, campaign_seed=c.seed) for spec, ss in campaign_specs(c))


@dataclass(frozen=True, kw_only=True)
class Corruption:
    """A sensor defect (docs/concepts.md (the bridge and the wind)) to apply to an event: ``corruption(event) -> event``.

    The truth is left as it is (the bridge did what it did; only the records
    are wrong), and the corrupted event still follows the format of docs/formats.md.

    Attributes
    ----------
    kind : one of :data:`CORRUPTION_KINDS`
        ``dropouts``: ``count`` NaN blocks of ``size`` s in the records of
        ``group``; ``spikes``: ``count`` single-sample spikes of ``size``
        times the channel's standard deviation in ``group``; ``clock_offset``: the
        accelerometer's times shifted by ``size`` s (samples before the start
        are dropped); ``clock_drift``: the accelerometer's clock running fast
        or slow by ``size`` parts per million; ``noise``: white noise of
        ``size`` times each channel's standard deviation added to ``group``.
    group : {"wind", "accel", "both"}
        The logger(s) affected (``clock_*`` always affect ``accel``).
    count : int
        Number of dropouts or spikes.
    size : float
        The defect's size, in the unit of its kind (above).
    seed : int
        Seed of the positions and signs.
    """

    kind: str
    group: str = "both"
    count: int = 1
    size: float = 0.0
    seed: int = 0

    def __post_init__(self) -> None:
        if self.kind not in CORRUPTION_KINDS:
            raise InputError(f"Corruption kind must be one of {list(CORRUPTION_KINDS)}; got {self.kind!r}")
        if self.group not in ("wind", "accel", "both"):
            raise InputError(f"Corruption group must be 'wind', 'accel' or 'both'; got {self.group!r}")
        if self.count < 0:
            raise InputError(f"Corruption count must be >= 0; got {self.count}")
        if self.kind == "clock_drift" and not abs(self.size) < 5e4:
            raise InputError(f"a clock drift must stay within +-50000 ppm (the rate check allows 10 %); got {self.size}")
        if self.kind in ("dropouts", "spikes", "noise") and self.size < 0:
            raise InputError(f"Corruption size must be >= 0 for {self.kind}; got {self.size}")

    def __call__(self, event: xr.DataTree) -> xr.DataTree:
        return self.apply(event)

    def apply(self, event: xr.DataTree) -> xr.DataTree:
        """A corrupted copy of ``event`` (the input is not changed).

        Parameters
        ----------
        event : xarray.DataTree
            A valid event (docs/formats.md).

        Returns
        -------
        xarray.DataTree
            The copy, checked against the format.
        """
        out = event.copy(deep=True)
        rng = np.random.default_rng(self.seed)
        groups = ("wind", "accel") if self.group == "both" else (self.group,)
        if self.kind in ("clock_offset", "clock_drift"):
            ds = out["accel"].to_dataset()
            t = ds["time"].values
            new = t + self.size if self.kind == "clock_offset" else t * (1.0 + self.size * 1e-6)
            keep = new >= 0.0
            ds = ds.isel(time=np.flatnonzero(keep)).assign_coords(time=("time", new[keep], ds["time"].attrs))
            out["accel"] = xr.DataTree(ds)
        else:
            for g in groups:
                ds = out[g].to_dataset()
                names = ("u", "v", "w") if g == "wind" else ("acc",)
                rate = NOMINAL_RATES[g]
                n = ds.sizes["time"]
                for name in names:
                    x = ds[name].values.astype(float)
                    # Sizes relative to the fluctuation (a wind's mean is not its noise scale).
                    std = np.nanstd(x, axis=0)
                    if self.kind == "dropouts":
                        # A logger drops out as a whole: every channel of the group, the same blocks.
                        if name == names[0]:
                            length = max(1, int(round(self.size * rate)))
                            starts = rng.integers(0, max(n - length, 1), size=self.count)
                        for i0 in starts:
                            x[i0:i0 + length] = np.nan
                    elif self.kind == "spikes":
                        rows = rng.integers(0, n, size=self.count)
                        cols = rng.integers(0, x.shape[1], size=self.count)
                        x[rows, cols] += rng.choice([-1.0, 1.0], size=self.count) * self.size * std[cols]
                    else:
                        x = x + rng.normal(size=x.shape) * self.size * std[None, :]
                    ds[name] = ds[name].copy(data=x.astype(ds[name].dtype))
                out[g] = xr.DataTree(ds)
        validate_event(out, name=f"event {event.attrs.get('event_id', '?')!r} after {self!r}")
        return out


@st.composite
def corruptions(draw, *, kind=st.sampled_from(CORRUPTION_KINDS), group=st.sampled_from(("wind", "accel", "both")),
                count=st.integers(1, 4), dropout_s=st.floats(1.0, 30.0), spike_size=st.floats(5.0, 30.0),
                clock_offset_s=st.floats(-2.0, 2.0), clock_drift_ppm=st.floats(-500.0, 500.0),
                noise=st.floats(0.01, 0.3), seed=_SEEDS) -> Corruption:
    """Sensor defects to apply to an event: ``corruption(event)`` (see :class:`Corruption`).

    Parameters
    ----------
    kind : one of :data:`CORRUPTION_KINDS` or strategy
    group : {"wind", "accel", "both"} or strategy
    count : int or strategy
        Dropouts or spikes per affected logger.
    dropout_s : float or strategy, s
        Length of each dropout.
    spike_size : float or strategy
        Spike height in multiples of the channel's standard deviation.
    clock_offset_s : float or strategy, s
        Offset of the accelerometer clock from the anemometers'.
    clock_drift_ppm : float or strategy, parts per million
    noise : float or strategy
        Extra white noise in multiples of each channel's standard deviation.
    seed : int or strategy
        Positions and signs of dropouts and spikes, noise samples.

    Returns
    -------
    strategy of :class:`Corruption`
    """
    k = _draw(draw, kind)
    size = {"dropouts": dropout_s, "spikes": spike_size, "clock_offset": clock_offset_s,
            "clock_drift": clock_drift_ppm, "noise": noise}[k]
    g = "accel" if k in ("clock_offset", "clock_drift") else _draw(draw, group)
    return Corruption(kind=k, group=g, count=int(_draw(draw, count)), size=float(_draw(draw, size)),
                      seed=int(_draw(draw, seed)))
