#!/usr/bin/env python3
"""diffusers' UNet2DConditionModel on the CPU (torch, float32) or a CUDA GPU (float16 or float32):
milliseconds per evaluation (the best, and each) and the peak memory (the process's resident set on the CPU, torch's
allocated device memory on the GPU).

Run by `vkdiff bench unet` and `vkdiff bench report` in the same run as their own measurement, with the same config
(passed as JSON), random weights, latent size and batch. WARM_UP 1 makes one untimed evaluation first, on every
device, where vkdiff made one on its side (0: none, as on vkdiff's). Prints one JSON line.
Setup: pip install torch diffusers   (vkdiff runs it with $VKDIFF_REFERENCE_PYTHON, else python3)
Usage: unet_reference.py CONFIG_JSON LATENT_H LATENT_W BATCH SAMPLES WARM_UP [cpu | cuda f16 | cuda f32]
"""
import json
import resource
import sys
import time

import diffusers
import torch
from diffusers import UNet2DConditionModel


def main():
    config = json.loads(sys.argv[1])
    h, w, batch, samples, warm_up = (int(a) for a in sys.argv[2:7])
    device = sys.argv[7] if len(sys.argv) > 7 else "cpu"
    dtype = torch.float16 if device == "cuda" and sys.argv[8:9] == ["f16"] else torch.float32
    torch.manual_seed(0)
    with torch.device("meta"):
        unet = UNet2DConditionModel(**config)
    # Random weights without the slow default initialisers of a 2.6 B-parameter model.
    unet = unet.to_empty(device=device).to(dtype).eval()
    with torch.no_grad():
        for p in unet.parameters():
            p.normal_(0.0, 0.02)
    text = config["projection_class_embeddings_input_dim"] - 6 * config["addition_time_embed_dim"]
    make = dict(device=device, dtype=dtype)
    sample = torch.randn(batch, config["in_channels"], h, w, **make)
    t = torch.full((batch,), 500.0, device=device)
    context = torch.randn(batch, 77, config["cross_attention_dim"], **make)
    time_ids = torch.tensor([[8.0 * h, 8.0 * w, 0, 0, 8.0 * h, 8.0 * w]] * batch, **make)
    added = dict(text_embeds=torch.randn(batch, text, **make), time_ids=time_ids)
    sync = torch.cuda.synchronize if device == "cuda" else (lambda: None)
    times = []
    with torch.inference_mode():
        if warm_up:  # the first call picks kernels and grows the allocator
            unet(sample, t, encoder_hidden_states=context, added_cond_kwargs=added)
        for _ in range(samples):
            sync()
            start = time.perf_counter()
            unet(sample, t, encoder_hidden_states=context, added_cond_kwargs=added)
            sync()
            times.append(time.perf_counter() - start)
    if device == "cuda":
        peak_mib = torch.cuda.max_memory_allocated() / 2**20
        where = f"{torch.cuda.get_device_name()} {str(dtype).removeprefix('torch.')}"
    else:
        peak_mib = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024  # Linux reports KiB
        where = f"CPU float32, {torch.get_num_threads()} threads"
    print(json.dumps(dict(ms=1000 * min(times), times_ms=[1000 * t for t in times], peak_mib=peak_mib,
                          torch=torch.__version__,
                          diffusers=diffusers.__version__, where=where)))


if __name__ == "__main__":
    main()
