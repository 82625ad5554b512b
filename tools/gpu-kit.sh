#!/usr/bin/env bash
# Prepares, on a Debian 12 build machine, what tools/gpu-check.sh needs on a GPU machine that has
# nothing beyond its driver: the release binary and the kernel and network tests' binaries (xz; the
# network tests read the repository's fixtures, through VKDIFF_REPO), the Vulkan
# loader and the GL dispatch libraries NVIDIA's Vulkan driver loads beside (Debian 12's .debs),
# and the wheels of diffusers (torch is expected there; without it the report runs without
# references) and of stable-diffusion.cpp's Vulkan build (cyllama-vulkan, the report's peer).
# About 45 MB; nothing needs a network on the GPU machine.
#   tools/gpu-kit.sh [KIT]        (default: .gpu-kit, which git ignores)
set -euo pipefail
cd "$(dirname "$0")/.."
kit=${1:-.gpu-kit}
mkdir -p "$kit"
cargo build --release
xz -T0 -c target/release/vkdiff >"$kit/vkdiff.xz"
for t in "vkdiff-runtime kernels" "vkdiff-networks networks"; do
    set -- $t
    tests=$(cargo test --release -p "$1" --test "$2" --no-run --message-format=json 2>/dev/null |
        sed -n 's/.*"executable":"\([^"]*\)".*/\1/p' | tail -1)
    xz -T0 -c "$tests" >"$kit/$2-test.xz"
done
(cd "$kit" && apt-get download -q libvulkan1 libglvnd0 libgl1 libglx0 libegl1 libgles2 libopengl0 >/dev/null)
python3 -m pip download -q --no-deps --dest "$kit" "diffusers==0.42.1" "importlib_metadata" \
    "cyllama-vulkan==0.2.18" >/dev/null
du -sh "$kit"
