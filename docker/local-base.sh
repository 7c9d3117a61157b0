#!/usr/bin/env bash
# A Python 3.11 base image made from Debian packages alone, for machines that reach Debian's
# archive and PyPI but not Docker Hub (where python:3.11-slim lives). Then:
#   docker build --network host -f docker/Dockerfile \
#       --build-arg PYTHON_IMAGE=robocal-local/python:3.11-bookworm -t robocal .
#   ROBOCAL_DOCKER_BASE=robocal-local/python:3.11-bookworm uv run pytest tests/test_docker.py
# Needs root, debootstrap (apt-get install debootstrap) and a running Docker daemon.
# The image trusts the CA certificates this machine adds to Debian's (/usr/local/share/
# ca-certificates), so that pip and uv inside reach PyPI the way this machine does.
set -euo pipefail

TAG=${1:-robocal-local/python:3.11-bookworm}
MIRROR=${DEBIAN_MIRROR:-http://deb.debian.org/debian}
ROOTFS=$(mktemp -d /tmp/robocal-base.XXXXXX)
trap 'rm -rf "$ROOTFS"' EXIT
chmod 755 "$ROOTFS"  # it becomes the image's /: mktemp's 0700 would lock out every other user

debootstrap --variant=minbase --include=python3,python3-pip,python3-venv,ca-certificates \
    bookworm "$ROOTFS" "$MIRROR"
if compgen -G "/usr/local/share/ca-certificates/*.crt" >/dev/null; then
    cp /usr/local/share/ca-certificates/*.crt "$ROOTFS/usr/local/share/ca-certificates/"
    chroot "$ROOTFS" update-ca-certificates
fi
rm -rf "$ROOTFS"/var/cache/apt/archives/*.deb "$ROOTFS"/var/lib/apt/lists/*
# Debian's python3 is 3.11 and marks its site-packages externally managed: the Dockerfile's
# `pip install uv` is allowed to go there, as it does in python:3.11-slim.
tar -C "$ROOTFS" -c . | docker import \
    --change 'ENV PATH=/usr/local/sbin:/usr/local/bin:/usr/sbin:/usr/bin:/sbin:/bin' \
    --change 'ENV LANG=C.UTF-8 PIP_BREAK_SYSTEM_PACKAGES=1 SSL_CERT_FILE=/etc/ssl/certs/ca-certificates.crt' \
    --change 'CMD ["python3"]' - "$TAG"
echo "built $TAG"
