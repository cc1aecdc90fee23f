#!/bin/sh
# Build the rangeplan image (used by `make container-test`).
#   CONTAINER_ENGINE=podman|docker BASE_IMAGE=python:3.11-slim IMAGE=localhost/rangeplan:test container/build.sh
# If BASE_IMAGE is neither present nor pullable (no registry access), a stand-in is built from
# Debian packages (container/stand-in-base.sh) and used instead; this script says so.
set -eu
ENGINE=${CONTAINER_ENGINE:-podman}
BASE=${BASE_IMAGE:-python:3.11-slim}
IMAGE=${IMAGE:-localhost/rangeplan:test}
cd "$(dirname "$0")/.."
# a short name (python:3.11-slim) means Docker Hub's image: podman would otherwise resolve it
# to a local stand-in of the same name
case "$BASE" in
    */*) ;;
    *) BASE=docker.io/library/$BASE ;;
esac
if "$ENGINE" image inspect "$BASE" >/dev/null 2>&1 || timeout 60 "$ENGINE" pull -q "$BASE" >/dev/null 2>&1; then
    echo "container: base image $BASE"
else
    STANDIN=localhost/python:3.11-slim
    echo "container: NOTE: the base image $BASE cannot be pulled here (no registry access);"
    echo "container: building on a stand-in, $STANDIN, made from Debian bookworm packages (python3 3.11)"
    "$ENGINE" image inspect "$STANDIN" >/dev/null 2>&1 || container/stand-in-base.sh "$STANDIN" "$ENGINE"
    BASE=$STANDIN
fi
if [ "$ENGINE" = podman ]; then
    # --format docker keeps the HEALTHCHECK; explicit ulimits: podman's defaults need CAP_SYS_RESOURCE
    set -- --format docker --network host --pull=never --ulimit nofile=20000:20000 --ulimit nproc=32768:32768
else
    set --
fi
start=$(date +%s)
"$ENGINE" build "$@" --build-arg BASE_IMAGE="$BASE" -t "$IMAGE" .
echo "container: built $IMAGE on $BASE in $(( $(date +%s) - start )) s"
echo "$BASE" > .container-base
