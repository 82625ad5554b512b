#!/usr/bin/env bash
# What minutes on a lent GPU should run, in order of worth, each step bounded so that the whole
# fits in 10 minutes (or GPU_CHECK_SECONDS), every figure and log under $OUT (the log appended as
# it goes: a call cut at its limit still brings back what ran):
#   1. `vkdiff devices --json`, the driver and torch's versions;
#   2. the kernel tests on the device, its matrix units required where it has them: every kernel
#      a timing below runs (the eight-subgroup tiles, VK_NV_cooperative_matrix2's workgroup-scope
#      probes) held to f64 on this driver first, since the time of a wrong kernel says nothing;
#   3. the SDXL UNet at 1024², batch 2, beside diffusers on CUDA in the same call (where torch
#      sees the GPU), eager at its best (cudnn.benchmark, channels_last, fused QKV, CUDA events)
#      and through torch.compile, on the tile `auto` takes;
#   3b. the same UNet on the kit's baseline build (the last one a GPU timed), where it has one:
#      every kernel change since, as one ratio from one machine;
#   4. the UNet with VKDIFF_TUNE=1 (each shape's kernels timed and the fastest taken: the table
#      of which tile or probe wins where);
#   5. the SDXL products (`bench kernels`: the linear, convolution and attention rows on every
#      tile and on the probes' tiles) and the matrix units' ceiling they are held against;
#   5b. the UNet on each of the matrix units' eight-subgroup tiles (VKDIFF_MATRIX_TILE=8,
#      128x64, 64x128; `auto` is four subgroups), to decide which `auto` takes, and with
#      VKDIFF_ATTENTION=cm2, VKDIFF_LINEAR=cm2 and VKDIFF_CONV=cm2 where the driver runs those
#      probes' tiles (after the rows: each whole UNet is a minute, the rows hold every family);
#   6. the UNet network tests against diffusers (the kit's UNet fixtures);
#   7. `vkdiff bench report` (the full suite: the paper's image first, then at 4 steps under Lightning's
#      recipe, the ratio images per hour gain), the peer where the kit
#      has it (KIT_PEER=1), `vkdiff devices --compile` and the paper's ablation, where time is left.
# KIT is what tools/gpu-kit.sh made on a build machine; nothing here reads the repository.
#   OUT=/some/folder tools/gpu-check.sh [KIT]     (default KIT: .gpu-kit)
set -uo pipefail
kit=$(cd "${1:-$(dirname "$0")/../.gpu-kit}" && pwd)
out=${OUT:?set OUT to the folder that takes the results}
mkdir -p "$out"
log=$out/gpu-check.log
work=$(mktemp -d)
start=$SECONDS

# Every step's limit is cut to what is left of GPU_CHECK_SECONDS (570 by default).
budget=${GPU_CHECK_SECONDS:-570}
step() {
    local limit=$1 left=$((budget - (SECONDS - start)))
    shift
    [ "$limit" -le "$left" ] || limit=$left
    if [ "$limit" -lt 15 ]; then
        echo "=== skipped, no time left: $*" >>"$log"
        return
    fi
    echo "=== $(date -u +%T) [$((SECONDS - start)) s] $*" >>"$log"
    local s=$SECONDS
    timeout "$limit" "$@" >>"$log" 2>&1
    echo "=== rc=$? in $((SECONDS - s)) s" >>"$log"
}

