"""The identification chain of one event: preprocess, differentiate, windowed SINDy, regimes.

Results go to ``<event_id>.identify.nc`` (NetCDF-4): per window and equation
the selected model in physical units, its AICc, RSS, threshold, regime and
identifiability flag; per window the library's condition number; and the
preprocessed series (A, U, dA/dt on the common grid) so that later stages
(clustering, simulation, forecasting) need not preprocess again. The file
format (variables, dims, units, version) is owned by :mod:`vivbench.io.result`
and documented in ``docs/formats.md``.
"""

from __future__ import annotations

import dataclasses
import json
from collections.abc import Callable, Sequence
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import xarray as xr

import vivbench
from vivbench.preprocess.derivative import Derivative
from vivbench.regression.settings import DEFAULT_THRESHOLDS
from vivbench.models.window import EventWindowSINDy
from vivbench.preprocess.noise_floor import window_amplitude_snr
from vivbench.regression.optimizers import OPTIMIZERS
from vivbench.regimes.window import label_windows
from vivbench.preprocess.config import PreprocessConfig
from vivbench.preprocess.wind import perpendicular_speed, wind_speed_direction
from vivbench.preprocess.yaw import event_yaw
from vivbench.preprocess.chain import preprocess_arrays
from vivbench.io.event import event_arrays, peek_event_id, read_event
from vivbench.io.result import WINDOW_FIT_VARIABLES, build_result, write_result
from vivbench.io.quality import check_acc_magnitude, check_wind_magnitude, check_wind_varies, despike
from vivbench.core.errors import InputError

__all__ = ["IdentifyConfig", "identify_event", "identify_files"]


@dataclass(frozen=True, kw_only=True)
class IdentifyConfig:
    """Settings of the identification chain.

    Attributes
    ----------
    preprocess : PreprocessConfig
    derivative : Derivative (default: total-variation regularised, Chartrand 2011, with the
        band-limited-noise setting of :meth:`Derivative.for_envelope`)
    window, step : s (the paper: 50 s and 25 s)
    thresholds : STLSQ threshold path on standardised coefficients (None: the engine's default)
    alpha : ridge parameter of STLSQ
    scaling : library basis, "scaled" (centred and scaled U), "normalized" or "raw"
    tau : regime threshold (docs/concepts.md (regimes))
    aicc_margin : models within this AICc of the best count as competitors
    fit_tolerance : relative RMS residual within which an order-restricted model fits equally well
    spike_mad : spike rule of the raw u, v and acc, robust standard deviations (1.4826 MAD) from the
        10 s block median (see vivbench.io.quality.despike); spike runs up to 0.1 s are bridged linearly,
        longer ones become NaN and split the record. None: off
    min_snr : a window's regime counts as identifiable only if its mean amplitude is at least this many
        times the accelerometers' noise floor in the vibration band (see
        :mod:`vivbench.preprocess.noise_floor`; the envelope of noise alone averages 1.25 times the floor).
        None: no test
    optimizer : sparse regression per window, "stlsq" (the fast engine), "sr3" or "ensemble"
        (pysindy-based, see :mod:`vivbench.regression.optimizers`; "ensemble" adds ``inclusion``)
    seed : seed of the ensemble's bootstrap samples (results depend on it only)
    """

    preprocess: PreprocessConfig = field(default_factory=PreprocessConfig)
    derivative: Derivative = field(default_factory=Derivative.for_envelope)
    window: float = 50.0
    step: float = 25.0
    thresholds: tuple[float, ...] = DEFAULT_THRESHOLDS
    alpha: float = 0.05
    scaling: str = "scaled"
    tau: float = 0.2
    aicc_margin: float = 2.0
    fit_tolerance: float = 0.1
    spike_mad: float | None = 8.0
    min_snr: float | None = 3.0
    optimizer: str = "stlsq"
    seed: int = 0

    def __post_init__(self) -> None:
        if self.spike_mad is not None and not (isinstance(self.spike_mad, (int, float)) and np.isfinite(self.spike_mad)
                                               and self.spike_mad > 1):
            raise InputError(f"spike_mad must be None (no despiking) or a finite number > 1 of robust standard deviations; got {self.spike_mad!r}")
        object.__setattr__(self, "thresholds", tuple(float(x) for x in self.thresholds))
        if not (self.window > 0 and self.step > 0):
            raise InputError(f"window and step must be positive seconds; got window={self.window}, step={self.step}")
        if not 0 < self.tau < 1:
            raise InputError(f"tau must be in (0, 1); got {self.tau}")
        if self.aicc_margin < 0 or self.fit_tolerance < 0:
            raise InputError("aicc_margin and fit_tolerance must be >= 0")
        if self.min_snr is not None and not (isinstance(self.min_snr, (int, float)) and np.isfinite(self.min_snr)
                                             and self.min_snr >= 0):
            raise InputError(f"min_snr must be None (no noise-floor test) or a finite number >= 0; got {self.min_snr!r}")
        if self.optimizer not in OPTIMIZERS:
            raise InputError(f"optimizer must be one of {', '.join(OPTIMIZERS)}; got {self.optimizer!r}")
        if isinstance(self.seed, bool) or not isinstance(self.seed, (int, np.integer)) or self.seed < 0:
            raise InputError(f"seed must be an integer >= 0; got {self.seed!r}")
        # the estimator validates the rest (thresholds, alpha, scaling) when it is built
        self.estimator()

    def estimator(self) -> EventWindowSINDy:
        est = EventWindowSINDy(window=self.window, step=self.step, thresholds=self.thresholds, alpha=self.alpha,
                            scaling=self.scaling, keep_path=False, optimizer=self.optimizer,
                            random_state=self.seed)
        est.settings()
        return est

    def to_json(self) -> str:
        return json.dumps(dataclasses.asdict(self), sort_keys=True, default=float)


