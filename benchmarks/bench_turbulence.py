"""Turbulence field: vivbench vs pyconturb's ``gen_turb``, side by side.

Case: u, v, w at the three deck sections (1/4, 1/2, 3/4 of a 1650 m span),
1 h at 32 Hz, U = 8 m/s, I_u = 0.08, Kaimal spectra with Lambda = 42 m,
Davenport coherence (C_u, C_v, C_w) = (10, 7, 4), components independent.

pyconturb gets the same model: its own IEC Kaimal spectrum (at z >= 60 m its
Lambda is 42 m, as ours), the same sigmas (a custom ``sig_func``), and the
Davenport coherence as a custom ``coh_model``. Davenport coherence is 1 at
f = 0, which makes the coherence matrix singular and pyconturb's Cholesky
fail, so the function passed to it is 0 at f = 0; pyconturb zeroes that
(mean) bin anyway, so the field is unchanged. Both scale the spectra to the
target sigma. pyconturb is timed at the fastest of a few ``nf_chunk``.

Run: ``.venv/bin/python benchmarks/bench_turbulence.py``.
"""

from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_var] = "1"

import sys  # noqa: E402
from pathlib import Path  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))  # benchmarks/_timing.py
from _timing import best_of  # noqa: E402
import warnings  # noqa: E402

import numpy as np  # noqa: E402

from vivbench.synth.turbulence import TurbulenceConfig, simulate_turbulence, target_sigmas  # noqa: E402

POSITIONS = np.array([412.5, 825.0, 1237.5])  # m
MEAN_SPEED = 8.0  # m/s
DURATION = 3600.0  # s
FS = 32.0  # Hz
SEED = 2024
NF_CHUNKS = (1024, 4096, 16384, 57601)  # 57601 = all frequencies of 1 h at 32 Hz in one chunk




def _pyconturb_runner(config: TurbulenceConfig, nf_chunk: int):
    from pyconturb import gen_turb
    from pyconturb._utils import gen_spat_grid
    from pyconturb.spectral_models import kaimal_spectrum
    from pyconturb.wind_profiles import constant_profile

    spat_df = gen_spat_grid(POSITIONS, np.array([70.0]))  # columns u_p0, v_p0, w_p0, u_p1, ...
    sigmas = target_sigmas(MEAN_SPEED, config)
    decay = config.coherence_decay

    def sig_func(spat_df, **kwargs):
        return sigmas[spat_df.loc["k"].values.astype(int)]

    def coh_func(ic, freq, r, u_ref, **kwargs):
        return np.where(freq > 0, np.exp(-decay[ic] * freq * r / u_ref), 0.0)

    n_samples = int(round(DURATION * FS))

    def run() -> np.ndarray:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", DeprecationWarning)
            df = gen_turb(spat_df, T=DURATION, nt=n_samples, coh_model=coh_func, wsp_func=constant_profile, sig_func=sig_func,
                          spec_func=kaimal_spectrum, u_ref=MEAN_SPEED, seed=SEED, nf_chunk=nf_chunk)
        values = df.values.reshape(n_samples, POSITIONS.size, 3).copy()
        values[:, :, 0] -= MEAN_SPEED  # constant_profile adds U to u
        return values

    return run


def main(repeats: int = 3, nf_chunks: tuple[int, ...] = NF_CHUNKS) -> dict:
    """Time both generators and check their standard deviations.

    Returns
    -------
    dict
        Times (s), the speed-up, the chosen ``nf_chunk`` and the relative
        sigma errors of both generators.
    """
    config = TurbulenceConfig()
    target = target_sigmas(MEAN_SPEED, config)

    def ours(double_indexing: bool):
        cfg = TurbulenceConfig(double_indexing=double_indexing)
        return lambda: simulate_turbulence(POSITIONS, MEAN_SPEED, DURATION, FS, cfg, np.random.default_rng(SEED))

    ours(True)()  # warm-up (imports, FFT plans)
    t_ours, x_ours = best_of(ours(True), max(10, repeats))
    t_single, x_single = best_of(ours(False), max(10, repeats))

    scan = {}
    for nf_chunk in nf_chunks:
        scan[nf_chunk], _ = best_of(_pyconturb_runner(config, nf_chunk), 1)
    best_chunk = min(scan, key=scan.get)
    t_pct, x_pct = best_of(_pyconturb_runner(config, best_chunk), repeats)

    def sigma_error(x: np.ndarray) -> np.ndarray:
        return x.std(axis=0) / target - 1.0  # (n_points, 3)

    err = {name: sigma_error(x) for name, x in [("ours", x_ours), ("ours_single", x_single), ("pyconturb", x_pct)]}
    result = {
        "n_samples": int(x_ours.shape[0]),
        "n_points": int(POSITIONS.size),
        "time_ours_s": t_ours,
        "time_ours_single_indexed_s": t_single,
        "time_pyconturb_s": t_pct,
        "pyconturb_nf_chunk": int(best_chunk),
        "pyconturb_scan_s": {int(k): v for k, v in scan.items()},
        "speedup": t_pct / t_ours,
        "speedup_single_indexed": t_pct / t_single,
        "target_sigma_u": float(target[0]),
        "sigma_u_ours": x_ours[:, :, 0].std(axis=0).tolist(),
        "sigma_u_pyconturb": x_pct[:, :, 0].std(axis=0).tolist(),
        "max_rel_sigma_error": {name: float(np.abs(e).max()) for name, e in err.items()},
    }

    print(f"turbulence: {POSITIONS.size} points x 3 components, {DURATION:.0f} s at {FS:g} Hz ({result['n_samples']} samples)")
    print(f"{'generator':<34}{'best time (s)':>14}{'max |sigma/target-1|':>22}")
    print(f"{'vivbench (double-indexed)':<34}{t_ours:>14.4f}{result['max_rel_sigma_error']['ours']:>22.2e}")
    print(f"{'vivbench (single-indexed)':<34}{t_single:>14.4f}{result['max_rel_sigma_error']['ours_single']:>22.2e}")
    print(f"{f'pyconturb gen_turb nf_chunk={best_chunk}':<34}{t_pct:>14.4f}{result['max_rel_sigma_error']['pyconturb']:>22.2e}")
    print("pyconturb nf_chunk scan (s): " + ", ".join(f"{k}: {v:.3f}" for k, v in scan.items()))
    print(f"speed-up: {result['speedup']:.1f}x (single-indexed {result['speedup_single_indexed']:.1f}x); target >= 5x")
    print(f"sigma_u target {target[0]:.4f} m/s; ours {np.round(result['sigma_u_ours'], 4).tolist()}, "
          f"pyconturb {np.round(result['sigma_u_pyconturb'], 4).tolist()}")
    return result


if __name__ == "__main__":
    main()
