#!/usr/bin/env python3
"""diffusers' AutoencoderKL decoder (SDXL's VAE config, random weights, float32 as its
force_upcast asks) on the CPU or a CUDA GPU: seconds per whole decode and the peak memory.

Run by `vkdiff bench vae --reference-device` in the same run as its own measurement, with the
same config (passed as JSON) and image size: float32 arithmetic throughout, as vkdiff's VAE
computes (seconds_f32), and on CUDA also with torch's default, which lets cuDNN run float32
convolutions on TF32 tensor cores (seconds_tf32). Prints one JSON line.
Setup: pip install torch diffusers   (vkdiff runs it with $VKDIFF_REFERENCE_PYTHON, else python3)
Usage: vae_reference.py CONFIG_JSON SIZE SAMPLES [cpu | cuda]
"""
import json
import resource
import sys
import time

import diffusers
import torch
from diffusers import AutoencoderKL


def best_decode(vae, latents, samples, sync):
    times = []
    with torch.inference_mode():
        vae.decode(latents)  # the first call picks kernels and grows the allocator
        for _ in range(samples):
            sync()
            start = time.perf_counter()
            vae.decode(latents)
            sync()
            times.append(time.perf_counter() - start)
    return min(times)


def main():
    config = json.loads(sys.argv[1])
    size, samples = int(sys.argv[2]), int(sys.argv[3])
    device = sys.argv[4] if len(sys.argv) > 4 else "cpu"
    torch.manual_seed(0)
    with torch.device("meta"):
        vae = AutoencoderKL(**config)
    vae = vae.to_empty(device=device).float().eval()
    with torch.no_grad():
        for p in vae.parameters():
            p.normal_(0.0, 0.02)
    factor = 2 ** (len(config["block_out_channels"]) - 1)
    latents = torch.randn(1, config["latent_channels"], size // factor, size // factor, device=device)
    result = dict(torch=torch.__version__, diffusers=diffusers.__version__)
    torch.backends.cuda.matmul.allow_tf32 = False  # torch's default, kept for both timings
    if device == "cuda":
        sync = torch.cuda.synchronize
        torch.backends.cudnn.allow_tf32 = False
        result["seconds_f32"] = best_decode(vae, latents, samples, sync)
        torch.backends.cudnn.allow_tf32 = True  # torch's default
        result["seconds_tf32"] = best_decode(vae, latents, samples, sync)
        result["peak_mib"] = torch.cuda.max_memory_allocated() / 2**20
        result["where"] = f"{torch.cuda.get_device_name()} float32"
    else:
        result["seconds_f32"] = best_decode(vae, latents, samples, lambda: None)
        result["peak_mib"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024  # KiB on Linux
        result["where"] = f"CPU float32, {torch.get_num_threads()} threads"
    print(json.dumps(result))


if __name__ == "__main__":
    main()
