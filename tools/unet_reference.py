#!/usr/bin/env python3
"""diffusers' UNet2DConditionModel on the CPU (torch, float32) or a CUDA GPU (float16 or float32), at its best
(tools/reference_timing.py: cuDNN's autotuner, channels_last, fused QKV): milliseconds per evaluation (the best, each
by wall-clock and on CUDA by CUDA events, at least 10), the peak memory (the process's resident set on the CPU, torch's
allocated device memory on the GPU), then the same through torch.compile (`compiled`, seconds).

Run by `vkdiff bench unet` and `vkdiff bench report` in the same run as their own measurement, with the same config
(passed as JSON), random weights, latent size and batch. WARM_UP 1 makes one untimed evaluation first, on every
device, where vkdiff made one on its side (0: none, as on vkdiff's). Prints one JSON line.
Setup: pip install torch diffusers   (vkdiff runs it with $VKDIFF_REFERENCE_PYTHON, else python3)
Usage: unet_reference.py CONFIG_JSON LATENT_H LATENT_W BATCH SAMPLES WARM_UP [cpu | cuda f16 | cuda f32]
"""
import json
import resource
import sys

import diffusers
import torch
from diffusers import UNet2DConditionModel

import reference_timing as rt


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
    settings = rt.best_settings(device)
    unet = rt.at_best(unet, settings)
    sample = sample.to(memory_format=torch.channels_last)
    host = rt.host(device)
    clocks = [rt.gpu_clocks()] if device == "cuda" else None

    def evaluation(model):
        return lambda: model(sample, t, encoder_hidden_states=context, added_cond_kwargs=added)

    with torch.inference_mode():
        # The first call picks kernels and grows the allocator: untimed only where vkdiff's side had one.
        times = rt.timed(evaluation(unet), samples, warm_up, device)
        peak = torch.cuda.max_memory_allocated() / 2**20 if device == "cuda" else None
        sdpa = rt.sdpa_backend(evaluation(unet))
        compiled = rt.time_compiled(unet, evaluation, samples, device)
    if clocks:
        clocks.append(rt.gpu_clocks())
    if device == "cuda":
        peak_mib = peak
        where = f"{torch.cuda.get_device_name()} {str(dtype).removeprefix('torch.')}"
    else:
        peak_mib = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024  # Linux reports KiB
        where = f"CPU float32, {torch.get_num_threads()} threads"
    wall = times["wall"]
    print(json.dumps(dict(ms=1000 * min(wall), times_ms=[1000 * t for t in wall], gpu=times["gpu"], peak_mib=peak_mib,
                          torch=torch.__version__, diffusers=diffusers.__version__, where=where,
                          settings=settings, sdpa=sdpa, host=host, clocks=clocks, compiled=compiled)))


if __name__ == "__main__":
    main()
