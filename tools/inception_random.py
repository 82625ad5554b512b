"""Reproducible random weights for torch-fidelity's FID InceptionV3, drawn bit for bit as
`vkdiff_unet::RandomInception` draws them: element i of tensor `name` is the top 24 bits of
splitmix64(fnv1a64(name) + i) / 2^24, mapped in float32 to He-uniform convolutions and batch norms
near the identity. Used by make_fid_fixtures.py; importable by anyone checking vkdiff fid."""

import numpy as np
import torch.nn as nn
from torch_fidelity.feature_extractor_inceptionv3 import (
    BasicConv2d,
    InceptionA,
    InceptionB,
    InceptionC,
    InceptionD,
    InceptionE_1,
    InceptionE_2,
)

M64 = (1 << 64) - 1


def fnv1a64(name):
    h = 0xCBF29CE484222325
    for b in name.encode():
        h = ((h ^ b) * 0x100000001B3) & M64
    return h


def uniform(name, n):
    with np.errstate(over="ignore"):
        z = np.arange(n, dtype=np.uint64) + np.uint64(fnv1a64(name)) + np.uint64(0x9E3779B97F4A7C15)
        z = (z ^ (z >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
        z = (z ^ (z >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
        z = z ^ (z >> np.uint64(31))
    return (z >> np.uint64(40)).astype(np.float32) / np.float32(1 << 24)


def skeleton():
    """torch-fidelity's FeatureExtractorInceptionV3 module tree, without loading weights."""
    m = nn.Module()
    m.Conv2d_1a_3x3 = BasicConv2d(3, 32, kernel_size=3, stride=2)
    m.Conv2d_2a_3x3 = BasicConv2d(32, 32, kernel_size=3)
    m.Conv2d_2b_3x3 = BasicConv2d(32, 64, kernel_size=3, padding=1)
    m.Conv2d_3b_1x1 = BasicConv2d(64, 80, kernel_size=1)
    m.Conv2d_4a_3x3 = BasicConv2d(80, 192, kernel_size=3)
    m.Mixed_5b = InceptionA(192, pool_features=32)
    m.Mixed_5c = InceptionA(256, pool_features=64)
    m.Mixed_5d = InceptionA(288, pool_features=64)
    m.Mixed_6a = InceptionB(288)
    m.Mixed_6b = InceptionC(768, channels_7x7=128)
    m.Mixed_6c = InceptionC(768, channels_7x7=160)
    m.Mixed_6d = InceptionC(768, channels_7x7=160)
    m.Mixed_6e = InceptionC(768, channels_7x7=192)
    m.Mixed_7a = InceptionD(768)
    m.Mixed_7b = InceptionE_1(1280)
    m.Mixed_7c = InceptionE_2(2048)
    m.fc = nn.Linear(2048, 1008)
    return m


def random_inception_state_dict():
    one, two, tenth = np.float32(1), np.float32(2), np.float32(0.1)
    out = {}
    for name, t in skeleton().state_dict().items():
        if name.endswith("num_batches_tracked"):
            continue
        u = uniform(name, t.numel())
        if name.endswith("conv.weight"):
            bound = np.float32(np.sqrt(6.0 / (t.shape[1] * t.shape[2] * t.shape[3])))
            v = (two * u - one) * bound
        elif name.endswith("bn.weight"):
            v = one + tenth * (two * u - one)
        elif name.endswith(("bn.bias", "bn.running_mean")):
            v = tenth * (two * u - one)
        elif name.endswith("bn.running_var"):
            v = np.float32(0.5) + u
        else:  # fc: not part of the pooled features
            v = np.float32(0.02) * (two * u - one)
        out[name] = v.astype(np.float32).reshape(tuple(t.shape))
    return out
