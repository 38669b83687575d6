"""vivbench: a testbed for time-varying SINDy on vortex-induced vibration of bridges."""

__version__ = "0.1.0"
__all__ = ["__version__"]
