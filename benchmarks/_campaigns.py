"""Generator settings shared by the benchmarks."""

from vivbench.synth import AeroConfig, GeneratorConfig, SensorConfig, TurbulenceConfig, WindConfig

#: The noise-free bridge: no sensor noise or quantisation, no anemometer error,
#: turbulence, buffeting or unlocked vortex shedding.
CLEAN = GeneratorConfig(
    aero=AeroConfig(cl_unlocked=0.0, buffeting_w=0.0),
    wind=WindConfig(turbulence=TurbulenceConfig(intensity=0.0), noise=0.0, resolution=0.0),
    sensors=SensorConfig(noise_density=0.0, bits=0),
)