# Attribute of the fitted EventWindowSINDy (or verdict of label_windows) behind each window variable of
# the result; the variables' dims, units and meanings are the result format's (vivbench.io.result).
_FITTED = {name: f"{name}_" for name in WINDOW_FIT_VARIABLES}


def _empty_fit(n_sections: int) -> dict:
    p = 23 * n_sections
    shapes = {"coef": (0, n_sections, p), "order_rms": (0, n_sections, 4), "cond": (0,), "n_samples": (0,)}
    return {name: np.zeros(shapes.get(name, (0, n_sections))) for name in WINDOW_FIT_VARIABLES}


def identify_event(tree: xr.DataTree, config: IdentifyConfig | None = None, *, source: str = "") -> xr.Dataset:
    """Run the identification chain on one event.

    Parameters
    ----------
    tree : an event (docs/formats.md), synthetic or field
    config : IdentifyConfig
    source : file name recorded in the result

    Returns
    -------
    xarray.Dataset
        The result (see module docstring); coordinates ``window``, ``equation``,
        ``feature``, ``order`` and ``time`` (the preprocessing grid). Data-quality
        attributes: ``quality_rate_{wind,accel}_hz`` (median rates),
        ``quality_missing_fraction_{wind,accel}`` (time stamps with a NaN in
        any section), ``quality_spikes_{wind,accel}`` and
        ``quality_spikes_bridged_{wind,accel}`` (see ``spike_mad``),
        ``quality_segments``, ``quality_windows``,
        ``quality_windows_without_model``, plus the event's own ``quality_*``
        attributes (repairs made on import).

    Raises
    ------
    ValueError
        When no segment of the record is long enough for one window; when the
        acceleration or the wind has a magnitude no bridge sees (a wrong unit)
        or the wind never varies at a section (see vivbench.io.quality).
    """
    config = config or IdentifyConfig()
    # The truth is never read here: identification must not see it (and a truth written by
    # another tool, partial or absent, must not stop it).
    arr = event_arrays(tree, truth=False)
    sections = list(arr["sections"])
    arr, quality = _data_quality(arr, float(tree.attrs["span_azimuth_deg"]), config)
    pre = preprocess_arrays(wind_time=arr["wind_time"], u=arr["u"], v=arr["v"], accel_time=arr["accel_time"],
                            acc=arr["acc"], span_azimuth_deg=float(tree.attrs["span_azimuth_deg"]),
                            config=config.preprocess)
    # The mean wind's yaw on the same grid: the varying campaign model's second covariate (U does not carry it).
    yaw = event_yaw(arr["wind_time"], arr["u"], arr["v"], float(tree.attrs["span_azimuth_deg"]), pre.t,
                    config.preprocess)
    dA = np.full_like(pre.A, np.nan)
    parts, starts, ends, segs = [], [], [], []
    est = config.estimator()
    for seg in np.unique(pre.segment[pre.segment >= 0]):
        sel = pre.segment == seg
        t = pre.t[sel]
        if t.size < 2 or t[-1] - t[0] < config.window:
            continue
        dA[sel] = config.derivative.differentiate(pre.A[sel], t)
        verdict = label_windows(est, t, pre.A[sel], pre.U[sel], dA[sel], tau=config.tau, margin=config.aicc_margin,
                                fit_tolerance=config.fit_tolerance)
        parts.append({name: verdict[name] if name in verdict else getattr(est, attr)
                      for name, attr in _FITTED.items()})
        if config.optimizer == "ensemble":
            parts[-1]["inclusion"] = est.inclusion_
        starts.append(est.window_start_)
        ends.append(est.window_end_)
        segs.append(np.full(est.window_start_.size, seg))
    if not parts:
        longest = max((float(np.ptp(pre.t[pre.segment == s])) for s in np.unique(pre.segment[pre.segment >= 0])), default=0.0)
        raise InputError(f"no valid segment is as long as one window ({config.window:g} s); the longest is {longest:.0f} s")
    fit = {name: np.concatenate([p[name] for p in parts], axis=0) for name in WINDOW_FIT_VARIABLES}
    n_w = fit["cond"].shape[0]
    window_start, window_end = np.concatenate(starts), np.concatenate(ends)
    snr = window_amplitude_snr(pre.t, pre.A, window_start, window_end, pre.noise_std)
    if config.min_snr is not None:
        # Below the noise floor A is the envelope of noise: no regression can give its regime.
        fit["identifiable"] = fit["identifiable"] & ~(snr < config.min_snr)
    quality["quality_segments"] = int(pre.n_segments)
    quality["quality_windows"] = int(n_w)
    quality["quality_windows_without_model"] = int(np.sum(np.any(fit["regime"] == 0, axis=1)))
    ok = fit["regime"] > 0
    coverage = float(fit["identifiable"][ok].mean()) if ok.any() else float("nan")
    attrs = {
        "event_id": str(tree.attrs["event_id"]),
        "source_file": source,
        "event_source": str(tree.attrs["source"]),
        "f_mode_hz": float(pre.f_mode_hz),
        "f_mode_source": pre.f_mode_source,
        "edge_s": float(pre.edge_s),
        "noise_std_m": [float(x) for x in pre.noise_std],
        "span_azimuth_deg": float(pre.span_azimuth_deg),
        "coverage": coverage,
        "identify_config_json": config.to_json(),
        "vivbench_version": vivbench.__version__,
    }
    distance = [tree.attrs.get(f"wind_distance_m_{sec}") for sec in sections]
    if all(d is not None for d in distance):  # the wind was taken from anemometers elsewhere on the span
        attrs["wind_distance_m"] = [float(d) for d in distance]
    # Repairs made when the event was imported travel with the result; this run's own come after.
    attrs.update({k: v for k, v in tree.attrs.items() if str(k).startswith("quality_") and k not in quality})
    attrs.update(quality)
    return build_result(
        fit=fit, window_start=window_start, window_end=window_end, window_segment=np.concatenate(segs),
        amplitude_snr=snr, time=pre.t, A=pre.A, U=pre.U, dA=dA, segment=pre.segment, sections=sections,
        features=est.feature_names_ if n_w else [], derivative_method=config.derivative.method, attrs=attrs,
        inclusion=np.concatenate([p["inclusion"] for p in parts]) if config.optimizer == "ensemble" else None,
        yaw=yaw)


