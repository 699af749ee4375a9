#!/bin/sh
# Builds the stage images physmotion/<stage>:<version> from stages/*/Dockerfile, on a machine whose
# Docker engine cannot pull from a registry (no python:3.11-slim) and may not reach PyTorch's index.
#
#   sh containers/build_images.sh                          # reconstruct, simulate, render and enhance
#   TORCH_WHEEL=/opt/wheels/torch-2.13.0+cpu-cp311-cp311-manylinux_2_28_x86_64.whl \
#       sh containers/build_images.sh simulate             # torch from a local wheel
#
# BASE: the base image (default physmotion/base:bookworm, made by make_base_image.sh when missing;
# BASE=python:3.11-slim where the engine can pull, as the Dockerfiles' own default).
# TORCH_WHEEL: a torch 2.13.0 wheel for CPython 3.11 on Linux. The host's pip fetches its
# dependencies, and a PEP 503 index of them all is served on loopback for the build's TORCH_INDEX;
# without it the Dockerfiles' default index is used. Builds use the host's network (--network host).
# TORCH_INDEX_PORT: the loopback port of that index (default 8765).
set -eu
cd "$(dirname "$0")/.."
VERSION=$(sed -n 's/^version = "\(.*\)"$/\1/p' pyproject.toml)
BASE=${BASE:-physmotion/base:bookworm}
PYTHON=${PYTHON:-python3}
if ! docker image inspect "$BASE" >/dev/null 2>&1; then
    case $BASE in physmotion/base:*) sh containers/make_base_image.sh "$BASE" ;; esac   # others are pulled
fi
set -- ${*:-reconstruct simulate render enhance}
ARGS="--network host --build-arg BASE=$BASE"

if [ -n "${TORCH_WHEEL:-}" ]; then
    INDEX=$(mktemp -d /tmp/physmotion-index.XXXXXX)
    SERVER=
    trap '[ -z "$SERVER" ] || kill "$SERVER"; rm -rf "$INDEX"' EXIT
    "$PYTHON" -m pip download --quiet --dest "$INDEX/wheels" "$TORCH_WHEEL"
    for whl in "$INDEX"/wheels/*; do        # simple/<normalised project name>/<file>
        name=$(basename "$whl" | cut -d- -f1 | tr 'A-Z_.' 'a-z--')
        mkdir -p "$INDEX/simple/$name" && mv "$whl" "$INDEX/simple/$name/"
    done
    # A fixed port: the index URL is part of the cache key of the Dockerfiles' pip layer.
    PORT=${TORCH_INDEX_PORT:-8765}
    "$PYTHON" -m http.server --bind 127.0.0.1 --directory "$INDEX" "$PORT" >/dev/null 2>&1 &
    SERVER=$!
    sleep 1
    kill -0 "$SERVER" 2>/dev/null || { SERVER=; echo "port $PORT is taken: set TORCH_INDEX_PORT" >&2; exit 1; }
    ARGS="$ARGS --build-arg TORCH_INDEX=http://127.0.0.1:$PORT/simple"
fi

for stage in "$@"; do
    start=$(date +%s)
    docker build $ARGS -f "stages/$stage/Dockerfile" -t "physmotion/$stage:$VERSION" .
    echo "physmotion/$stage:$VERSION built in $(( $(date +%s) - start )) s"
done
