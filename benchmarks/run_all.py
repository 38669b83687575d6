"""Run every benchmark in one process and write benchmarks/out/results.json.

Each ``bench_*.py`` defines ``main() -> dict``; a benchmark whose reference
package is missing is reported and skipped, never faked.
"""

from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import importlib.util  # noqa: E402
import json  # noqa: E402
import platform  # noqa: E402
import sys  # noqa: E402
import traceback  # noqa: E402
from pathlib import Path  # noqa: E402

HERE = Path(__file__).resolve().parent


def main() -> int:
    results = {"python": sys.version.split()[0], "machine": platform.machine(), "cpus": os.cpu_count()}
    failed = False
    only = set(sys.argv[1:])
    for path in sorted(HERE.glob("bench_*.py")):
        name = path.stem.removeprefix("bench_")
        if only and name not in only:
            continue
        print(f"\n=== {name} ===", flush=True)
        spec = importlib.util.spec_from_file_location(path.stem, path)
        module = importlib.util.module_from_spec(spec)
        try:
            spec.loader.exec_module(module)
            results[name] = module.main()
        except ModuleNotFoundError as exc:
            print(f"skipped: {exc}")
            results[name] = {"skipped": str(exc)}
        except Exception:
            traceback.print_exc()
            results[name] = {"error": traceback.format_exc(limit=1)}
            failed = True
    out = HERE / "out"
    out.mkdir(exist_ok=True)
    (out / "results.json").write_text(json.dumps(results, indent=2, default=float) + "\n")
    print(f"\nwrote {out / 'results.json'}")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
