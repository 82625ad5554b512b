#!/usr/bin/env bash
# What lavapipe's JIT made of the kernels a command runs, and where its time goes: samples the
# running process with perf (software clock: no hardware counters needed), copies its anonymous
# executable mappings (llvmpipe's machine code) with gdb, and prints the instruction mix the
# samples land on and the hottest code (tools/jit_annotate.py). Release Mesa prints no assembly
# (GALLIVM_DEBUG=asm needs a debug build), so this is how LLVM's output is read here.
#   tools/jit-profile.sh DELAY SECONDS -- COMMAND...    (e.g. 20 8 -- vkdiff bench kernels --filter linear)
# Needs perf and gdb (apt-get install linux-perf gdb); files go to ${JIT_PROFILE_DIR:-/tmp/jit-profile}.
set -euo pipefail
[ $# -ge 4 ] && [ "$3" = -- ] || { echo "usage: $0 DELAY SECONDS -- COMMAND..." >&2; exit 2; }
delay=$1 seconds=$2
shift 3
dir=${JIT_PROFILE_DIR:-/tmp/jit-profile}
rm -rf "$dir" && mkdir -p "$dir"
"$@" >"$dir/command.out" 2>&1 &
pid=$!
sleep "$delay"
kill -0 "$pid" 2>/dev/null || { echo "the command ended before $delay s: see $dir/command.out" >&2; exit 1; }
perf record -F 1999 -p "$pid" -o "$dir/perf.data" -- sleep "$seconds" >/dev/null 2>&1
# llvmpipe's code: executable mappings with no file behind them.
grep -E ' (r-xp|rwxp) ' "/proc/$pid/maps" | grep -v -E '\.so|/|\[vdso\]' >"$dir/maps" || true
while read -r range _; do
    gdb -p "$pid" -batch -ex "dump memory $dir/jit_${range%-*}.bin 0x${range%-*} 0x${range#*-}" >/dev/null 2>&1
done <"$dir/maps"
kill "$pid" 2>/dev/null || true
perf script -i "$dir/perf.data" -F ip 2>/dev/null | sort | uniq -c | sort -rn >"$dir/ips"
python3 "$(dirname "$0")/jit_annotate.py" "$dir"
