"""stable-diffusion.cpp's Vulkan build (ggml-vulkan, through the `cyllama-vulkan` wheel) timing
SDXL text-to-image on the same Vulkan device as vkdiff, from the single file vkdiff wrote
(`vkdiff_networks::write_random_single_file`: random weights in the original layout, which
sd.cpp detects as SDXL). `vkdiff bench report` runs it after releasing the device.

    python tools/sdcpp_reference.py MODEL.safetensors SIZE STEPS

Prints one JSON object: load_s (the model onto the device), steps (seconds of each sampling
step, as sd.cpp's own progress line gives them; vkdiff takes their median after the first, its
one step rule), total_s, and what ran. `GGML_VK_VISIBLE_DEVICES` picks
the device (0 where unset, which also lets ggml take a CPU device such as lavapipe).

Last run with: cyllama-vulkan 0.2.18, Python 3.11, on Mesa 22.3's lavapipe (2026-12-01): loaded in
4 s and 43 s a 64² step in the runs that finished; most ended in a segmentation fault inside
its sampler (with or without a Python progress callback, which is why none is used).
"""

import json
import os
import re
import sys
import tempfile
import time

os.environ.setdefault("GGML_VK_VISIBLE_DEVICES", "0")


def main():
    model, size, steps = sys.argv[1], int(sys.argv[2]), int(sys.argv[3])
    import importlib.metadata

    import cyllama.sd as sd

    params = sd.SDContextParams()
    params.model_path = model
    params.n_threads = os.cpu_count() or 1
    # sd.cpp prints its progress ("2/30 - 1.25s/it", each step's own time) on the process's
    # standard output, where the JSON below must stand alone: it goes to a file instead.
    log = tempfile.TemporaryFile(mode="w+b")
    saved = os.dup(1)
    os.dup2(log.fileno(), 1)
    try:
        start = time.perf_counter()
        ctx = sd.SDContext(params)
        load_s = time.perf_counter() - start
        gen = sd.SDImageGenParams()
        gen.prompt = "white button mushrooms on brown compost, top-down photo"
        gen.width = gen.height = size
        gen.seed = 0
        gen.sample_params.sample_steps = steps
        gen.sample_params.sample_method = sd.SampleMethod.EULER
        gen.sample_params.cfg_scale = 5.0
        start = time.perf_counter()
        ctx.generate_with_params(gen)
        total_s = time.perf_counter() - start
    finally:
        sys.stdout.flush()
        os.dup2(saved, 1)
    log.seek(0)
    printed = log.read().decode(errors="replace")
    steps_s = {}
    for done, total, value, unit in re.findall(r"(\d+)/(\d+) - ([\d.]+)(s/it|it/s)", printed):
        if int(total) == steps:
            steps_s[int(done)] = float(value) if unit == "s/it" else 1 / float(value)
    what = f"stable-diffusion.cpp (cyllama-vulkan {importlib.metadata.version('cyllama-vulkan')}, ggml-vulkan), f16 weights"
    print(json.dumps({"load_s": load_s, "steps": [steps_s[k] for k in sorted(steps_s)], "total_s": total_s,
                      "what": what}))


if __name__ == "__main__":
    main()
