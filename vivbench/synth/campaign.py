"""Campaigns: many events with one seed, written as event files plus a catalogue.

Event seeds are ``SeedSequence(seed).spawn(n)`` (docs/concepts.md (the bridge and the wind)), so the same seed
gives the same files whatever the number of worker processes.
"""

from __future__ import annotations

import csv
import io as _io
from collections.abc import Callable
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass
from datetime import datetime, timedelta, timezone
from pathlib import Path

import numpy as np

from vivbench.io.netcdf import atomic_path
from vivbench.io.event import write_event
from vivbench.synth.config import DEFAULT_LOCK_IN, GeneratorConfig
from vivbench.synth.event import EventSpec, generate_event
from vivbench.synth.wind import WindScript
from vivbench.core.errors import InputError, error_line

__all__ = ["SCENARIOS", "LOCK_IN_TOLERANCE", "CampaignConfig", "draw_script", "script_lock_in", "campaign_specs", "generate_campaign", "CampaignResult"]

# Scenario cycle: the first event is like the paper's event 1 (growth in lock-in,
# a strongly self-excited plateau, decay as the wind leaves), and any four
# consecutive events visit all four regimes.
SCENARIOS = ("pass_high", "pass_low", "brief", "outside")
_CYCLE = ("pass_high", "pass_low", "brief", "outside", "pass_high", "pass_low", "brief", "pass_high")
# Campaign scripts follow a bridge's lock-in only when it differs from the default's by more than
# this at either end (m/s): the default bridge's (and the realistic mode's) specs stay as they were.
LOCK_IN_TOLERANCE = 0.5
# Fractions of the duration range each scenario uses (lock-in passes need time to grow).
_DURATION_SHARE = {"pass_high": (0.4, 1.0), "pass_low": (0.4, 1.0), "brief": (0.0, 0.5), "outside": (0.0, 0.6)}


@dataclass(frozen=True, kw_only=True)
class CampaignConfig:
    """A campaign: how many events, how long, which seed, and the generator.

    Attributes
    ----------
    n_events : number of events (default 31, as in the paper)
    seed : campaign seed
    duration : (min, max) event duration, s
    start : ISO 8601 UTC date of the first event
    generator : GeneratorConfig
    """

    n_events: int = 31
    seed: int = 0
    duration: tuple[float, float] = (1200.0, 3600.0)
    start: str = "2026-01-01T00:00:00Z"
    generator: GeneratorConfig = GeneratorConfig()

    def __post_init__(self) -> None:
        object.__setattr__(self, "duration", tuple(float(x) for x in self.duration))
        if not 1 <= self.n_events <= 100000:
            raise InputError(f"n_events must be in 1..100000; got {self.n_events}")
        if self.seed < 0:
            raise InputError(f"seed must be a non-negative integer; got {self.seed}")
        lo, hi = self.duration
        if not 120.0 <= lo <= hi <= 6 * 3600.0:
            raise InputError(f"duration must be (min, max) seconds with 120 <= min <= max <= 21600; got {self.duration}")
        try:
            datetime.fromisoformat(self.start.replace("Z", "+00:00"))
        except ValueError:
            raise InputError(f"start must be an ISO 8601 date, e.g. 2026-01-01T00:00:00Z; got {self.start!r}") from None


