"""Benchmark of the noise generator (the GPU Pro 7 / S15 texture set): generation time and texture memory.

Run from anywhere: ``python tests/benchmarks/bench_noise.py [--repeat N] [--seed S]``. Not collected by pytest.
"""

from __future__ import annotations

import argparse
import resource
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

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
    cache_table(ns, seconds, args.repeat)
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss  # KiB on Linux
    print(f"peak RSS of this process: {peak / 1024:.0f} MiB")


def cache_table(ns: noise.NoiseSet, generate_s: float, repeat: int) -> None:
    """The cache file of one set: the earlier uncompressed .npz against the compressed one, in one run."""
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        plain = folder / "plain.npz"
        write_plain, _ = best_of(repeat, lambda: np.savez(plain, **ns.arrays()))
        read_plain, _ = best_of(repeat, lambda: {k: v for k, v in np.load(plain).items()})
        path = folder / noise.cache_file_name(ns.seed)
        write_new, _ = best_of(repeat, noise._write_cache, path, ns)
        read_new, (back, _old) = best_of(repeat, noise._read_cache, path, ns.seed)
        assert back is not None and all(
            np.array_equal(a, b) for a, b in zip(back.arrays().values(), ns.arrays().values(), strict=True)
        )
        rows = [
            ("uncompressed .npz", plain.stat().st_size, write_plain, read_plain),
            ("cache (compressed)", path.stat().st_size, write_new, read_new),
        ]
    print()
    print(f"{'cache file':<19} {'MiB':>7} {'write [s]':>10} {'read [s]':>9} {'size ratio':>11}")
    print("-" * 60)
    for label, size, write, read in rows:
        print(f"{label:<19} {size / MIB:>7.2f} {write:>10.3f} {read:>9.3f} {size / rows[0][1]:>11.2f}")
    print(f"a cached seed loads {generate_s / rows[1][3]:.0f}x faster than it generates (bit-identical, checked)")
    print(f"bounds: {noise.CACHE_MAX_SEEDS} sets, {noise.CACHE_MAX_BYTES / MIB:.0f} MiB")


if __name__ == "__main__":
    main()