# The Vulkan loader and the GL dispatch libraries beside NVIDIA's driver, where they are missing.
# (The cache is searched after it is read: a pipe into grep -q fails under pipefail whenever
# grep stops reading first.)
cache=$(ldconfig -p)
if ! grep -q 'libGLX.so.0' <<<"$cache" || ! grep -q 'libvulkan.so.1' <<<"$cache"; then
    for deb in "$kit"/*.deb; do dpkg -x "$deb" /; done
    ldconfig
fi
for f in vkdiff vkdiff-baseline kernels-test networks-test; do
    [ -f "$kit/$f.xz" ] && xz -d -c "$kit/$f.xz" >"$work/$f" && chmod +x "$work/$f"
done
mkdir -p "$work/repo" && tar -xf "$kit/unet-fixtures.tar" -C "$work/repo"
reference=none
if python3 -c 'import torch; assert torch.cuda.is_available()' 2>/dev/null; then
    python3 -m pip install -q --no-index --no-deps --no-compile --target "$work/site" "$kit"/*.whl &&
        export PYTHONPATH=$work/site && reference=cuda
fi
export VKDIFF_REFERENCE_PYTHON=python3
{
    nvidia-smi --query-gpu=name,driver_version,clocks.sm,clocks.max.sm --format=csv 2>&1
    python3 -c 'import torch, diffusers; print("torch", torch.__version__, "diffusers", diffusers.__version__)' 2>&1
    echo "references: $reference"
} >>"$log"
vkdiff=$work/vkdiff
step 30 sh -c "'$vkdiff' devices --json >'$out/devices.json'"
step 90 env VKDIFF_EXPECT_COOPERATIVE=1 "$work/kernels-test" --test-threads 4
unet() { # the output's name, the environment, then bench unet's further arguments ($limit: 90 s)
    local name=$1 env=$2
    shift 2
    step "${limit:-90}" sh -c "$env '${bin:-$vkdiff}' bench unet --size 1024 --samples 3 --profile $* >'$out/unet-$name.txt'"
}
# With the references: diffusers eager at its best, then torch.compile (minutes of compiling).
if [ "$reference" = cuda ]; then limit=240 unet auto "" --reference-device cuda; else unet auto "" --no-cpu-reference; fi
if [ -x "$work/vkdiff-baseline" ]; then
    bin=$work/vkdiff-baseline unet "baseline-$(cat "$kit/baseline-commit")" "" --no-cpu-reference
fi
# Every shape's kernels timed against each other (its table lists each shape's candidates).
unet tuned "VKDIFF_TUNE=1" --no-cpu-reference
# The convolution rows are four shapes on every family and probe tile: more time.
for filter in linear:90 conv2d:120 attention:90 ceiling:30; do
    step "${filter#*:}" sh -c "'$vkdiff' bench kernels --no-cpu-reference --filter ${filter%:*} \
        >'$out/kernels-${filter%:*}.txt'"
done
for tile in 8 128x64 64x128; do unet "tile-$tile" "VKDIFF_MATRIX_TILE=$tile" --no-cpu-reference; done
# VK_NV_cooperative_matrix2's attention, its linear product, then its convolution, each where
# the driver runs one of that probe's tiles.
for probe in 'ATTENTION:attention [0-9]* rows' 'LINEAR:linear [0-9]*×' 'CONV:convolution [0-9]* pixels'; do
    name=${probe%%:*}
    if grep -q "${probe#*:}" "$out/devices.json" 2>/dev/null; then
        unet "${name,,}-cm2" "VKDIFF_$name=cm2" --no-cpu-reference
    fi
done
step 90 env VKDIFF_EXPECT_COOPERATIVE=1 VKDIFF_REPO="$work/repo" "$work/networks-test" --test-threads 4 forward
step 220 "$vkdiff" bench report --only image,unet,vae,kernels --reference-device "$reference" \
    --out "$out/report.json"
if ls "$kit"/cyllama_vulkan-*.whl >/dev/null 2>&1; then
    step 150 "$vkdiff" bench report --only peer --runs 1 --reference-device none --out "$out/peer.json"
fi
step 40 sh -c "'$vkdiff' devices --compile --json >'$out/compile.json'"
step 570 "$vkdiff" bench report --only ablation --runs 1 --reference-device none --out "$out/ablation.json"
nvidia-smi --query-gpu=clocks.sm,clocks.mem,temperature.gpu,power.draw --format=csv >>"$log" 2>&1
echo "=== done [$((SECONDS - start)) s]" >>"$log"
rm -rf "$work"