def draw_script(kind: str, duration: float, rng: np.random.Generator, *,
                lock_in: tuple[float, float] | None = None) -> WindScript:
    """Draw a mean-wind script of a scenario.

    Speeds are designed for the default bridge's lock-in range, 5.5-10.5 m/s:

    - ``pass_high``: from outside lock-in to its upper centre (8.4-9.4 m/s: a
      strongly self-excited plateau, regime 4) and out again;
    - ``pass_low``: the same to the lower part of lock-in (6.7-7.1 m/s, regime 3);
    - ``brief``: a short passage through lock-in: growth, no plateau, decay;
    - ``outside``: wind that stays below or above lock-in (regime 1).

    Parameters
    ----------
    kind : one of :data:`SCENARIOS`
    duration : s
    rng : the script's random stream
    lock_in : (low, high) lock-in range of another bridge, m/s; every speed is then
        mapped affinely from 5.5-10.5 m/s onto it (the same draws, so the scenarios keep
        their places relative to lock-in). None: the default bridge's speeds.
    """
    T = float(duration)
    low = lambda: rng.uniform(3.8, 5.0)  # noqa: E731
    high = lambda: rng.uniform(11.0, 12.2)  # noqa: E731
    outside = lambda: low() if rng.random() < 0.7 else high()  # noqa: E731
    side = int(rng.choice([-1, 1]))
    yaw = float(rng.uniform(-12.0, 12.0))
    if kind in ("pass_high", "pass_low"):
        plateau = rng.uniform(8.4, 9.4) if kind == "pass_high" else rng.uniform(6.7, 7.1)
        t1 = T * rng.uniform(0.04, 0.12)
        t2 = t1 + T * rng.uniform(0.06, 0.10)
        t3 = T * rng.uniform(0.68, 0.80)
        t4 = t3 + T * rng.uniform(0.06, 0.10)
        start, end = outside(), outside()
        drift = rng.uniform(-0.2, 0.2)
        times = (0.0, t1, t2, t3, t4, T)
        speeds = (start, start, plateau, plateau + drift, end, end)
    elif kind == "brief":
        peak = rng.uniform(7.6, 9.0)
        t1 = T * rng.uniform(0.1, 0.2)
        t2 = T * rng.uniform(0.35, 0.45)
        t3 = T * rng.uniform(0.6, 0.7)
        start, end = outside(), outside()
        times = (0.0, t1, t2, t3, T)
        speeds = (start, start, peak, end, end)
    elif kind == "outside":
        base = outside()
        n = 4
        times = tuple(np.linspace(0.0, T, n))
        spread = 0.6
        speeds = tuple(float(np.clip(base + rng.uniform(-spread, spread), 3.0, 13.0)) for _ in range(n))
        if base < 8:
            speeds = tuple(min(s, 5.2) for s in speeds)
        else:
            speeds = tuple(max(s, 10.8) for s in speeds)
    else:
        raise InputError(f"unknown scenario {kind!r}; allowed: {', '.join(SCENARIOS)}")
    if lock_in is not None:
        (a, b), (lo, hi) = DEFAULT_LOCK_IN, lock_in
        if not 0 < lo < hi:
            raise InputError(f"lock_in must be (low, high) m/s with 0 < low < high; got {lock_in}")
        scale = (hi - lo) / (b - a)
        speeds = tuple(float(max(lo + (s - a) * scale, 0.5)) for s in speeds)
    return WindScript(times=times, speeds=speeds, side=side, yaw_deg=yaw)


def script_lock_in(generator: GeneratorConfig) -> tuple[float, float] | None:
    """The lock-in range a campaign's scripts follow: None (the default speeds) unless the
    bridge's own (:attr:`GeneratorConfig.lock_in`) differs from 5.5-10.5 m/s by more than
    :data:`LOCK_IN_TOLERANCE` at either end. A bridge without self-excitation keeps the default speeds."""
    lock = generator.lock_in
    if lock is None or max(abs(lock[0] - DEFAULT_LOCK_IN[0]), abs(lock[1] - DEFAULT_LOCK_IN[1])) <= LOCK_IN_TOLERANCE:
        return None
    return lock


def campaign_specs(campaign: CampaignConfig) -> list[tuple[EventSpec, np.random.SeedSequence]]:
    """Event specifications and seeds of a campaign (cheap; nothing simulated)."""
    root = np.random.SeedSequence(campaign.seed)
    children = root.spawn(campaign.n_events)
    start = datetime.fromisoformat(campaign.start.replace("Z", "+00:00")).astimezone(timezone.utc)
    width = max(3, len(str(campaign.n_events)))
    specs = []
    lo, hi = campaign.duration
    lock_in = script_lock_in(campaign.generator)
    for i, child in enumerate(children):
        # The script draws from its own stream, spawned from the event's seed.
        rng = np.random.default_rng(np.random.SeedSequence(child.entropy, spawn_key=child.spawn_key + (1000,)))
        kind = _CYCLE[i % len(_CYCLE)]
        a, b = _DURATION_SHARE[kind]
        duration = round(rng.uniform(lo + a * (hi - lo), lo + b * (hi - lo)))
        begin = start + timedelta(days=i, hours=int(rng.integers(0, 20)), minutes=int(rng.integers(0, 60)))
        spec = EventSpec(
            event_id=f"E{i + 1:0{width}d}",
            start_time=begin.strftime("%Y-%m-%dT%H:%M:%SZ"),
            kind=kind,
            script=draw_script(kind, duration, rng, lock_in=lock_in),
            number=i + 1,
            campaign_time=(begin - start).total_seconds(),
        )
        specs.append((spec, child))
    return specs


