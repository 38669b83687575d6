"""The scenario suite (docs/methods.md): named, versioned synthetic campaigns on which every method is scored.

A scenario is data, not a code path: a generator configuration in the layout
of ``vivbench synth --config`` (a TOML-like dict read by
:func:`vivbench.synth.config_from_dict`), a number of events, their duration
and a seed, with a version number. The same scenario name and version always
gives the same campaign, byte for byte. Changing anything in a scenario means
bumping its version: :data:`SCENARIO_FINGERPRINTS` pins the fingerprint of every
built-in (name, version) and ``tests/validate/test_scenarios.py`` fails when the content
changes under an unchanged version. The leaderboard caches each scenario's
campaign with its record and regenerates it when the record differs.

The built-in suite (:data:`SCENARIOS`, in this order):

==============  ===========================================================================
in_library      the truth inside the identification's model class (polynomial aerodynamics
                in U, the deck feels the anemometer's wind; docs/concepts.md (no inverse crime)): an *in-class*
                check for library-based methods, not field performance
realistic       the default bridge of ``vivbench synth`` (realistic mode: functions of
                reduced velocity with a yaw factor, tributary-averaged felt wind)
other_bridge    a second realistic bridge (``examples/bridge_b_realistic.toml``: 0.25 Hz,
                4 m deep, four sections, lock-in about 6.6-11.4 m/s)
forced_only     locked shedding without self-excitation (``examples/forced_only.toml``):
                the true regime is 1 everywhere
drift           the default bridge with a daily damping drift (+-30 %) and a retrofit of
                the deck aerodynamics from the fifth event on (``examples/drift.toml``,
                retrofit moved to the middle of the shorter campaign)
high_noise      the default bridge with 10x the accelerometer noise floor (300 micro-g/
                sqrt(Hz)) and 3x the anemometer error (3 % rms)
dropouts        the default bridge with sensor dropouts: NaN blocks of 1-30 s, 6 per hour
                in each stream
==============  ===========================================================================

Every built-in scenario has 8 events of 20 min (one full cycle of the
campaign's wind scripts: every true regime is visited) and seed 2. The
built-in methods were tuned on seed-0 campaigns; the suite reports on another
seed. All scenarios share the seed, so their wind scripts and noise draws are
paired (common random numbers): ``realistic``, ``high_noise`` and
``dropouts`` differ only by their sensors.
"""

from __future__ import annotations

import copy
import hashlib
import json
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from vivbench.core.errors import InputError
from vivbench.core.toml import load_toml

__all__ = ["Scenario", "SCENARIOS", "SCENARIO_FINGERPRINTS", "family_scenarios", "scenario", "select_scenarios",
           "load_scenario_file", "scenarios_from_dict"]

_NAME_CHARS = set("abcdefghijklmnopqrstuvwxyz0123456789_")


def _plain(value: Any) -> Any:
    """A JSON-ready deep copy (tuples as lists) of a generator table."""
    return json.loads(json.dumps(value))


