#!/bin/sh
# A stand-in for python:3.11-slim on a machine whose Docker engine cannot pull from a registry
# but can reach Debian's package mirror: Debian 12 (bookworm) minbase + its Python 3.11, with a
# virtual environment first on PATH so that `pip install` works as in the official image (PEP 668).
# Needs root, debootstrap (apt-get install debootstrap) and a running Docker engine.
# The host's own certificate authorities (/usr/local/share/ca-certificates, e.g. of a proxy that
# inspects TLS) are trusted in the image too, and pip reads the system bundle (PIP_CERT), so that
# `pip install` in a build reaches PyPI wherever the host does.
#
#   sh containers/make_base_image.sh                 # -> physmotion/base:bookworm
#   docker build --build-arg BASE=physmotion/base:bookworm -f stages/simulate/Dockerfile ...
#
# Arguments (all optional): image tag, Debian mirror.
set -eu
TAG=${1:-physmotion/base:bookworm}
MIRROR=${2:-http://deb.debian.org/debian}
ROOT=$(mktemp -d /tmp/physmotion-base.XXXXXX)
trap 'rm -rf "$ROOT"' EXIT

debootstrap --variant=minbase --include=python3,python3-venv,ca-certificates bookworm "$ROOT" "$MIRROR"
in_root() { env -i PATH=/usr/sbin:/usr/bin:/sbin:/bin chroot "$ROOT" "$@"; }
cp -r /usr/local/share/ca-certificates/. "$ROOT"/usr/local/share/ca-certificates/ 2>/dev/null || true
in_root update-ca-certificates
in_root python3 -m venv /opt/venv
rm -rf "$ROOT"/var/lib/apt/lists/* "$ROOT"/var/cache/apt/* "$ROOT"/usr/share/doc/* "$ROOT"/usr/share/man/*

tar -C "$ROOT" --numeric-owner -c . | docker import \
    --change 'ENV PATH=/opt/venv/bin:/usr/local/sbin:/usr/local/bin:/usr/sbin:/usr/bin:/sbin:/bin' \
    --change 'ENV LANG=C.UTF-8' \
    --change 'ENV PIP_CERT=/etc/ssl/certs/ca-certificates.crt' \
    --change 'CMD ["python3"]' \
    --message "debian bookworm minbase + python3 venv (containers/make_base_image.sh)" \
    - "$TAG"
docker run --rm "$TAG" sh -c 'python --version && pip --version'
