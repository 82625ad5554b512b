#!/usr/bin/env python3
"""How much arithmetic hides each device load of a kernel's main loop, as AMD's compiler built it.

Reads what RADV prints while `vkdiff devices --compile` compiles (on a GPU that .ci/drm-shim
fakes, or a real one):

    export MESA_SHADER_CACHE_DISABLE=true VKDIFF_GPU_PATHS=1    # every kernel compiled anew
    RADV_DEBUG=shaders vkdiff devices --compile --kernel gemm_tiled_v4 > radv.txt 2>&1
    python3 tools/load_cover.py radv.txt

For every compiled shader, it takes the largest loop that loads from device memory (buffer_load,
global_load) and follows each load around the loop, as the next iterations would run it, to the
first `s_waitcnt vmcnt(c)` that it must pass (loads complete in order, so one with L loads issued
after it is done once c <= L). It counts the multiply-adds (v_fma*, v_dual_fmac, v_pk_fma, and
v_wmma on the matrix units) issued in between: the work that the load's latency can hide behind.
A kernel that prefetches the next step's operands should show most of a step's multiply-adds;
0 means each load is waited for before any arithmetic. Static counts, not timings.
No dependency beyond Python 3.
"""
import re
import sys

LOADS = ("buffer_load", "global_load")
WORK = ("v_fma", "v_dual_fmac", "v_dual_fma", "v_pk_fma", "v_wmma")


def loops(lines):
    """Bodies of the loops in one disassembly (a backward branch's range), labels dropped."""
    labels = {l[:-1]: i for i, l in enumerate(lines) if re.fullmatch(r"BB\d+:", l)}
    for i, l in enumerate(lines):
        m = re.search(r"s_c?branch\w* (BB\d+)", l)
        if m and m.group(1) in labels and labels[m.group(1)] < i:
            yield [x for x in lines[labels[m.group(1)] : i + 1] if not x.endswith(":")]


def cover(body, at):
    """Multiply-adds between the load at `at` and the first wait it must pass, going round."""
    later, work = 0, 0
    for step in range(1, len(body) + 1):
        op = body[(at + step) % len(body)]
        wait = re.search(r"vmcnt\((\d+)\)", op) if op.startswith("s_waitcnt") else None
        if wait and int(wait.group(1)) <= later:
            return work
        later += op.startswith(LOADS)
        work += op.startswith(WORK)
    return work


def main():
    if len(sys.argv) != 2:
        sys.exit(__doc__)
    text = open(sys.argv[1], errors="replace").read()
    parts = text.split("\ndisasm:\n")[1:]
    if not parts:
        sys.exit(f"{sys.argv[1]}: no disassembly (RADV_DEBUG=shaders output?)")
    # The census's own lines name the variants in the order they were compiled.
    labels = re.findall(r"^  (\S+ F(?:16|32)(?: \S+=\d+)*) [\d.]+ s", text, re.M)
    for n, part in enumerate(parts):
        lines = [l.split(";")[0].strip() for l in part.split("\n\n")[0].splitlines()]
        lines = [l for l in lines if l]
        loading = [b for b in loops(lines) if any(op.startswith(LOADS) for op in b)]
        if not loading:
            continue
        body = max(loading, key=len)
        loads = [i for i, op in enumerate(body) if op.startswith(LOADS)]
        covers = [cover(body, i) for i in loads]
        work = sum(op.startswith(WORK) for op in body)
        label = labels[n] if len(labels) == len(parts) else f"shader {n}"
        print(f"{label}: loop of {len(body)}, {work} multiply-adds, {len(loads)} loads; "
              f"multiply-adds before a load is waited for: {min(covers)}–{max(covers)}")


if __name__ == "__main__":
    main()
