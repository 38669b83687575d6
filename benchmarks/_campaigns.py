"""Generator settings shared by the benchmarks."""

from vivbench.synth import GeneratorConfig, SensorConfig, TurbulenceConfig

#: The noise-free bridge: no sensor noise or quantisation, no anemometer error,
#: turbulence, buffeting or unlocked vortex shedding. The in_library mode (docs/concepts.md (no inverse crime)):
#: its recovery is scored against the truth's exact coefficient matrix.
CLEAN = GeneratorConfig.in_library(
    aero=dict(cl_unlocked=0.0, buffeting_w=0.0),
    wind=dict(turbulence=TurbulenceConfig(intensity=0.0), noise=0.0, resolution=0.0),
    sensors=SensorConfig(noise_density=0.0, bits=0),
)
