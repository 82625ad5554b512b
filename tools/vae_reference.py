#!/usr/bin/env python3
"""diffusers' AutoencoderKL decoder (SDXL's VAE config, random weights) on the CPU or a CUDA GPU, at its best
(tools/reference_timing.py): seconds per whole decode (the best, each by wall-clock and on CUDA by CUDA events, at
least 10) and the peak memory, then the same through torch.compile (`compiled`).

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

import diffusers
import torch
from diffusers import AutoencoderKL

import reference_timing as rt


def decodes(vae, latents, samples, device):
    """Each decode's wall-clock and GPU seconds, after one untimed (it picks kernels and grows the
    allocator)."""
    with torch.inference_mode():
        return rt.timed(lambda: vae.decode(latents), samples, 1, device)


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
    result["settings"] = rt.best_settings(device)
    vae = rt.at_best(vae, result["settings"])
    result["host"] = rt.host(device)
    result["clocks"] = [rt.gpu_clocks()] if device == "cuda" else None
    torch.backends.cuda.matmul.allow_tf32 = False  # torch's default, kept for every timing
    torch.backends.cudnn.allow_tf32 = False
    timed = decodes(vae, latents, samples, device)
    result.update(times=timed["wall"], gpu=timed["gpu"], seconds=min(timed["wall"]))
    if device == "cuda":
        result["peak_mib"] = torch.cuda.max_memory_allocated() / 2**20
    if device == "cuda" and dtype == torch.float32:
        torch.backends.cudnn.allow_tf32 = True  # torch's default
        result["times_tf32"] = decodes(vae, latents, samples, device)["wall"]
        result["seconds_tf32"] = min(result["times_tf32"])
        torch.backends.cudnn.allow_tf32 = False
    with torch.inference_mode():
        result["sdpa"] = rt.sdpa_backend(lambda: vae.decode(latents))
        result["compiled"] = rt.time_compiled(vae.decode, lambda decode: lambda: decode(latents), samples, device)
    if device == "cuda":
        result["clocks"].append(rt.gpu_clocks())
    name = str(dtype).removeprefix("torch.")
    if device == "cuda":
        result["where"] = f"{torch.cuda.get_device_name()} {name}"
    else:
        result["peak_mib"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024  # KiB on Linux
        result["where"] = f"CPU {name}, {torch.get_num_threads()} threads"
    print(json.dumps(result))


if __name__ == "__main__":
    main()
