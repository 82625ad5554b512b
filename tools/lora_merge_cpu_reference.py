#!/usr/bin/env python3
"""CPU reference for `vkdiff bench lora`: the work of peft's merge (what diffusers' fuse_lora runs),
W += scale * (B @ A), for every module, in torch float32 on this machine's CPU.

Reads JSON on stdin: {"rank": r, "shapes": [[out, in], ...]}; prints one JSON line with the
seconds of the merge loop (factors and weights are created before timing starts).
Used with torch 2.15.0 (CPU). Run by hand:
  echo '{"rank": 32, "shapes": [[640, 640]]}' | python3 tools/lora_merge_cpu_reference.py
"""
import json
import sys
import time

import torch

job = json.load(sys.stdin)
r = job["rank"]
g = torch.Generator().manual_seed(0)
modules = [
    (torch.randn(o, i, generator=g), torch.randn(r, i, generator=g) * 0.01, torch.randn(o, r, generator=g) * 0.01)
    for o, i in job["shapes"]
]
start = time.perf_counter()
with torch.no_grad():
    for w, a, b in modules:
        w.add_(b @ a, alpha=0.8 * 16 / r)
seconds = time.perf_counter() - start
print(json.dumps({"merge_s": seconds, "modules": len(modules), "torch": torch.__version__, "threads": torch.get_num_threads()}))