@dataclass(frozen=True, kw_only=True)
class Scenario:
    """One named, versioned campaign of the suite.

    Attributes
    ----------
    name : lower-case letters, digits and ``_``
    version : integer >= 1; bump it whenever anything below changes
    description : one line for the leaderboard's legend
    generator : generator configuration as plain data (the layout of ``vivbench synth --config``;
        ``{"mode": "in_library"}`` or ``{}`` for the realistic default)
    n_events : number of events
    duration : (min, max) event duration, s
    seed : campaign seed
    in_class : True when the truth lies inside the identification's library (an exact coefficient
        matrix exists): scores of library-based methods there are an in-class check, not field
        performance, and the leaderboard marks them so
    """

    name: str
    version: int
    description: str
    generator: Mapping[str, Any] = field(default_factory=dict)
    n_events: int = 8
    duration: tuple[float, float] = (1200.0, 1200.0)
    seed: int = 2
    in_class: bool = False

    def __post_init__(self) -> None:
        if not isinstance(self.name, str) or not self.name or not set(self.name) <= _NAME_CHARS:
            raise InputError(f"scenario name must be lower-case letters, digits and _; got {self.name!r}")
        if isinstance(self.version, bool) or not isinstance(self.version, int) or self.version < 1:
            raise InputError(f"scenario {self.name}: version must be an integer >= 1; got {self.version!r}")
        if not isinstance(self.description, str) or not self.description.strip():
            raise InputError(f"scenario {self.name}: description must be a non-empty string")
        if not isinstance(self.generator, Mapping):
            raise InputError(f"scenario {self.name}: generator must be a table; got {type(self.generator).__name__}")
        if isinstance(self.seed, bool) or not isinstance(self.seed, int) or self.seed < 0:
            raise InputError(f"scenario {self.name}: seed must be an integer >= 0; got {self.seed!r}")
        if not isinstance(self.in_class, bool):
            raise InputError(f"scenario {self.name}: in_class must be true or false; got {self.in_class!r}")
        try:
            duration = tuple(float(x) for x in self.duration)
        except (TypeError, ValueError):
            duration = ()
        if len(duration) != 2 or not all(math.isfinite(x) for x in duration):
            raise InputError(f"scenario {self.name}: duration must be (min, max) seconds; got {self.duration!r}")
        object.__setattr__(self, "duration", duration)
        object.__setattr__(self, "generator", _plain(dict(self.generator)))
        # The campaign's and generator's own checks give the messages for the rest.
        self.campaign_config()

    def generator_config(self):
        """The :class:`vivbench.synth.GeneratorConfig` of this scenario."""
        from vivbench.synth.config import config_from_dict

        try:
            return config_from_dict(copy.deepcopy(dict(self.generator)))
        except (ValueError, TypeError) as exc:
            raise InputError(f"scenario {self.name}: generator: {exc}") from None

    def campaign_config(self):
        """The :class:`vivbench.synth.CampaignConfig` of this scenario."""
        from vivbench.synth.campaign import CampaignConfig

        if isinstance(self.n_events, bool) or not isinstance(self.n_events, int):
            raise InputError(f"scenario {self.name}: n_events must be an integer; got {self.n_events!r}")
        try:
            return CampaignConfig(n_events=self.n_events, seed=self.seed, duration=self.duration,
                                  generator=self.generator_config())
        except InputError as exc:
            raise InputError(f"scenario {self.name}: {exc}") from None

    def to_dict(self) -> dict[str, Any]:
        """Plain-data form; its canonical JSON is what :meth:`fingerprint` hashes."""
        return {"name": self.name, "version": self.version, "description": self.description,
                "generator": _plain(dict(self.generator)), "n_events": self.n_events,
                "duration": list(self.duration), "seed": self.seed, "in_class": self.in_class}

    def fingerprint(self) -> str:
        """SHA-256 (hex) of the campaign this scenario generates: the fully resolved configuration.

        It hashes the resolved :class:`~vivbench.synth.CampaignConfig` (every generator key,
        defaults included), so a change of a generator default also changes it, and the
        description does not enter.
        """
        from vivbench.synth.config import config_to_dict

        camp = self.campaign_config()
        data = {"n_events": camp.n_events, "seed": camp.seed, "duration": list(camp.duration), "start": camp.start,
                "generator": config_to_dict(camp.generator), "in_class": self.in_class}
        return hashlib.sha256(json.dumps(data, sort_keys=True).encode()).hexdigest()

    @property
    def label(self) -> str:
        """``name vN``."""
        return f"{self.name} v{self.version}"


_BRIDGE_B = {
    "mode": "realistic",
    "structure": {"frequency": 0.25, "damping_ratio": 0.004, "depth": 4.0, "mass": 2.2e4, "span_length": 1400.0,
                  "mode_shape": [0.55, 0.92, 0.98, 0.62], "tributary_lengths": [350.0, 350.0, 350.0, 350.0]},
    "aero": {
        "strouhal": 0.111,
        "Y1": {"kind": "gaussian", "peak": 18.0, "center": 9.0, "width": 1.3, "baseline": -4.0},
        "e1": {"kind": "logistic", "start": 32.0, "end": 18.0, "center": 9.0, "width": 1.6},
        "e2": {"kind": "logistic", "start": 260.0, "end": 480.0, "center": 9.0, "width": 1.6},
        "C_L": {"kind": "gaussian", "peak": 0.035, "center": 9.0, "width": 2.2, "baseline": 0.003},
    },
    "wind": {"span_azimuth_deg": 75.0, "points_per_section": 4},
}

