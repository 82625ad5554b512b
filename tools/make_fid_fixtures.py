"""Fixtures for `vkdiff fid`: two small image folders, the 2048-d Inception features torch-fidelity
computes for each image, and its FID and KID between the folders.

The Inception weights are the real architecture with reproducible random values, drawn here bit
for bit as `vkdiff_unet::RandomInception` draws them (splitmix64 of an FNV-1a hash of the tensor
name plus the element index; float32 arithmetic), so the test rebuilds them instead of committing
a 95 MB file. torch-fidelity loads them from a .pth exactly as it loads the real
`weights-inception-2015-12-05-6726825d.pth`.

    /tmp/ref/bin/pip install torch torch-fidelity safetensors pillow numpy
    /tmp/ref/bin/python tools/make_fid_fixtures.py

Writes tests/fixtures/fid/{real,fake}/*.{png,jpg}, features.safetensors and expected.json.
"""

import json
import os
import sys
import tempfile

import numpy as np
import torch
import torch_fidelity
from PIL import Image
from safetensors.numpy import save_file
from torch_fidelity.feature_extractor_inceptionv3 import FeatureExtractorInceptionV3

sys.path.insert(0, os.path.dirname(__file__))
from inception_random import random_inception_state_dict  # noqa: E402

OUT = os.path.join(os.path.dirname(__file__), "..", "tests", "fixtures", "fid")


def image(rng, h, w):
    """Smooth colour fields with some noise: image-like statistics, small PNGs."""
    y, x = np.mgrid[0:h, 0:w].astype(np.float64)
    chans = []
    for _ in range(3):
        fy, fx, ph = rng.uniform(0.02, 0.2), rng.uniform(0.02, 0.2), rng.uniform(0, 6.3)
        chans.append(127.5 + 90 * np.sin(fy * y + ph) * np.cos(fx * x - ph) + rng.normal(0, 12, (h, w)))
    return np.clip(np.stack(chans, -1), 0, 255).astype(np.uint8)


def write_sets(rng):
    real = [(64, 64), (80, 48), (48, 96), (120, 100), (37, 53)]
    fake = [(64, 64), (64, 64), (90, 70), (299, 299), (61, 40), (128, 96)]
    names = {}
    for folder, sizes in (("real", real), ("fake", fake)):
        os.makedirs(os.path.join(OUT, folder), exist_ok=True)
        names[folder] = []
        for i, (h, w) in enumerate(sizes):
            img = Image.fromarray(image(rng, h, w))
            # PIL's convert("RGB") as torch-fidelity reads them: grey, alpha and palette PNGs.
            if folder == "fake" and i == 1:
                img = img.convert("L")
            if folder == "fake" and i == 2:
                img = img.convert("RGBA")
                img.putalpha(Image.fromarray(image(rng, h, w)[:, :, 0]))
            if folder == "fake" and i == 4:
                img = img.convert("P", palette=Image.Palette.ADAPTIVE, colors=64)
            # Real photos are JPEG: the last one is, with 4:2:0 chroma (Pillow's default).
            ext = "jpg" if folder == "real" and i == len(sizes) - 1 else "png"
            name = f"{folder}_{i:02d}.{ext}"
            img.save(os.path.join(OUT, folder, name), **({"quality": 90} if ext == "jpg" else {}))
            names[folder].append(name)
    return names


def main():
    rng = np.random.default_rng(20261125)
    names = write_sets(rng)
    with tempfile.TemporaryDirectory() as tmp:
        weights = os.path.join(tmp, "inception-random.pth")
        torch.save({k: torch.from_numpy(v) for k, v in random_inception_state_dict().items()}, weights)
        extractor = FeatureExtractorInceptionV3("inception-v3-compat", ["2048"], feature_extractor_weights_path=weights)
        features = {}
        for folder, files in names.items():
            rows = []
            for f in files:
                img = Image.open(os.path.join(OUT, folder, f)).convert("RGB")
                x = torch.from_numpy(np.asarray(img).copy()).permute(2, 0, 1)[None]
                with torch.no_grad():
                    rows.append(extractor(x)[0][0].numpy())
            features[folder] = np.stack(rows)
        save_file({k: v.astype(np.float32) for k, v in features.items()}, os.path.join(OUT, "features.safetensors"))
        # Five real images: the KID subset size is clamped to 5 (torch-fidelity refuses more).
        kid_subset_size = min(len(names["real"]), len(names["fake"]))
        metrics = torch_fidelity.calculate_metrics(
            input1=os.path.join(OUT, "fake"),
            input2=os.path.join(OUT, "real"),
            fid=True,
            kid=True,
            kid_subset_size=kid_subset_size,
            feature_extractor="inception-v3-compat",
            feature_extractor_weights_path=weights,
            batch_size=1,
            cuda=False,
            cache=False,
            verbose=False,
            samples_find_ext="png,jpg",
        )
    expected = {
        "made_by": "tools/make_fid_fixtures.py",
        "versions": {"torch": torch.__version__, "torch_fidelity": torch_fidelity.__version__, "numpy": np.__version__},
        "files": names,
        "kid_subset_size": kid_subset_size,
        "kid_subsets": 100,
        "fid": metrics["frechet_inception_distance"],
        "kid_mean": metrics["kernel_inception_distance_mean"],
        "kid_std": metrics["kernel_inception_distance_std"],
    }
    with open(os.path.join(OUT, "expected.json"), "w") as f:
        json.dump(expected, f, indent=1)
    print(json.dumps({k: v for k, v in expected.items() if k != "files"}, indent=1))


if __name__ == "__main__":
    main()
