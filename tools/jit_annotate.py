#!/usr/bin/env python3
"""Reads what tools/jit-profile.sh left in DIR: the sampled instruction pointers and llvmpipe's
machine code. Prints the share of samples by instruction, then for the hottest stretch of code
(the loop the samples crowd into) its static mix: multiplies, adds and fused multiply-adds, loads
folded from the stack, and stores to the stack (spills) per product.
Usage: jit_annotate.py DIR [LINES]
"""
import collections
import glob
import re
import subprocess
import sys


def code(directory):
    """Every instruction of the dumped mappings, by address."""
    insns = {}
    for path in glob.glob(f"{directory}/jit_*.bin"):
        base = int(re.search(r"jit_([0-9a-f]+)\.bin", path).group(1), 16)
        out = subprocess.run(["objdump", "-D", "-b", "binary", "-mi386:x86-64", f"--adjust-vma={base:#x}",
                              "--no-show-raw-insn", path], capture_output=True, text=True, check=True).stdout
        for line in out.splitlines():
            m = re.match(r"\s*([0-9a-f]+):\s+(.*)", line)
            if m:
                insns[int(m.group(1), 16)] = m.group(2).strip()
    return insns


def main():
    directory = sys.argv[1]
    span = int(sys.argv[2]) if len(sys.argv) > 2 else 400
    samples = collections.Counter()
    for line in open(f"{directory}/ips"):
        count, ip = line.split()
        samples[int(ip, 16)] += int(count)
    insns = code(directory)
    inside = {ip: c for ip, c in samples.items() if ip in insns}
    total = sum(inside.values())
    print(f"{sum(samples.values())} samples, {total} in llvmpipe's code")
    if not total:
        return
    by_op = collections.Counter()
    for ip, c in inside.items():
        by_op[insns[ip].split()[0]] += c
    for op, c in by_op.most_common(15):
        print(f"{100 * c / total:6.1f} %  {op}")
    # The hottest stretch: `span` instructions around the address with the most samples nearby.
    addrs = sorted(insns)
    hot = max(inside, key=lambda ip: sum(inside.get(a, 0) for a in addrs[max(0, addrs.index(ip) - span // 2):addrs.index(ip) + span // 2]))
    i = addrs.index(hot)
    stretch = [insns[a] for a in addrs[max(0, i - span // 2):i + span // 2]]
    ops = [s.split()[0] for s in stretch]
    products = sum(op.startswith("vfmadd") or op == "vmulps" for op in ops)
    stack_stores = sum(op.startswith("vmov") and re.search(r"%[xyz]mm\d+,\s*-?0x[0-9a-f]+\(%rsp\)", s) is not None
                       for op, s in zip(ops, stretch))
    stack_loads = sum(re.search(r"\(%rsp\),\s*%[xyz]mm", s) is not None for s in stretch)
    print(f"hottest {len(stretch)} instructions: {products} products ({ops.count('vmulps')} vmulps + "
          f"{ops.count('vaddps')} vaddps, {sum(o.startswith('vfmadd') for o in ops)} fused), "
          f"{stack_loads} reads of the stack, {stack_stores} stores to it")


if __name__ == "__main__":
    main()
