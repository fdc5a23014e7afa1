#!/usr/bin/env bash
# Installs what psrestir needs on a fresh Debian/Ubuntu machine: the Vulkan loader and Mesa's
# CPU Vulkan driver (lavapipe), plus rustfmt for the format check. Does nothing when they are
# there already. Safe to run again.
set -euo pipefail

have_lavapipe() {
    ls /usr/share/vulkan/icd.d/lvp_icd*.json >/dev/null 2>&1 &&
        ldconfig -p 2>/dev/null | grep -q 'libvulkan\.so\.1'
}

if have_lavapipe; then
    echo "ci/setup.sh: lavapipe and the Vulkan loader are installed"
else
    echo "ci/setup.sh: installing mesa-vulkan-drivers and libvulkan1"
    SUDO=""
    if [ "$(id -u)" != "0" ]; then SUDO="sudo"; fi
    export DEBIAN_FRONTEND=noninteractive
    $SUDO apt-get update -qq
    $SUDO apt-get install -y -qq --no-install-recommends mesa-vulkan-drivers libvulkan1 >/dev/null
    have_lavapipe || { echo "ci/setup.sh: lavapipe still missing after install" >&2; exit 1; }
fi

if ! command -v cargo >/dev/null 2>&1; then
    echo "ci/setup.sh: cargo not found; install Rust (rustup) first" >&2
    exit 1
fi
