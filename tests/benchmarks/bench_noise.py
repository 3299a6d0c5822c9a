"""Benchmark of the noise generator (the GPU Pro 7 / S15 texture set): generation time and texture memory.

Run from anywhere: ``python tests/benchmarks/bench_noise.py [--repeat N] [--seed S]``. Not collected by pytest.
"""

from __future__ import annotations

import argparse
import resource
import sys
import time
from pathlib import Path

REPO_ROOT = Path(__file__).resolve().parents[2]
if str(REPO_ROOT) not in sys.path:
    sys.path.insert(0, str(REPO_ROOT))

from nubis_addon.core import noise  # noqa: E402

MIB = 1024 * 1024


def best_of(repeat: int, fn, *args):
    best = float("inf")
    result = None
    for _ in range(repeat):
        t0 = time.perf_counter()
        result = fn(*args)
        best = min(best, time.perf_counter() - t0)
    return best, result


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=3, help="runs per measurement; the best is reported")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()

    parts = [
        ("lf", "LF 128^3 RGBA", noise._make_lf, noise.LF_SIZE),
        ("hf", "HF 32^3 RGB", noise._make_hf, noise.HF_SIZE),
        ("curl", "curl 128^2 RGB", noise._make_curl, noise.CURL_SIZE),
        ("cirrus", "cirrus 512^2 RGB", noise._make_cirrus, noise.CIRRUS_SIZE),
    ]
    rows = []
    for _, label, make, size in parts:
        seconds, arr = best_of(args.repeat, make, args.seed, size)
        rows.append((label, seconds, arr.nbytes / MIB, noise.mip_chain_nbytes(arr) / MIB))
    seconds, ns = best_of(args.repeat, noise.generate_noise_set, args.seed)
    rows.append(("full set", seconds, ns.nbytes / MIB, ns.nbytes_with_mips / MIB))
    mip_seconds, _ = best_of(args.repeat, lambda: [noise.mip_chain(a) for a in ns.arrays().values()])

    print(f"Nubis noise v{noise.NOISE_VERSION}, seed {args.seed}, best of {args.repeat}")
    print(f"{'texture':<18} {'time [s]':>9} {'MiB':>8} {'MiB+mips':>9}")
    print("-" * 47)
    for label, sec, mib, mib_mips in rows:
        if label == "full set":
            print("-" * 47)
        print(f"{label:<18} {sec:>9.3f} {mib:>8.3f} {mib_mips:>9.3f}")
    print(f"{'mip chains (all)':<18} {mip_seconds:>9.3f}")
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss  # KiB on Linux
    print(f"peak RSS of this process: {peak / 1024:.0f} MiB")


if __name__ == "__main__":
    main()
