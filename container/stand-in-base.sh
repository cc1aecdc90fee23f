#!/bin/sh
# Build a stand-in for python:3.11-slim from Debian packages, for sites without access to a
# container registry (the Debian mirror is enough): debootstrap of Debian bookworm (whose
# python3 is 3.11) with python3, python3-venv and python3-pip, imported as IMAGE.
#   container/stand-in-base.sh [IMAGE] [ENGINE]     (root; ENGINE: podman (default) or docker)
set -eu
IMAGE=${1:-localhost/python:3.11-slim}
ENGINE=${2:-podman}
SUITE=bookworm
# the mirror the host's apt uses (deb822 "URIs:" or one-line "deb URI suite ..."), else Debian's CDN
MIRROR=$(cat /etc/apt/sources.list.d/*.sources 2>/dev/null | awk '/^URIs:/ && $2 ~ /debian\/?$/ {print $2; exit}')
[ -n "$MIRROR" ] || MIRROR=$(cat /etc/apt/sources.list /etc/apt/sources.list.d/*.list 2>/dev/null \
    | awk '$1 == "deb" && $2 ~ /debian\/?$/ {print $2; exit}')
[ -n "$MIRROR" ] || MIRROR=http://deb.debian.org/debian
ROOTFS=$(mktemp -d /var/tmp/rangeplan-base.XXXXXX)
trap 'umount "$ROOTFS/proc" 2>/dev/null || true; rm -rf "$ROOTFS"' EXIT
echo "stand-in base: debootstrap $SUITE from $MIRROR (no registry needed) -> $IMAGE"
debootstrap --variant=minbase "$SUITE" "$ROOTFS" "$MIRROR" >/dev/null
mount -t proc proc "$ROOTFS/proc"
chroot "$ROOTFS" sh -c 'apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq \
    --no-install-recommends python3 python3-venv python3-pip ca-certificates >/dev/null \
    && ln -sf /usr/bin/python3 /usr/local/bin/python && apt-get clean && rm -rf /var/lib/apt/lists/*'
# locally added CA certificates (a TLS-inspecting egress proxy): pip needs them at build time
if ls /usr/local/share/ca-certificates/*.crt >/dev/null 2>&1; then
    cp /usr/local/share/ca-certificates/*.crt "$ROOTFS/usr/local/share/ca-certificates/"
    chroot "$ROOTFS" update-ca-certificates >/dev/null 2>&1
fi
umount "$ROOTFS/proc"
tar -C "$ROOTFS" -c . | "$ENGINE" import --change 'CMD ["python3"]' - "$IMAGE" >/dev/null
echo "stand-in base: $IMAGE ($("$ENGINE" image inspect --format '{{.Size}}' "$IMAGE") bytes)"
