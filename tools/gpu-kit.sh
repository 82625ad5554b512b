#!/usr/bin/env bash
# Prepares, on a Debian 12 build machine, what tools/gpu-check.sh needs on a GPU machine that has
# nothing beyond its driver: the release binary and the kernel tests' binary (xz), the Vulkan
# loader and the GL dispatch libraries NVIDIA's Vulkan driver loads beside (Debian 12's .debs),
# and diffusers' wheel for the references (torch is expected there; without it the report runs
# without references). About 15 MB; nothing needs a network on the GPU machine.
#   tools/gpu-kit.sh [KIT]        (default: .gpu-kit, which git ignores)
set -euo pipefail
cd "$(dirname "$0")/.."
kit=${1:-.gpu-kit}
mkdir -p "$kit"
cargo build --release
xz -T0 -c target/release/vkdiff >"$kit/vkdiff.xz"
tests=$(cargo test --release -p vkdiff-runtime --test kernels --no-run --message-format=json 2>/dev/null |
    sed -n 's/.*"executable":"\([^"]*\)".*/\1/p' | tail -1)
xz -T0 -c "$tests" >"$kit/kernels-test.xz"
(cd "$kit" && apt-get download -q libvulkan1 libglvnd0 libgl1 libglx0 libegl1 libgles2 libopengl0 >/dev/null)
python3 -m pip download -q --no-deps --dest "$kit" "diffusers==0.42.1" "importlib_metadata" >/dev/null
du -sh "$kit"
