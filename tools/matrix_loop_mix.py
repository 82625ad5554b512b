#!/usr/bin/env python3
"""The inner loop of each matrix-unit kernel as a vendor's compiler emitted it.

Reads what Mesa's drivers print while `vkdiff devices --compile` compiles (on a GPU that
.ci/drm-shim fakes, or a real one):

    export MESA_SHADER_CACHE_DISABLE=true VKDIFF_GPU_PATHS=1    # every kernel compiled anew
    RADV_DEBUG=shaders vkdiff devices --compile --kernel gemm_coop > radv.txt 2>&1   # AMD: ACO's ISA
    NAK_DEBUG=print vkdiff devices --compile --kernel gemm_coop > nvk.txt 2>&1      # NVIDIA: NAK's IR

    python3 tools/matrix_loop_mix.py radv.txt   (or nvk.txt)

For every compiled shader holding matrix instructions (v_wmma, hmma), it prints the loops that
hold them (a backward branch's range, the innermost first) and counts their instructions by
class: matrix, shared-memory loads and stores, global loads, waits and barriers, vector and
scalar ALU. Static counts, not timings: one pass through the loop body as compiled.
No dependency beyond Python 3.
"""
import collections
import re
import sys


def aco_class(op):
    if op.startswith("v_wmma"):
        return "matrix"
    if op.startswith("ds_load") or op.startswith("ds_read"):
        return "shared load"
    if op.startswith("ds_store") or op.startswith("ds_write"):
        return "shared store"
    if op.startswith(("global_load", "buffer_load")):
        return "global load"
    if op.startswith(("global_store", "buffer_store")):
        return "global store"
    if op.startswith(("s_waitcnt", "s_barrier", "s_delay_alu", "s_nop", "s_clause")):
        return "wait, barrier, hint"
    if op.startswith("s_"):
        return "scalar ALU"
    if op.startswith("v_"):
        return "vector ALU"
    return "other"


def aco_shaders(text):
    """(instructions, loops) of each ACO disassembly that holds v_wmma."""
    for part in text.split("\ndisasm:\n")[1:]:
        lines = [l.split(";")[0].strip() for l in part.split("\n\n")[0].splitlines()]
        lines = [l for l in lines if l]
        if not any(l.startswith("v_wmma") for l in lines):
            continue
        labels = {l[:-1]: i for i, l in enumerate(lines) if re.fullmatch(r"BB\d+:", l)}
        loops = []
        for i, l in enumerate(lines):
            m = re.search(r"s_c?branch\w* (BB\d+)", l)
            if m and m.group(1) in labels and labels[m.group(1)] < i:
                body = [x.split()[0] for x in lines[labels[m.group(1)] : i + 1] if not x.endswith(":")]
                if any(op.startswith("v_wmma") for op in body):
                    loops.append(body)
        ops = [l.split()[0] for l in lines if not l.endswith(":")]
        yield ops, loops, aco_class


def nak_class(op):
    base = op.split(".")[0]
    if base == "hmma":
        return "matrix"
    if base == "ldsm" or op.startswith("ld.shared"):
        return "shared load"
    if op.startswith("st.shared"):
        return "shared store"
    if op.startswith("ld.global"):
        return "global load"
    if op.startswith("st.global"):
        return "global store"
    if base in ("bar", "membar", "nop", "bssy", "bsync", "bclear"):
        return "wait, barrier, hint"
    if base in ("mov", "prmt", "sel"):
        return "moves and selects"
    return "ALU"


def nak_shaders(text):
    """(instructions, loops) of each final NAK shader (after calc_instr_deps) that holds hmma."""
    for part in text.split("NAK IR after calc_instr_deps:")[1:]:
        blocks, preds, cur = {}, {}, None
        for l in part.split("\nStage:")[0].splitlines():
            m = re.match(r"\s*block(?:\.u)? (\d+) L\d+ \[([\d, ]*)\]", l)
            if m:
                cur = int(m.group(1))
                blocks[cur] = []
                preds[cur] = [int(x) for x in m.group(2).split(",") if x.strip()]
                continue
            s = l.split("//")[0].strip()
            if cur is None or not s or s.startswith("}"):
                continue
            s = re.sub(r"^@!?\w+\s+", "", s)
            if "=" in s:
                s = s.split("=", 1)[1].strip()
            blocks[cur].append(s.split()[0])
        ops = [op for b in sorted(blocks) for op in blocks[b]]
        if not any(op.startswith("hmma") for op in ops):
            continue
        loops = []
        for head, ps in preds.items():
            for tail in (p for p in ps if p >= head):
                # Blocks before the first matrix block that end in `exit` are the epilogue,
                # which NAK may place inside the loop's range.
                span = [b for b in range(head, tail + 1) if b in blocks]
                first = next(b for b in span if any(o.startswith("hmma") for o in blocks[b]))
                start = max([b + 1 for b in span if b < first and "exit" in blocks[b]], default=head)
                body = [o for b in span if b >= start for o in blocks[b]]
                if any(o.startswith("hmma") for o in body):
                    loops.append(body)
        yield ops, loops, nak_class


def main():
    if len(sys.argv) != 2:
        sys.exit(__doc__)
    text = open(sys.argv[1], errors="replace").read()
    shaders = list(aco_shaders(text)) or list(nak_shaders(text))
    if not shaders:
        sys.exit(f"{sys.argv[1]}: no shader with matrix instructions (RADV_DEBUG=shaders or NAK_DEBUG=print output?)")
    # The census's own lines name the variants in the order they were compiled.
    labels = re.findall(r"^  (\S+ F16 FM=\S+(?: \S+=\d+)*) [\d.]+ s", text, re.M)
    for n, (ops, loops, classify) in enumerate(shaders):
        label = labels[n] if len(labels) == len(shaders) else f"shader {n}"
        print(f"{label}: {len(ops)} instructions")
        for body in sorted(loops, key=len):
            mix = collections.Counter(classify(op) for op in body)
            each = ", ".join(f"{k} {v}" for k, v in mix.most_common())
            print(f"  loop of {len(body)}: {each}")


if __name__ == "__main__":
    main()
