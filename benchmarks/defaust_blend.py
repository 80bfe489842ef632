"""The fixed-order skinning blend of the DeFAUST builder (defaust.fixed_order.blend: the
same bytes on every machine) against the BLAS product it replaced, at a subject's size:
168,853 vertices (subject 0's high-res mesh) x 124 bones, four non-zero weights per vertex
(seeded), each bone a 3 x 4 affine map.

    python benchmarks/defaust_blend.py [repeats]   # prints one Markdown row per way

Columns: the median and range of ``repeats`` (default 5) calls in seconds, and the largest
difference from the fixed-order result. Measured rows: benchmarks/records/defaust_fixed_order.md.
"""
import argparse
import time

import numpy as np

from defaust.fixed_order import blend

N, K, NONZERO = 168_853, 124, 4


def weights(seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """W (N, K) float64 rows of NONZERO weights summing to 1, T (K, 3, 4) float64 maps."""
    rng = np.random.default_rng(seed)
    W = np.zeros((N, K))
    cols = np.argsort(rng.random((N, K)), axis=1)[:, :NONZERO]
    w = rng.random((N, NONZERO))
    W[np.arange(N)[:, None], cols] = w / w.sum(axis=1, keepdims=True)
    return W, rng.normal(size=(K, 3, 4))


def main(repeats: int = 5) -> None:
    W, T = weights()
    ways = {"fixed_order.blend": lambda: blend(W, T),
            "BLAS (W @ T.reshape(K, 12))": lambda: (W @ T.reshape(K, -1)).reshape(N, 3, 4)}
    ref = blend(W, T)
    print("| way | median (s) | range (s) | max difference |")
    print("|---|---:|---:|---:|")
    for name, f in ways.items():
        times = []
        for _ in range(repeats):
            t = time.perf_counter()
            out = f()
            times.append(time.perf_counter() - t)
        print(f"| {name} | {np.median(times):.3f} | {min(times):.3f}-{max(times):.3f} | "
              f"{float(np.abs(out - ref).max()):.1e} |", flush=True)


if __name__ == "__main__":
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("repeats", nargs="?", type=int, default=5)
    main(p.parse_args().repeats)
