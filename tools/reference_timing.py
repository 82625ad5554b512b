"""What every timed PyTorch reference of `vkdiff bench` shares, so that each runs at its best and is
timed the same way: cuDNN's autotuner, channels_last and fused QKV projections; CUDA events beside
wall-clock; the SDPA backend torch picked; the host's CPU, load, threads, BLAS and GPU clocks; and
the same model again through torch.compile (CUDA graphs where compiling fails).

vkdiff carries this file in its binary beside each script (`import reference_timing` works either
way); run by hand, the scripts find it in tools/.
"""
import os
import re
import subprocess
import time

import torch

MIN_SAMPLES = 10


def best_settings(device):
    """Backend switches torch leaves off by default that make the reference faster."""
    if device == "cuda":
        torch.backends.cudnn.benchmark = True  # cuDNN tries its convolution algorithms once per shape
    return ["cudnn.benchmark"] if device == "cuda" else []


def at_best(model, settings, fuse=True):
    """The model in channels_last with its attention projections fused, where diffusers can
    (`fuse` False: a model whose attention processors must stay, as an IP-Adapter's)."""
    model = model.to(memory_format=torch.channels_last)
    if "channels_last" not in settings:
        settings.append("channels_last")
    if fuse and hasattr(model, "fuse_qkv_projections"):
        model.fuse_qkv_projections()
        label = f"fused QKV ({type(model).__name__})"
        settings.append(label)
    return model


def sdpa_backend(call):
    """The scaled_dot_product_attention implementation one call of `call` ran, by its aten op."""
    from torch.profiler import ProfilerActivity, profile

    with profile(activities=[ProfilerActivity.CPU]) as prof:
        call()
    names = {e.key for e in prof.key_averages()}
    for op, backend in [
        ("_scaled_dot_product_cudnn_attention", "cuDNN"),
        ("_scaled_dot_product_flash_attention_for_cpu", "flash (CPU)"),
        ("_scaled_dot_product_flash_attention", "FlashAttention"),
        ("_scaled_dot_product_efficient_attention", "memory-efficient"),
        ("_scaled_dot_product_attention_math", "math"),
    ]:
        if f"aten::{op}" in names:
            return backend
    return "none ran"


def timed(call, samples, warm_up, device):
    """Each sample's wall-clock seconds, and on CUDA its GPU seconds by CUDA events; `warm_up`
    untimed calls first. At least MIN_SAMPLES samples."""
    samples = max(samples, MIN_SAMPLES)
    cuda = device == "cuda"
    for _ in range(warm_up):
        call()
    wall, gpu = [], []
    for _ in range(samples):
        if cuda:
            torch.cuda.synchronize()
            begin, end = torch.cuda.Event(enable_timing=True), torch.cuda.Event(enable_timing=True)
            begin.record()
        start = time.perf_counter()
        call()
        if cuda:
            end.record()
            torch.cuda.synchronize()
            gpu.append(begin.elapsed_time(end) / 1e3)
        wall.append(time.perf_counter() - start)
    return dict(wall=wall, gpu=gpu or None)


def compiled(model, device):
    """The model through torch.compile (with CUDA graphs on CUDA: `reduce-overhead`), and how."""
    mode = "reduce-overhead" if device == "cuda" else "default"
    return torch.compile(model, mode=mode, fullgraph=True), f"torch.compile({mode}, fullgraph)"


def cuda_graphed(call):
    """`call` captured once into a CUDA graph and replayed: the fallback where compiling fails."""
    stream = torch.cuda.Stream()
    stream.wait_stream(torch.cuda.current_stream())
    with torch.cuda.stream(stream):
        for _ in range(2):
            call()
    torch.cuda.current_stream().wait_stream(stream)
    graph = torch.cuda.CUDAGraph()
    with torch.cuda.graph(graph):
        call()
    return graph.replay


def time_compiled(model, make_call, samples, device):
    """Timings of the compiled model (compiling in its warm-up calls), or of its CUDA graph where
    compiling fails; `why` says what ran or why nothing did."""
    try:
        fast, how = compiled(model, device)
        call = make_call(fast)
        return dict(timed(call, samples, 3, device), how=how)
    except Exception as e:  # noqa: BLE001 — any compiler failure falls back, and is named
        failure = f"torch.compile failed: {type(e).__name__}: {str(e).splitlines()[0][:160] if str(e) else ''}"
    if device != "cuda":
        return dict(wall=None, gpu=None, how=failure)
    try:
        call = cuda_graphed(make_call(model))
        return dict(timed(call, samples, 1, device), how=f"CUDA graph ({failure})")
    except Exception as e:  # noqa: BLE001
        return dict(wall=None, gpu=None, how=f"{failure}; CUDA graph failed: {type(e).__name__}")


def gpu_clocks():
    """SM and memory clocks (MHz), temperature and power of the GPU torch uses, by nvidia-smi."""
    index = torch.cuda.current_device()
    fields = "clocks.sm,clocks.mem,temperature.gpu,power.draw"
    try:
        out = subprocess.run(
            ["nvidia-smi", f"--query-gpu={fields}", "--format=csv,noheader,nounits", f"--id={index}"],
            capture_output=True, text=True, timeout=20, check=True,
        ).stdout.strip()
        sm, mem, temp, power = (v.strip() for v in out.split(","))
        return f"SM {sm} MHz, memory {mem} MHz, {temp} °C, {power} W"
    except (OSError, subprocess.SubprocessError, ValueError):
        return "unknown (nvidia-smi not runnable)"


def host(device):
    """The machine as a row needs it: CPU model, load average, torch's threads and BLAS."""
    model = "unknown CPU"
    try:
        with open("/proc/cpuinfo") as f:
            model = next((l.split(":", 1)[1].strip() for l in f if l.startswith("model name")), model)
    except OSError:
        pass
    load = "%.2f" % os.getloadavg()[0] if hasattr(os, "getloadavg") else "unknown"
    found = re.search(r"\bBLAS_INFO=([^,\s]+)", torch.__config__.show())
    blas = found.group(1) if found else "unknown"
    text = f"{model}, load {load}, torch {torch.get_num_threads()} threads, BLAS {blas}"
    if torch.backends.mkldnn.is_available():
        text += ", oneDNN"
    return text

