#!/usr/bin/env python3
"""diffusers' UNet2DConditionModel on the CPU (torch, float32): milliseconds per evaluation and the
process's peak resident memory.

Run by `vkdiff bench unet` in the same run as its own measurement, with the same config (passed as
JSON), random weights, latent size and batch. Prints one JSON line.
Setup: pip install torch diffusers   (vkdiff runs it with $VKDIFF_REFERENCE_PYTHON, else python3)
Usage: unet_cpu_reference.py CONFIG_JSON LATENT_H LATENT_W BATCH SAMPLES
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
    h, w, batch, samples = (int(a) for a in sys.argv[2:6])
    torch.manual_seed(0)
    with torch.device("meta"):
        unet = UNet2DConditionModel(**config)
    # Random weights without the slow default initialisers of a 2.6 B-parameter model.
    unet = unet.to_empty(device="cpu").eval()
    with torch.no_grad():
        for p in unet.parameters():
            p.normal_(0.0, 0.02)
    text = config["projection_class_embeddings_input_dim"] - 6 * config["addition_time_embed_dim"]
    sample = torch.randn(batch, config["in_channels"], h, w)
    t = torch.full((batch,), 500.0)
    context = torch.randn(batch, 77, config["cross_attention_dim"])
    added = dict(text_embeds=torch.randn(batch, text), time_ids=torch.tensor([[8.0 * h, 8.0 * w, 0, 0, 8.0 * h, 8.0 * w]] * batch))
    times = []
    with torch.inference_mode():
        for _ in range(samples):
            start = time.perf_counter()
            unet(sample, t, encoder_hidden_states=context, added_cond_kwargs=added)
            times.append(time.perf_counter() - start)
    peak_mib = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024  # Linux reports KiB
    print(json.dumps(dict(ms=1000 * min(times), peak_mib=peak_mib, torch=torch.__version__, diffusers=diffusers.__version__,
                          threads=torch.get_num_threads())))


if __name__ == "__main__":
    main()
