#!/usr/bin/env python3
"""torch's own kernels at the shapes of `vkdiff bench report`'s headline products, on the CPU
(float32) or a CUDA GPU (float16 or float32): a 2048x1280x5120 linear layer (the UNet's 32x32
level's feed-forward output at 1024²), the 64x64 level's 3x3 convolution (640 channels in and
out) and self-attention over its 4096 tokens in 10 heads of 64 (scaled_dot_product_attention:
FlashAttention on CUDA; the backend torch ran is printed). TFLOP/s of each timed run (at least
10) after a warm-up, by wall-clock as vkdiff times its own rows, with the CUDA events' rates
beside on CUDA; the convolution in channels_last with cuDNN's
autotuner (tools/reference_timing.py). Single products gain nothing from torch.compile, so no
compiled rates are printed. Prints one JSON line.

Run by `vkdiff bench report` in the same invocation as its own kernels.
Setup: pip install torch   (vkdiff runs it with $VKDIFF_REFERENCE_PYTHON, else python3)
Usage: kernels_reference.py RUNS [cpu | cuda f16 | cuda f32]
"""
import json
import statistics
import sys
import time

import torch
import torch.nn.functional as F

import reference_timing as rt


def timed(fn, flops, runs, device):
    """TFLOP/s of each run of about half a second of repeated calls, by wall-clock as vkdiff times
    its kernel rows (a submission's whole run), and on CUDA by CUDA events beside (or None)."""
    sync = torch.cuda.synchronize if device == "cuda" else (lambda: None)
    fn()  # the first call picks kernels
    sync()
    start = time.perf_counter()
    fn()
    sync()
    once = time.perf_counter() - start
    reps = max(1, min(200, int(0.5 / max(once, 1e-6))))

    def repeated():
        for _ in range(reps):
            fn()

    samples = rt.timed(repeated, runs, 0, device)

    def rates(seconds):
        return [flops * reps / s / 1e12 for s in seconds] if seconds else None

    return rates(samples["wall"]), rates(samples["gpu"])


def main():
    runs = int(sys.argv[1])
    device = sys.argv[2] if len(sys.argv) > 2 else "cpu"
    dtype = torch.float16 if device == "cuda" and sys.argv[3:4] == ["f16"] else torch.float32
    make = dict(device=device, dtype=dtype)
    torch.manual_seed(0)
    settings = rt.best_settings(device)
    x, w = torch.randn(2048, 5120, **make), torch.randn(1280, 5120, **make)
    image, kernel = (t.to(memory_format=torch.channels_last) for t in
                     (torch.randn(1, 640, 64, 64, **make), torch.randn(640, 640, 3, 3, **make)))
    settings.append("channels_last")
    q, k, v = (torch.randn(1, 10, 4096, 64, **make) for _ in range(3))
    with torch.inference_mode():
        both = {
            "linear": timed(lambda: F.linear(x, w), 2.0 * 2048 * 1280 * 5120, runs, device),
            "conv": timed(lambda: F.conv2d(image, kernel, padding=1), 2.0 * 4096 * 640 * 9 * 640, runs, device),
            "attention": timed(lambda: F.scaled_dot_product_attention(q, k, v), 4.0 * 4096 * 4096 * 640, runs, device),
        }
        result = {name: wall for name, (wall, _) in both.items()}
        result["sdpa"] = rt.sdpa_backend(lambda: F.scaled_dot_product_attention(q, k, v))
    name = str(dtype).removeprefix("torch.")
    where = f"{torch.cuda.get_device_name()} {name}" if device == "cuda" else f"CPU {name}, {torch.get_num_threads()} threads"
    timing = "wall-clock"
    if device == "cuda":
        events = ", ".join(f"{name} {statistics.median(gpu):.1f}" for name, (_, gpu) in both.items())
        timing += f" (by CUDA events, median TFLOP/s: {events})"
    result.update(torch=torch.__version__, where=where, settings=settings + [timing], host=rt.host(device),
                  clocks=[rt.gpu_clocks()] if device == "cuda" else None)
    print(json.dumps(result))


if __name__ == "__main__":
    main()