# Resolution floors of the spike rule's MAD: 0.05 m/s for sonic anemometers (records are
# often quantised to 0.01 m/s), 1e-3 m/s^2 for accelerometers (about 16-bit steps of +-2 g).
_SPIKE_FLOOR = {"wind": 0.05, "accel": 1e-3}
# Spike runs up to 0.1 s (3 wind or 5 acceleration samples) are bridged linearly: far shorter
# than the 60 s mean-wind time scale and the 3 s period of the VIV mode, and not worth the
# 2 x edge_s of record that a split costs. Longer runs stay NaN and split the record.
_SPIKE_BRIDGE_S = 0.1
_FIX_UNITS = "in the import mapping and re-import (event files hold SI units)"


def _data_quality(arr: dict, span_azimuth_deg: float, config: IdentifyConfig) -> tuple[dict, dict]:
    """Refuse implausible records and replace spikes by NaN; returns the cleaned arrays and quality_* attributes."""
    sections = list(arr["sections"])
    check_acc_magnitude(arr["acc"], "m/s^2", where="/accel/acc", labels=sections, fix=_FIX_UNITS)
    check_wind_magnitude(arr["u"], arr["v"], "m/s", where="/wind", labels=sections, fix=_FIX_UNITS)
    rates = {"wind": 1.0 / float(np.median(np.diff(arr["wind_time"]))),
             "accel": 1.0 / float(np.median(np.diff(arr["accel_time"])))}
    missing_wind = ~(np.isfinite(arr["u"]) & np.isfinite(arr["v"])).all(axis=1)
    missing_accel = ~np.isfinite(arr["acc"]).all(axis=1)
    out = dict(arr)
    spikes = {"wind": 0, "accel": 0}
    bridged = {"wind": 0, "accel": 0}
    if config.spike_mad is not None:
        for group, names in (("wind", ("u", "v")), ("accel", ("acc",))):
            for name in names:
                out[name], n, nb = despike(arr[name], rates[group], threshold=config.spike_mad,
                                           floor=_SPIKE_FLOOR[group], bridge_s=_SPIKE_BRIDGE_S)
                spikes[group] += n
                bridged[group] += nb
    V, theta = wind_speed_direction(out["u"], out["v"])
    check_wind_varies(perpendicular_speed(V, theta, span_azimuth_deg), where="/wind", labels=sections)
    quality = {
        "quality_rate_wind_hz": rates["wind"],
        "quality_rate_accel_hz": rates["accel"],
        "quality_missing_fraction_wind": float(missing_wind.mean()),
        "quality_missing_fraction_accel": float(missing_accel.mean()),
        "quality_spike_mad": float(config.spike_mad or 0.0),
        "quality_spikes_wind": int(spikes["wind"]),
        "quality_spikes_accel": int(spikes["accel"]),
        "quality_spikes_bridged_wind": int(bridged["wind"]),
        "quality_spikes_bridged_accel": int(bridged["accel"]),
    }
    return out, quality


