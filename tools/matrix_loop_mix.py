#!/usr/bin/env python3
"""The inner loop of each matrix-unit kernel as a vendor's compiler emitted it.

Reads what Mesa's drivers print while `vkdiff devices --compile` compiles (on a GPU that
.ci/drm-shim fakes, or a real one):

    export MESA_SHADER_CACHE_DISABLE=true VKDIFF_GPU_PATHS=1    # every kernel compiled anew
    RADV_DEBUG=shaders vkdiff devices --compile --kernel gemm_coop > radv.txt 2>&1   # AMD: ACO's ISA
    NAK_DEBUG=print vkdiff devices --compile --kernel gemm_coop > nvk.txt 2>&1      # NVIDIA: NAK's IR

    python3 tools/matrix_loop_mix.py radv.txt   (or nvk.txt)

For every compiled shader holding matrix instructions (v_wmma, hmma), it prints the loops that
hold them (a backward branch's range, the innermost first): all their instructions, and those of
one pass, the shortest path through the loop's blocks, which skips the branches a pass rarely
takes (the stores of a last, partial K-step; attention's masked chunks and rescaling). It
counts that pass by class: matrix, shared-memory loads and stores, global loads, waits and
barriers, vector and scalar ALU (NAK: ALU, moves and selects). Static counts, not timings.
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


def passes(blocks, succs, loops):
    """For each loop (head, tail), its instructions and those of its shortest pass."""
    out = []
    for head, tail in loops:
        # The loop's blocks: on a path from its head to its tail (not an exit placed inside).
        ahead, behind = {head}, {tail}
        for b in sorted(blocks):
            if b in ahead:
                ahead.update(s for s in succs.get(b, []) if b < s <= tail)
        for b in sorted(blocks, reverse=True):
            if any(s in behind for s in succs.get(b, []) if b < s <= tail):
                behind.add(b)
        body = [op for b in sorted(ahead & behind) for op in blocks[b]]
        if not any(o.startswith(("v_wmma", "hmma")) for o in body):
            continue
        best = {head: [blocks[head]]}
        for b in sorted(blocks):
            if b < head or b > tail or b not in best:
                continue
            for s in succs.get(b, []):
                if b < s <= tail:
                    path = best[b] + [blocks[s]]
                    if s not in best or sum(map(len, path)) < sum(map(len, best[s])):
                        best[s] = path
        one = [op for blk in best.get(tail, [body]) for op in blk]
        out.append((body, one))
    return out


def aco_shaders(text):
    """(instructions, loops) of each ACO disassembly that holds v_wmma: each loop as its whole
    body and its shortest pass."""
    for part in text.split("\ndisasm:\n")[1:]:
        lines = [l.split(";")[0].strip() for l in part.split("\n\n")[0].splitlines()]
        lines = [l for l in lines if l]
        if not any(l.startswith("v_wmma") for l in lines):
            continue
        # Basic blocks in layout order: a label starts one, a branch ends one.
        blocks, names = {0: []}, {}
        for l in lines:
            if re.fullmatch(r"BB\d+:", l):
                if blocks[len(blocks) - 1]:
                    blocks[len(blocks)] = []
                names[l[:-1]] = len(blocks) - 1
                continue
            blocks[len(blocks) - 1].append(l)
            if l.startswith(("s_branch", "s_cbranch", "s_endpgm")):
                blocks[len(blocks)] = []
        succs, loops = {}, []
        for b, body in blocks.items():
            last = body[-1] if body else ""
            target = re.search(r"s_c?branch\w* (BB\d+)", last)
            succs[b] = [] if last.startswith(("s_endpgm", "s_branch")) else [b + 1]
            if target and target.group(1) in names:
                succs[b].append(names[target.group(1)])
                if names[target.group(1)] <= b:
                    loops.append((names[target.group(1)], b))
        blocks = {b: [l.split()[0] for l in body] for b, body in blocks.items()}
        ops = [op for b in sorted(blocks) for op in blocks[b]]
        yield ops, passes(blocks, succs, loops), aco_class


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
    """(instructions, loops) of each final NAK shader (after calc_instr_deps) that holds hmma:
    each loop as its whole body and its shortest pass."""
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
        succs = {}
        for b, ps in preds.items():
            for p in ps:
                succs.setdefault(p, []).append(b)
        loops = [(head, tail) for head, ps in preds.items() for tail in ps if tail >= head]
        yield ops, passes(blocks, succs, loops), nak_class


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
        for body, one in sorted(loops, key=lambda loop: len(loop[0])):
            mix = collections.Counter(classify(op) for op in one)
            each = ", ".join(f"{k} {v}" for k, v in mix.most_common())
            print(f"  loop of {len(body)}, one pass {len(one)}: {each}")


if __name__ == "__main__":
    main()
