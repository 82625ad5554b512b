#!/usr/bin/env python3
"""CPU reference for `vkdiff bench kernels`: float32 matmul GFLOP/s with numpy (OpenBLAS).

Usage: cpu_gemm_peak.py M N K [M N K ...]   -> one JSON object per line.
Best of 5 timed runs after a warm-up, all cores (numpy's default threading). vkdiff embeds this
file and runs it with $VKDIFF_REFERENCE_PYTHON (else python3) when numpy is importable, so both
sides are measured in one run, with OPENBLAS_CORETYPE and OPENBLAS_L2_SIZE removed from its
environment (set on some machines for old OpenBLAS builds, they force slower kernels); the kernel
OpenBLAS chose is reported (threadpoolctl's internal_api and architecture, when installed).
"""
import json
import sys
import time

import numpy as np


def gflops(m, n, k):
    rng = np.random.default_rng(0)
    a = rng.standard_normal((m, k), dtype=np.float32)
    b = rng.standard_normal((k, n), dtype=np.float32)
    a @ b
    best = float("inf")
    for _ in range(5):
        t = time.perf_counter()
        a @ b
        best = min(best, time.perf_counter() - t)
    return 2.0 * m * n * k / best / 1e9


def blas_name():
    try:
        info = np.show_config(mode="dicts")
        blas = info["Build Dependencies"]["blas"]
        return f"{blas.get('name', '?')} {blas.get('version', '')}".strip()
    except Exception:
        return "unknown BLAS"


def blas_kernel():
    try:
        from threadpoolctl import threadpool_info
    except ImportError:
        return None
    for pool in threadpool_info():
        if pool.get("user_api") == "blas":
            return f"{pool.get('internal_api')} {pool.get('version')}, {pool.get('architecture')}, {pool.get('num_threads')} threads"
    return None


if __name__ == "__main__":
    dims = list(map(int, sys.argv[1:]))
    for i in range(0, len(dims), 3):
        m, n, k = dims[i : i + 3]
        print(json.dumps({"m": m, "n": n, "k": k, "gflops": gflops(m, n, k), "numpy": np.__version__, "blas": blas_name(), "kernel": blas_kernel()}))