def _identify_one(path: str, out_dir: str, config: IdentifyConfig) -> str:
    tree = read_event(path, truth=False)
    ds = identify_event(tree, config, source=Path(path).name)
    return str(write_result(ds, out_dir))


def _file_size(path) -> int:
    try:
        return Path(path).stat().st_size
    except OSError:
        return 0


def identify_files(paths: Sequence[str | Path], out_dir: str | Path, config: IdentifyConfig | None = None, *,
                   workers: int = 1, progress: Callable[[str], None] | None = None) -> tuple[list[Path], dict[str, str]]:
    """Identify every event file; a failing file is reported and the others finish.

    Returns
    -------
    written : result files, in the order of ``paths``
    failures : file -> one-line message
    """
    config = config or IdentifyConfig()
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    written: dict[str, Path] = {}
    failures: dict[str, str] = {}

    def record(path, fn):
        try:
            written[str(path)] = Path(fn())
        except (InputError, OSError) as exc:  # documented refusals (EventFormatError is an InputError)
            msg = " ".join(str(exc).split())
            failures[str(path)] = msg if msg.startswith(str(path)) else f"{path}: {msg}"
        except Exception as exc:  # noqa: BLE001 - a bug; one bad event must not stop the others
            failures[str(path)] = f"{path}: internal error ({type(exc).__name__}: {' '.join(str(exc).split())})"
        if progress is not None:
            progress(str(path))

    # Two events with one id would write one result file over the other.
    first_with: dict[str, str] = {}
    for p in paths:
        eid = peek_event_id(p)
        if eid is not None and eid in first_with:
            failures[str(p)] = (f"{p}: event_id {eid!r} is also that of {first_with[eid]}; their results would "
                                f"overwrite each other (give one of them another event_id)")
            if progress is not None:
                progress(str(p))
        elif eid is not None:
            first_with[eid] = str(p)
    todo = [p for p in paths if str(p) not in failures]
    if workers <= 1:
        for p in todo:
            record(p, lambda p=p: _identify_one(str(p), str(out), config))
    else:
        # Longest first (file size as the proxy): a long event started last
        # would leave the other workers idle while it finishes.
        todo = sorted(todo, key=_file_size, reverse=True)
        with ProcessPoolExecutor(max_workers=workers) as pool:
            futs = {pool.submit(_identify_one, str(p), str(out), config): p for p in todo}
            for fut in as_completed(futs):
                record(futs[fut], fut.result)
    return [written[str(p)] for p in paths if str(p) in written], failures
