#!/usr/bin/env python3
"""diffusers' AutoencoderKL decoder (SDXL's VAE config, random weights) on the CPU or a CUDA GPU:
seconds per whole decode (the best, and each) and the peak memory.

Run by `vkdiff bench vae --reference-device` in the same run as its own measurement, with the
same config (passed as JSON), image size and precision: float32 (SDXL's VAE) or float16 (the
fp16-fix VAE's config). `seconds` is the decode in the precision's own arithmetic; for float32 on
CUDA, `seconds_tf32` is the decode with torch's default, which lets cuDNN run float32
convolutions on TF32 tensor cores. Prints one JSON line.
Setup: pip install torch diffusers   (vkdiff runs it with $VKDIFF_REFERENCE_PYTHON, else python3)
Usage: vae_reference.py CONFIG_JSON SIZE SAMPLES [cpu | cuda] [f32 | f16]
"""
import json
import resource
import sys
import time

import diffusers
import torch
from diffusers import AutoencoderKL


def decodes(vae, latents, samples, sync):
    times = []
    with torch.inference_mode():
        vae.decode(latents)  # the first call picks kernels and grows the allocator
        for _ in range(samples):
            sync()
            start = time.perf_counter()
            vae.decode(latents)
            sync()
            times.append(time.perf_counter() - start)
    return times


def main():
    config = json.loads(sys.argv[1])
    size, samples = int(sys.argv[2]), int(sys.argv[3])
    device = sys.argv[4] if len(sys.argv) > 4 else "cpu"
    dtype = torch.float16 if sys.argv[5:6] == ["f16"] else torch.float32
    torch.manual_seed(0)
    with torch.device("meta"):
        vae = AutoencoderKL(**config)
    vae = vae.to_empty(device=device).to(dtype).eval()
    with torch.no_grad():
        for p in vae.parameters():
            p.normal_(0.0, 0.02)
    factor = 2 ** (len(config["block_out_channels"]) - 1)
    latents = torch.randn(1, config["latent_channels"], size // factor, size // factor, device=device, dtype=dtype)
    result = dict(torch=torch.__version__, diffusers=diffusers.__version__)
    sync = torch.cuda.synchronize if device == "cuda" else (lambda: None)
    torch.backends.cuda.matmul.allow_tf32 = False  # torch's default, kept for every timing
    torch.backends.cudnn.allow_tf32 = False
    result["times"] = decodes(vae, latents, samples, sync)
    result["seconds"] = min(result["times"])
    if device == "cuda" and dtype == torch.float32:
        torch.backends.cudnn.allow_tf32 = True  # torch's default
        result["times_tf32"] = decodes(vae, latents, samples, sync)
        result["seconds_tf32"] = min(result["times_tf32"])
    name = str(dtype).removeprefix("torch.")
    if device == "cuda":
        result["peak_mib"] = torch.cuda.max_memory_allocated() / 2**20
        result["where"] = f"{torch.cuda.get_device_name()} {name}"
    else:
        result["peak_mib"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024  # KiB on Linux
        result["where"] = f"CPU {name}, {torch.get_num_threads()} threads"
    print(json.dumps(result))


if __name__ == "__main__":
    main()
