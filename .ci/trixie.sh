#!/usr/bin/env bash
# The second tested platform, Debian 13 (DOLFINx 0.9, Python 3.13, numpy 2), in a chroot:
#   trixie.sh tree DIR "PACKAGES"   make the tree once (debootstrap from the mirror the machine's
#                                   own apt sources name, then the Debian packages), cached in DIR
#   trixie.sh test DIR              run `make test` in the tree on a copy of this checkout
# Run as root (or with sudo available); the tree lives outside the repository.
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
cmd=$1 tree=$2
SUDO=""
if [ "$(id -u)" -ne 0 ]; then SUDO="sudo"; fi

mirror() {  # the Debian mirror of this machine's apt sources (deb822 or one-line format)
    { cat /etc/apt/sources.list.d/*.sources 2>/dev/null | awk '/^URIs:/ {print $2}';
      cat /etc/apt/sources.list 2>/dev/null | awk '$1 == "deb" {print $2}'; } |
        grep -v security | head -n 1
}

mount_all() {  # the kernel's file systems, and what pip needs: its configuration and wheels
    for d in proc sys dev; do
        mountpoint -q "$tree/$d" || $SUDO mount --bind "/$d" "$tree/$d"
    done
    $SUDO cp /etc/resolv.conf "$tree/etc/resolv.conf"
    if [ -f /etc/ssl/certs/ca-certificates.crt ]; then
        $SUDO mkdir -p "$tree/etc/ssl/certs"
        $SUDO cp /etc/ssl/certs/ca-certificates.crt "$tree/etc/ssl/certs/ca-certificates.crt"
    fi
    if [ -f /etc/pip.conf ]; then $SUDO cp /etc/pip.conf "$tree/etc/pip.conf"; fi
    if [ -d /etc/xdg/pip ]; then $SUDO mkdir -p "$tree/etc/xdg" && $SUDO cp -r /etc/xdg/pip "$tree/etc/xdg/"; fi
    for d in /opt/wheels /opt/pypi /opt/pypi-more; do
        if [ -d "$d" ]; then
            $SUDO mkdir -p "$tree$d"
            mountpoint -q "$tree$d" || $SUDO mount --bind "$d" "$tree$d"
        fi
    done
}

unmount_all() {
    for d in /opt/pypi-more /opt/pypi /opt/wheels /dev /sys /proc; do
        if mountpoint -q "$tree$d"; then $SUDO umount -l "$tree$d"; fi
    done
}

case "$cmd" in
tree)
    packages=$3
    if [ -f "$tree/.dolfinx-dem-ready" ]; then exit 0; fi
    if ! command -v debootstrap >/dev/null 2>&1; then
        if [ -z "${APT_UPDATED:-}" ]; then $SUDO apt-get update; fi
        $SUDO env DEBIAN_FRONTEND=noninteractive apt-get install -y --no-install-recommends debootstrap
    fi
    $SUDO rm -rf "$tree"
    $SUDO mkdir -p "$(dirname "$tree")"
    $SUDO debootstrap --variant=minbase trixie "$tree" "$(mirror)"
    trap unmount_all EXIT
    mount_all
    $SUDO chroot "$tree" apt-get update
    $SUDO chroot "$tree" env DEBIAN_FRONTEND=noninteractive apt-get install -y --no-install-recommends $packages
    $SUDO touch "$tree/.dolfinx-dem-ready"
    ;;
test)
    trap unmount_all EXIT
    mount_all
    # a copy of this checkout (its git data, tracked and new files; not the venv or outputs):
    # the tree builds its own venv and kernels
    $SUDO rm -rf "$tree/src"
    $SUDO mkdir -p "$tree/src"
    { git ls-files -z --cached --others --exclude-standard; printf '.git\0'; } |
        $SUDO tar --null -T - -cf - | $SUDO tar -xf - -C "$tree/src"
    $SUDO chroot "$tree" git config --global --add safe.directory /src
    $SUDO chroot "$tree" env HOME=/root bash -c "cd /src && make test"
    ;;
*)
    echo "usage: $0 tree DIR PACKAGES | test DIR" >&2
    exit 2
    ;;
esac
