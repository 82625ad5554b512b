#!/usr/bin/env bash
# What minutes on a lent GPU should run, in order of worth, each step bounded so that the whole
# fits in 10 minutes (or GPU_CHECK_SECONDS), every figure and log under $OUT (the log appended as it goes: a call cut
# at its limit still brings back what ran):
#   1. `vkdiff devices --json`, the driver and torch's versions;
#   2. the matrix units' two workgroup tiles, one after the other on one machine: the SDXL
#      products (`bench kernels`, which times both, and VK_NV_cooperative_matrix2's probes on the
#      linear, convolution and attention rows where the driver offers workgroup scope) and the SDXL UNet at 1024² with
#      VKDIFF_MATRIX_TILE=4 and 8, to decide which `auto` takes, and with VKDIFF_ATTENTION=cm2
#      VKDIFF_LINEAR=cm2 and VKDIFF_CONV=cm2 where the driver runs those probes' tiles;
#   3. `vkdiff bench report` (the full suite: the paper's image first) beside diffusers and
#      torch on CUDA where torch is installed, else without references;
#   4. stable-diffusion.cpp's Vulkan build beside vkdiff (`bench report --only peer`);
#   5. the kernel and network tests on the device, its matrix units required where it has them
#      (the network tests read the fixtures of the repository this script is in);
#   6. `vkdiff devices --compile` (every kernel through the driver's own compiler);
#   7. the paper's ablation (`bench report --only ablation`), where time is left.
# KIT is what tools/gpu-kit.sh made on a build machine.
#   OUT=/some/folder tools/gpu-check.sh [KIT]     (default KIT: .gpu-kit)
set -uo pipefail
kit=$(cd "${1:-$(dirname "$0")/../.gpu-kit}" && pwd)
repo=$(cd "$(dirname "$0")/.." && pwd)
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
if ! ldconfig -p | grep -q 'libGLX.so.0' || ! ldconfig -p | grep -q 'libvulkan.so.1'; then
    for deb in "$kit"/*.deb; do dpkg -x "$deb" /; done
    ldconfig
fi
for f in vkdiff kernels-test networks-test; do xz -d -c "$kit/$f.xz" >"$work/$f" && chmod +x "$work/$f"; done
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
step 30 sh -c "'$work/vkdiff' devices --json >'$out/devices.json'"
# The convolution rows are four shapes on every family and probe tile: more time.
for filter in linear:90 conv2d:120 attention:90; do
    step "${filter#*:}" sh -c "'$work/vkdiff' bench kernels --no-cpu-reference --filter ${filter%:*} \
        >'$out/kernels-${filter%:*}.txt'"
done
for tile in 8 4; do
    step 70 sh -c "VKDIFF_MATRIX_TILE=$tile '$work/vkdiff' bench unet --size 1024 --samples 3 --profile \
        --no-cpu-reference >'$out/unet-tile-$tile.txt'"
done
# The UNet with VK_NV_cooperative_matrix2's attention, its linear product, then its convolution,
# each where the driver runs one of that probe's tiles.
for probe in 'ATTENTION:attention [0-9]* rows' 'LINEAR:linear [0-9]*×' 'CONV:convolution [0-9]* pixels'; do
    variable=VKDIFF_${probe%%:*} name=${probe%%:*}
    if grep -q "${probe#*:}" "$out/devices.json" 2>/dev/null; then
        step 70 sh -c "$variable=cm2 '$work/vkdiff' bench unet --size 1024 --samples 3 --profile \
            --no-cpu-reference >'$out/unet-${name,,}-cm2.txt'"
    fi
done
step 220 "$work/vkdiff" bench report --only image,unet,vae,kernels --reference-device "$reference" \
    --out "$out/report.json"
step 150 "$work/vkdiff" bench report --only peer --runs 1 --reference-device none --out "$out/peer.json"
step 100 env VKDIFF_EXPECT_COOPERATIVE=1 "$work/kernels-test" --test-threads 4
step 60 env VKDIFF_EXPECT_COOPERATIVE=1 VKDIFF_REPO="$repo" "$work/networks-test" --test-threads 4
step 40 sh -c "'$work/vkdiff' devices --compile --json >'$out/compile.json'"
step 570 "$work/vkdiff" bench report --only ablation --runs 1 --reference-device none --out "$out/ablation.json"
echo "=== done [$((SECONDS - start)) s]" >>"$log"
rm -rf "$work"