@dataclass(frozen=True)
class CampaignResult:
    """Paths written and the failures (event id -> one-line message)."""

    files: list[Path]
    catalogue: Path
    failures: dict[str, str]


def _catalogue_row(spec: EventSpec, path: Path, tree) -> dict:
    truth = tree["truth"].ds
    regime = truth["regime"].values
    counts = [int(np.sum(regime == k)) for k in (1, 2, 3, 4)]
    total = max(regime.size, 1)
    return {
        "event_id": spec.event_id,
        "file": path.name,
        "start_time": spec.start_time,
        "scenario": spec.kind,
        "duration_s": f"{spec.script.duration:.0f}",
        "U_min": f"{float(truth['U'].min()):.2f}",
        "U_max": f"{float(truth['U'].max()):.2f}",
        "A_max_m": f"{float(truth['A'].max()):.4f}",
        **{f"share_regime{k}": f"{c / total:.3f}" for k, c in zip((1, 2, 3, 4), counts)},
        **_changes_columns(truth),
    }


def _changes_columns(truth) -> dict:
    """Catalogue columns of the slow changes (docs/concepts.md (no inverse crime)); none when the truth does not record them."""
    if "damping_ratio" not in truth.data_vars:
        return {}
    zeta = truth["damping_ratio"].values
    aero = truth["aero_factor"].values
    return {
        "damping_ratio_min": f"{float(zeta.min()):.6f}",
        "damping_ratio_max": f"{float(zeta.max()):.6f}",
        "mass_factor": f"{float(truth['mass_factor'].values.mean()):.4f}",
        **{f"aero_factor_r{i}": f"{float(aero[:, i].mean()):.4f}" for i in range(4)},
    }


def _make_one(spec: EventSpec, seed: np.random.SeedSequence, generator: GeneratorConfig, out_dir: str, campaign_seed: int) -> dict:
    tree = generate_event(spec, generator, seed, campaign_seed=campaign_seed)
    path = write_event(tree, Path(out_dir) / f"{spec.event_id}.nc")
    return _catalogue_row(spec, Path(path), tree)


def generate_campaign(campaign: CampaignConfig, out_dir: str | Path, *, workers: int = 1,
                      progress: Callable[[str], None] | None = None) -> CampaignResult:
    """Generate and write every event of a campaign, and ``catalogue.csv`` beside them.

    Parameters
    ----------
    campaign : CampaignConfig
    out_dir : directory for ``<event_id>.nc`` and ``catalogue.csv`` (created)
    workers : number of worker processes (1: in this process). The files do not
        depend on it.
    progress : optional callback called with each finished event id

    Returns
    -------
    CampaignResult
        An event that fails is reported in ``failures`` and the others still
        finish; the catalogue lists the events that were written.
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    specs = campaign_specs(campaign)
    rows: dict[str, dict] = {}
    failures: dict[str, str] = {}

    def done(spec, fn):
        try:
            rows[spec.event_id] = fn()
        except Exception as exc:  # one bad event must not sink the campaign
            failures[spec.event_id] = error_line(exc)  # "internal error (...)" unless bad input or OSError
        if progress is not None:
            progress(spec.event_id)

    if workers <= 1:
        for spec, seed in specs:
            done(spec, lambda: _make_one(spec, seed, campaign.generator, str(out), campaign.seed))
    else:
        with ProcessPoolExecutor(max_workers=workers) as pool:
            futures = {pool.submit(_make_one, spec, seed, campaign.generator, str(out), campaign.seed): spec
                       for spec, seed in specs}
            for fut in as_completed(futures):
                done(futures[fut], fut.result)

    ordered = [rows[s.event_id] for s, _ in specs if s.event_id in rows]
    buf = _io.StringIO()
    if ordered:
        writer = csv.DictWriter(buf, fieldnames=list(ordered[0]), lineterminator="\n")
        writer.writeheader()
        writer.writerows(ordered)
    catalogue = out / "catalogue.csv"
    with atomic_path(catalogue) as tmp:
        tmp.write_text(buf.getvalue())
    files = [out / r["file"] for r in ordered]
    return CampaignResult(files=files, catalogue=catalogue, failures=failures)
