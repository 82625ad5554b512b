#!/usr/bin/env python3
"""torch-fidelity's InceptionV3 feature extraction on the CPU (torch, float32): images per second
over a folder of PNGs, read and batched as torch-fidelity reads them.

Run by `vkdiff bench fid` in the same run as its own measurement, on the same folder and with the
same weights (a safetensors file of torch-fidelity's tensor names, saved here as the .pth that
torch-fidelity loads). Prints one JSON line.
Setup: pip install torch torch-fidelity safetensors   ($VKDIFF_REFERENCE_PYTHON, else python3)
Usage: fid_cpu_reference.py WEIGHTS.safetensors FOLDER BATCH
"""
import json
import os
import resource
import sys
import tempfile
import time

import torch
import torch_fidelity
from safetensors.torch import load_file
from torch.utils.data import DataLoader
from torch_fidelity.datasets import ImagesPathDataset
from torch_fidelity.feature_extractor_inceptionv3 import FeatureExtractorInceptionV3
from torch_fidelity.utils import glob_samples_paths


def main():
    weights, folder, batch = sys.argv[1], sys.argv[2], int(sys.argv[3])
    with tempfile.TemporaryDirectory() as tmp:
        pth = os.path.join(tmp, "inception.pth")
        state = load_file(weights)
        state.setdefault("fc.weight", torch.zeros(1008, 2048))
        state.setdefault("fc.bias", torch.zeros(1008))
        torch.save(state, pth)
        extractor = FeatureExtractorInceptionV3("inception-v3-compat", ["2048"], feature_extractor_weights_path=pth)
    files = glob_samples_paths(folder, False, "png", verbose=False)
    # torch-fidelity's loader: worker processes decode while the network runs.
    loader = DataLoader(ImagesPathDataset(files), batch_size=batch, num_workers=min(4, 2 * os.cpu_count()))
    start = time.perf_counter()
    n = 0
    with torch.no_grad():
        for images in loader:
            extractor(images)
            n += images.shape[0]
    seconds = time.perf_counter() - start
    peak_mib = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    print(json.dumps(dict(images_per_s=n / seconds, seconds=seconds, peak_mib=peak_mib, torch=torch.__version__,
                          torch_fidelity=torch_fidelity.__version__, threads=torch.get_num_threads())))


if __name__ == "__main__":
    main()
