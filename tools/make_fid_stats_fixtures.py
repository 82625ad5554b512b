#!/usr/bin/env python3
"""Golden values for `eval/src/fid/`: FID and KID of small random feature sets computed by
torch-fidelity's own functions, and numpy's legacy `RandomState(seed).choice(n, k, replace=False)`.

Each set pair is scored twice by torch-fidelity: on float32 tensors (what it does with real
features) and on the same values as float64 tensors (its formulas, without float32 round-off),
which is what an f64 implementation should match closely. FID is also computed exactly (mpmath,
40 digits): torch-fidelity's `eigvals(σ1·σ2)` turns the zero eigenvalues of a rank-deficient
product into noise whose square roots add up (about 1e-7 relative at D = 2048, N = 50).

Usage: make_fid_stats_fixtures.py [OUT_DIR]   (default tests/fixtures/fid_stats; writes
features.safetensors and expected.json)
"""
import json
import pathlib
import sys

import mpmath
import numpy as np
import torch
import torch_fidelity
from safetensors.numpy import save_file
from torch_fidelity.metric_fid import fid_features_to_statistics, fid_statistics_to_metric
from torch_fidelity.metric_kid import kid_features_to_metric

OUT = pathlib.Path(sys.argv[1] if len(sys.argv) > 1 else pathlib.Path(__file__).parent.parent / "tests/fixtures/fid_stats")

# name: (D, N1, N2, KID subsets, KID subset size, seed, same distribution). Small sets (N < D, the
# Gram path), real Inception width, tall sets (N > D, the QR path), one of each, torch-fidelity's
# 100 subsets, and two samples of one distribution (KID near 0, where float32 loses digits).
CASES = {
    "small": (64, 30, 45, 10, 20, 1, False),
    "inception_width": (2048, 50, 60, 10, 20, 2, False),
    "tall": (16, 200, 150, 100, 100, 3, False),
    "mixed": (32, 20, 100, 10, 15, 4, False),
    "same_distribution": (64, 80, 70, 20, 40, 5, True),
}

# (seed, n, k) for RandomState(seed).choice(n, k, replace=False), and draw sequences from one
# RandomState as KID makes them.
CHOICES = [(2020, 1, 1), (2020, 2, 2), (0, 5, 3), (2020, 10, 10), (1, 1000, 20), (2020, 3000, 3000),
           (4294967295, 70000, 1000), (12345, 65537, 300)]
SEQUENCES = [(2020, [(50, 20), (60, 20), (50, 20), (60, 20)]), (7, [(70000, 5), (1, 1), (3, 2), (100, 100)])]


def features(rng, mix, n, shift, scale):
    """ReLU-ish rows like pooled Inception activations: nonnegative, correlated across columns."""
    z = rng.standard_normal((n, mix.shape[0])) @ mix * scale + shift
    return np.abs(z).astype(np.float32)


def fid(x, y):
    s1, s2 = fid_features_to_statistics(x), fid_features_to_statistics(y)
    return fid_statistics_to_metric(s1, s2, verbose=False)["frechet_inception_distance"]


def exact_fid(x, y):
    """|mu1 - mu2|² + tr σ1 + tr σ2 - 2 tr sqrt(σ1σ2) in 40 digits, with tr sqrt(σ1σ2) the sum of
    the singular values of F1·F2ᵀ for any factors σ = FᵀF (the centred rows over sqrt(N - 1), or
    the transposed Cholesky factor of σ when that is smaller)."""
    mpmath.mp.dps = 40

    def stats(v):
        n, d = v.shape
        rows = [[mpmath.mpf(float(e)) for e in r] for r in v]
        mu = [mpmath.fsum(r[j] for r in rows) / n for j in range(d)]
        a = mpmath.matrix([[(r[j] - mu[j]) / mpmath.sqrt(n - 1) for j in range(d)] for r in rows])
        return mu, a if n <= d else mpmath.cholesky(a.T * a).T

    (mu1, f1), (mu2, f2) = stats(x), stats(y)
    norm2 = lambda f: mpmath.fsum(e * e for e in f)
    covmean = mpmath.fsum(mpmath.svd_r(f1 * f2.T, compute_uv=False))
    return float(mpmath.fsum((a - b) ** 2 for a, b in zip(mu1, mu2)) + norm2(f1) + norm2(f2) - 2 * covmean)


def kid(x, y, subsets, size):
    out = kid_features_to_metric(x, y, kid_subsets=subsets, kid_subset_size=size, rng_seed=2020, verbose=False)
    return out["kernel_inception_distance_mean"], out["kernel_inception_distance_std"]


def score(x, y, subsets, size):
    got = {}
    for dtype in ("float32", "float64"):
        tx, ty = (torch.from_numpy(v).to(getattr(torch, dtype)) for v in (x, y))
        mean, std = kid(tx, ty, subsets, size)
        got[dtype] = {"fid": fid(tx, ty), "kid_mean": mean, "kid_std": std}
    return got


def main():
    versions = {"numpy": np.__version__, "torch": torch.__version__, "torch_fidelity": torch_fidelity.__version__}
    print(versions)
    tensors, cases = {}, {}
    for name, (d, n1, n2, subsets, size, seed, same) in CASES.items():
        rng = np.random.default_rng(seed)
        mix = rng.standard_normal((d, d)) / np.sqrt(d)
        x = features(rng, mix, n1, 0.3, 1.0)
        y = features(rng, mix if same else rng.standard_normal((d, d)) / np.sqrt(d), n2, 0.3 if same else 0.35,
                     1.0 if same else 1.1)
        tensors[f"{name}.x"], tensors[f"{name}.y"] = x, y
        cases[name] = {"dim": d, "kid_subsets": subsets, "kid_subset_size": size, "fid_exact": exact_fid(x, y),
                       **score(x, y, subsets, size)}
        print(name, cases[name])
    # torch-fidelity refuses a subset larger than a set; vkdiff clamps it to the smaller set.
    small = cases["small"]
    small["kid_clamped"] = kid(*(torch.from_numpy(tensors[f"small.{s}"]).double() for s in "xy"), 10, 30)
    choices = [{"seed": s, "n": n, "k": k, "indices": np.random.RandomState(s).choice(n, k, replace=False).tolist()}
               for s, n, k in CHOICES]
    sequences = []
    for seed, draws in SEQUENCES:
        rs = np.random.RandomState(seed)
        sequences.append({"seed": seed, "draws": [{"n": n, "k": k, "indices": rs.choice(n, k, replace=False).tolist()}
                                                  for n, k in draws]})
    OUT.mkdir(parents=True, exist_ok=True)
    save_file(tensors, str(OUT / "features.safetensors"))
    (OUT / "features.safetensors").chmod(0o644)
    expected = {"versions": versions, "kid_rng_seed": 2020, "cases": cases, "choices": choices, "sequences": sequences}
    (OUT / "expected.json").write_text(json.dumps(expected, indent=1) + "\n")


if __name__ == "__main__":
    main()