_FORCED_ONLY = {
    "mode": "realistic",
    "aero": {
        "Y1": {"kind": "gaussian", "peak": -0.5, "center": 7.0, "width": 1.1, "baseline": -4.0},
        "e1": {"kind": "constant", "value": 0.0},
        "e2": {"kind": "constant", "value": 0.0},
        "C_L": {"kind": "gaussian", "peak": 0.06, "center": 7.0, "width": 2.0, "baseline": 0.004},
    },
}

_DRIFT = {
    "mode": "realistic",
    "changes": {"drift_amplitude": 0.3, "drift_period": 86400.0, "drift_phase_deg": -90.0,
                "retrofit_event": 5, "retrofit_Y1_factor": 0.6, "retrofit_CL_factor": 0.7},
}

#: The built-in suite, by name, in leaderboard order.
SCENARIOS: dict[str, Scenario] = {s.name: s for s in (
    Scenario(name="in_library", version=1, in_class=True, generator={"mode": "in_library"},
             description="truth inside the library (polynomial aerodynamics in U, anemometer wind): in-class check"),
    Scenario(name="realistic", version=1, generator={"mode": "realistic"},
             description="default bridge, realistic mode (reduced-velocity bell with yaw, tributary felt wind)"),
    Scenario(name="other_bridge", version=1, generator=_BRIDGE_B,
             description="second realistic bridge: 0.25 Hz, 4 m deep, four sections, lock-in 6.6-11.4 m/s"),
    Scenario(name="forced_only", version=1, generator=_FORCED_ONLY,
             description="locked shedding without self-excitation: true regime 1 everywhere"),
    Scenario(name="drift", version=1, generator=_DRIFT,
             description="default bridge, daily damping drift +-30 %, aerodynamic retrofit from E005"),
    Scenario(name="high_noise", version=1,
             generator={"mode": "realistic", "sensors": {"noise_density": 300.0}, "wind": {"noise": 0.03}},
             description="default bridge, accelerometer floor 300 micro-g/sqrt(Hz) (10x), anemometer error 3 %"),
    Scenario(name="dropouts", version=1,
             generator={"mode": "realistic",
                        "sensors": {"defects": {"dropouts_per_hour": 6.0, "dropout_duration": [1.0, 30.0]}}},
             description="default bridge, sensor dropouts: 6 NaN blocks of 1-30 s per hour in each stream"),
)}

#: SHA-256 fingerprints (:meth:`Scenario.fingerprint`) of every built-in (name, version). A test
#: checks them: a scenario whose content changes must get a new version (and a new entry here).
SCENARIO_FINGERPRINTS: dict[tuple[str, int], str] = {
    ('in_library', 1): "fb149c8e5ae3115ad822b3065d739087e1cdab11594a4b0ce3fafd2831d226ac",
    ('realistic', 1): "1ce175662186769de69e7d80c1dec57ace1818b8496c17505eb8d3085f97ce1b",
    ('other_bridge', 1): "91389e300687042eb9681cefb8dd2cfe7685684ed3a4edc5d2e4d79fdfb6593b",
    ('forced_only', 1): "e8c8d73933f1691caeccb0abb11ac1dfb8f55771fe149e539b151e12668b23e9",
    ('drift', 1): "6634a84e2c0e3e7c249e7ea4604693079054c59635d740fe76ae7e8a5c1d84e7",
    ('high_noise', 1): "4c6a5e9c21f0223851843a097630d36e20d653c496b78c062eaab5db04448632",
    ('dropouts', 1): "ed48b896d8dcfaacebac546795c36db294e9bf4cf3e007ecb03cd2b34aa98594",
}


