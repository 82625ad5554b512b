#!/usr/bin/env bash
# Prepares, on a Debian 12 build machine, what tools/gpu-check.sh needs on a GPU machine that has
# nothing beyond its driver: the release binary and the kernel and network tests' binaries (xz),
# the UNet fixtures the network tests it runs there read (tests/fixtures/unet, as a tar), the
# Vulkan loader and the GL dispatch libraries NVIDIA's Vulkan driver loads beside (Debian 12's
# .debs), and the wheels of diffusers (torch is expected there; without it the UNet runs without
# its reference). With KIT_PEER=1 also stable-diffusion.cpp's Vulkan build (cyllama-vulkan, 31 MB,
# the report's peer, which gpu-check.sh reaches only with more than its default ten minutes).
# And the release binary of KIT_BASELINE (a commit; default 9f9bdc8, the last build a GPU timed),
# built in a scratch worktree, so that the check times the UNet on both builds in one call: every
# kernel change since is then a ratio measured on one machine (KIT_BASELINE=none leaves it out).
# About 42 MB (73 with the peer); nothing needs a network on the GPU machine.
#   tools/gpu-kit.sh [KIT]        (default: .gpu-kit, which git ignores)
set -euo pipefail
cd "$(dirname "$0")/.."
kit=${1:-.gpu-kit}
mkdir -p "$kit"
cargo build --release
target=$(realpath -m "${CARGO_TARGET_DIR:-target}")
xz -T0 -c "$target/release/vkdiff" >"$kit/vkdiff.xz"
for t in "vkdiff-runtime kernels" "vkdiff-networks networks"; do
    set -- $t
    tests=$(cargo test --release -p "$1" --test "$2" --no-run --message-format=json 2>/dev/null |
        sed -n 's/.*"executable":"\([^"]*\)".*/\1/p' | tail -1)
    xz -T0 -c "$tests" >"$kit/$2-test.xz"
done
tar -cf "$kit/unet-fixtures.tar" tests/fixtures/unet
baseline=${KIT_BASELINE:-9f9bdc8}
if [ "$baseline" != none ]; then
    tree=$(mktemp -d)/baseline
    git worktree add -q --detach "$tree" "$baseline"
    # A target folder of its own (kept for the next kit): the baseline's crates must not
    # overwrite this build's.
    (cd "$tree" && CARGO_TARGET_DIR="$target/baseline" cargo build --release -q)
    xz -T0 -c "$target/baseline/release/vkdiff" >"$kit/vkdiff-baseline.xz"
    git rev-parse --short "$baseline" >"$kit/baseline-commit"
    git worktree remove --force "$tree"
fi
(cd "$kit" && apt-get download -q libvulkan1 libglvnd0 libgl1 libglx0 libegl1 libgles2 libopengl0 >/dev/null)
wheels=("diffusers==0.42.1" "importlib_metadata")
[ "${KIT_PEER:-0}" = 1 ] && wheels+=("cyllama-vulkan==0.2.18")
# For the GPU machine's Python (3.12 on the lent H100/H200s; KIT_PYTHON names another), not this
# one's: a wheel of another CPython stops gpu-check.sh's whole install, and with it the references.
python3 -m pip download -q --no-deps --only-binary=:all: --python-version "${KIT_PYTHON:-3.12}" \
    --implementation cp --platform manylinux_2_35_x86_64 --platform manylinux_2_31_x86_64 \
    --platform manylinux_2_17_x86_64 --platform any --dest "$kit" "${wheels[@]}" >/dev/null
du -sh "$kit"
