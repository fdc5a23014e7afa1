#!/usr/bin/env bash
# Installs what psrestir needs on a fresh Debian/Ubuntu machine: the Vulkan loader and Mesa's
# CPU Vulkan driver (lavapipe). Safe to run again; does nothing when a current one is there.
#
# Which lavapipe: Mesa >= 24 traces psrestir's rays about 3.8x faster than Mesa 22 on the
# same CPU (measured with `psrestir render`, same images to 5e-7). Debian 12 ships Mesa 22.3.6
# and carries Mesa 25 in bookworm-backports, so on Debian 12 this script enables backports
# (on the mirror the machine's own apt sources already use) and installs mesa-vulkan-drivers
# from there; libdrm comes along. Where that fails, or on other distributions, it keeps (or
# installs) the distribution's own driver. PSRESTIR_MESA=distro skips the backports step.
set -euo pipefail

SUDO=""
if [ "$(id -u)" != "0" ]; then SUDO="sudo"; fi
export DEBIAN_FRONTEND=noninteractive

have_lavapipe() {
    ls /usr/share/vulkan/icd.d/lvp_icd*.json >/dev/null 2>&1 &&
        ldconfig -p 2>/dev/null | grep -q 'libvulkan\.so\.1'
}

# The installed mesa-vulkan-drivers version ("" when none).
mesa_version() {
    dpkg-query -W -f='${Status} ${Version}\n' mesa-vulkan-drivers 2>/dev/null |
        awk '$3 == "installed" { print $4 }'
}

mesa_is_current() {
    local v
    v="$(mesa_version)"
    [ -n "$v" ] && dpkg --compare-versions "$v" ge 24
}

# The Debian mirror this machine already uses for bookworm (deb822 or one-line sources).
debian_mirror() {
    local f
    for f in /etc/apt/sources.list.d/*.sources; do
        [ -e "$f" ] || continue
        awk 'BEGIN { RS = ""; FS = "\n" }
             /Suites:[^\n]*bookworm([ \n]|$)/ {
                 for (i = 1; i <= NF; i++) if ($i ~ /^URIs:/) { split($i, a, " "); print a[2]; exit }
             }' "$f"
    done | head -n 1
    for f in /etc/apt/sources.list /etc/apt/sources.list.d/*.list; do
        [ -e "$f" ] || continue
        awk '$1 == "deb" && $3 == "bookworm" { print $2; exit }' "$f"
    done | head -n 1
}

try_backports() {
    [ "${PSRESTIR_MESA:-}" = "distro" ] && return 1
    [ -r /etc/os-release ] || return 1
    # shellcheck disable=SC1091
    . /etc/os-release
    [ "${ID:-}" = "debian" ] && [ "${VERSION_CODENAME:-}" = "bookworm" ] || return 1
    if ! apt-cache policy 2>/dev/null | grep -q 'bookworm-backports'; then
        local mirror
        mirror="$(debian_mirror | head -n 1)"
        if [ -z "$mirror" ]; then
            echo "ci/setup.sh: no Debian mirror found in the apt sources; keeping the distribution's Mesa"
            return 1
        fi
        echo "ci/setup.sh: enabling bookworm-backports on $mirror"
        printf 'Types: deb\nURIs: %s\nSuites: bookworm-backports\nComponents: main\nSigned-By: /usr/share/keyrings/debian-archive-keyring.gpg\n' \
            "$mirror" | $SUDO tee /etc/apt/sources.list.d/psrestir-backports.sources >/dev/null
    fi
    $SUDO apt-get update -qq || return 1
    echo "ci/setup.sh: installing mesa-vulkan-drivers from bookworm-backports"
    $SUDO apt-get install -y -qq --no-install-recommends -t bookworm-backports \
        mesa-vulkan-drivers libvulkan1 >/dev/null || return 1
    mesa_is_current
}

if have_lavapipe && mesa_is_current; then
    echo "ci/setup.sh: lavapipe (Mesa $(mesa_version)) and the Vulkan loader are installed"
else
    if ! try_backports; then
        if ! have_lavapipe; then
            echo "ci/setup.sh: installing the distribution's mesa-vulkan-drivers and libvulkan1"
            $SUDO apt-get update -qq
            $SUDO apt-get install -y -qq --no-install-recommends mesa-vulkan-drivers libvulkan1 >/dev/null
        fi
    fi
    have_lavapipe || { echo "ci/setup.sh: lavapipe still missing after install" >&2; exit 1; }
    v="$(mesa_version)"
    echo "ci/setup.sh: lavapipe from Mesa ${v:-unknown} installed"
    if ! mesa_is_current; then
        echo "ci/setup.sh: note: Mesa ${v:-unknown} is older than 24; psrestir runs, about 4x slower"
    fi
fi

if ! command -v cargo >/dev/null 2>&1; then
    echo "ci/setup.sh: cargo not found; install Rust (rustup) first" >&2
    exit 1
fi