def family_scenarios(split: str, draws) -> list[Scenario]:
    """Draws of the generator family (:func:`vivbench.synth.draw_bridge`) as scenarios of the leaderboard.

    Ranking methods on evaluation draws, which no one may tune on, keeps a method's author from tuning
    on the campaigns it is ranked on (the built-in suite is public and fixed).

    Parameters
    ----------
    split : "development" or "evaluation"
    draws : sequence of int, draw numbers

    Returns
    -------
    list of Scenario, named ``<split>_<draw>`` (e.g. ``evaluation_003``), version 1, with the draw's
    bridge, number of events, durations and campaign seed; the description lists what was drawn.
    """
    from vivbench.synth.config import config_to_dict
    from vivbench.synth.family import draw_bridge

    out = []
    for index in draws:
        d = draw_bridge(split, int(index))
        labels = ", ".join(f"{k} {v}" for k, v in sorted(d.labels.items()) if not isinstance(v, (dict, list)))
        out.append(Scenario(name=f"{split}_{int(index):03d}", version=1, generator=config_to_dict(d.config),
                            n_events=int(d.n_events), duration=tuple(float(x) for x in d.duration),
                            seed=int(d.campaign_seed), in_class=False,
                            description=f"family draw {split} {int(index)}: {labels}"))
    return out


def scenario(name: str) -> Scenario:
    """The built-in scenario ``name``; InputError listing the names otherwise."""
    try:
        return SCENARIOS[name]
    except KeyError:
        raise InputError(f"unknown scenario {name!r}; the suite has: {', '.join(SCENARIOS)}") from None


def select_scenarios(names: str | list[str] | None = None,
                     extra: Mapping[str, Scenario] | None = None) -> list[Scenario]:
    """Scenarios by name (comma-separated text or a list), in the order given; None: the whole suite.

    ``extra`` adds user-defined scenarios (e.g. from :func:`load_scenario_file`); with
    ``names`` None they replace the suite.
    """
    pool = dict(SCENARIOS)
    if extra:
        pool.update(extra)
    if names is None:
        return list(extra.values()) if extra else list(SCENARIOS.values())
    if isinstance(names, str):
        names = [n.strip() for n in names.split(",") if n.strip()]
    if not names:
        raise InputError(f"no scenario named; the suite has: {', '.join(pool)}")
    if len(set(names)) != len(names):
        raise InputError(f"scenarios named twice: {', '.join(names)}")
    missing = [n for n in names if n not in pool]
    if missing:
        raise InputError(f"unknown scenario(s) {', '.join(missing)}; available: {', '.join(pool)}")
    return [pool[n] for n in names]


_SCENARIO_KEYS = {"version", "description", "generator", "events", "duration", "seed", "in_class"}


def scenarios_from_dict(data: Mapping[str, Any]) -> dict[str, Scenario]:
    """User scenarios from the layout of :func:`load_scenario_file`."""
    if not isinstance(data, Mapping) or set(data) - {"scenario"}:
        raise InputError("a scenario file holds only [scenario.NAME] tables")
    tables = data.get("scenario", {})
    if not isinstance(tables, Mapping) or not tables:
        raise InputError("a scenario file needs at least one [scenario.NAME] table")
    out = {}
    for name, table in tables.items():
        if name in SCENARIOS:
            raise InputError(f"[scenario.{name}]: {name} is a built-in scenario; give yours another name")
        if not isinstance(table, Mapping):
            raise InputError(f"[scenario.{name}] must be a table")
        unknown = sorted(set(table) - _SCENARIO_KEYS)
        if unknown:
            raise InputError(f"[scenario.{name}]: unknown keys {unknown}; allowed: {sorted(_SCENARIO_KEYS)}")
        for key in ("version", "description"):
            if key not in table:
                raise InputError(f"[scenario.{name}] needs {key}")
        d = table.get("duration", (1200.0, 1200.0))
        if isinstance(d, (int, float)) and not isinstance(d, bool):
            d = (d, d)
        kwargs = {"name": name, "version": table["version"], "description": table["description"],
                  "generator": table.get("generator", {}), "n_events": table.get("events", 8), "duration": d,
                  "seed": table.get("seed", 2), "in_class": table.get("in_class", False)}
        out[name] = Scenario(**kwargs)
    return out


def load_scenario_file(path: str | Path) -> dict[str, Scenario]:
    """User-defined scenarios from TOML; errors name the file.

    Layout::

        [scenario.short_realistic]
        version = 1
        description = "two 4-min events of the default bridge"
        events = 2
        duration = [240.0, 240.0]     # s
        seed = 0
        in_class = false              # true: the truth lies in the library (marked in-class)
        [scenario.short_realistic.generator]
        mode = "realistic"            # the layout of `vivbench synth --config`
    """
    return load_toml(path, scenarios_from_dict, "scenario file")
