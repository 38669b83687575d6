"""Configuration of the synthetic accelerometers and their defects: frozen, keyword-only dataclasses."""

from __future__ import annotations

from dataclasses import dataclass, field

from vivbench.core.errors import require

__all__ = ["DefectConfig", "SensorConfig"]


@dataclass(frozen=True, kw_only=True)
class DefectConfig:
    """Sensor defects for robustness studies (docs/concepts.md (the bridge and the wind)); all off by default.

    Attributes
    ----------
    dropouts_per_hour : mean number of NaN blocks per hour in each stream
    dropout_duration : (min, max) length of a block, s
    spikes_per_hour : mean number of single-sample spikes per hour per channel
    spike_amplitude : spike size in units of the channel's rms
    clock_offset : s, accelerometer clock minus anemometer clock
    clock_drift_ppm : accelerometer clock rate error, parts per million
    """

    dropouts_per_hour: float = 0.0
    dropout_duration: tuple[float, float] = (1.0, 30.0)
    spikes_per_hour: float = 0.0
    spike_amplitude: float = 20.0
    clock_offset: float = 0.0
    clock_drift_ppm: float = 0.0

    def __post_init__(self) -> None:
        object.__setattr__(self, "dropout_duration", tuple(float(x) for x in self.dropout_duration))
        require(self.dropouts_per_hour >= 0, f"dropouts_per_hour must be >= 0; got {self.dropouts_per_hour}")
        lo, hi = self.dropout_duration
        require(0 < lo <= hi, f"dropout_duration must be (min, max) seconds with 0 < min <= max; got {self.dropout_duration}")
        require(self.spikes_per_hour >= 0, f"spikes_per_hour must be >= 0; got {self.spikes_per_hour}")
        require(self.spike_amplitude > 0, f"spike_amplitude must be positive; got {self.spike_amplitude}")
        require(abs(self.clock_offset) <= 60, f"clock_offset must be within +-60 s; got {self.clock_offset}")
        require(abs(self.clock_drift_ppm) <= 1e4, f"clock_drift_ppm must be within +-1e4; got {self.clock_drift_ppm}")

    @property
    def any(self) -> bool:
        return bool(self.dropouts_per_hour or self.spikes_per_hour or self.clock_offset or self.clock_drift_ppm)


@dataclass(frozen=True, kw_only=True)
class SensorConfig:
    """Accelerometers (docs/concepts.md (the bridge and the wind)).

    Attributes
    ----------
    rate : Hz
    noise_density : micro-g per sqrt(Hz), white noise floor
    full_scale : g; the 16-bit converter spans +-full_scale
    bits : converter resolution
    defects : optional defects, off by default
    """

    rate: float = 50.0
    noise_density: float = 30.0
    full_scale: float = 1.0
    bits: int = 16
    defects: DefectConfig = field(default_factory=DefectConfig)

    def __post_init__(self) -> None:
        if isinstance(self.defects, dict):
            object.__setattr__(self, "defects", DefectConfig(**{k: tuple(v) if isinstance(v, list) else v for k, v in self.defects.items()}))
        require(self.rate > 0, f"rate must be positive; got {self.rate}")
        require(self.noise_density >= 0, f"noise_density must be >= 0; got {self.noise_density}")
        require(self.full_scale > 0, f"full_scale must be positive (g); got {self.full_scale}")
        require(self.bits == 0 or 8 <= self.bits <= 32, f"bits must be 0 (no quantisation) or 8..32; got {self.bits}")

