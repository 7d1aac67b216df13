#!/usr/bin/env bash
# `make image`: the service image motion-style:latest from the Dockerfile, and, where the
# official images cannot be pulled, nginx and Prometheus images for docker-compose.yml.
#
# The official python:3.11-slim-bookworm base is used when it is here or can be pulled.
# Otherwise the base is made from Debian's packages (deploy/image/debian-base.sh, cached by
# a hash of its inputs) and passed as the Dockerfile's PYTHON_IMAGE, the only difference;
# nginx and Prometheus are then Debian's, built on that base under the names that
# deploy/compose.debian.yml gives them. Prints the base that was used (last line).
set -euo pipefail
cd "$(dirname "$0")/../.."

IMAGE=${IMAGE:-motion-style:latest}
# pyproject.toml's extras in the image: `make image-fbx` builds motion-style:fbx with
# EXTRAS="serve fbx" (Blender as a Python module, for FBX in and out)
EXTRAS=${EXTRAS:-serve}
OFFICIAL=python:3.11-slim-bookworm
# The classic builder: BuildKit would fetch its Dockerfile frontend and base metadata from a
# registry, and Debian's docker.io ships no buildx.
export DOCKER_BUILDKIT=0

if [ -n "${PYTHON_IMAGE:-}" ]; then
  base=$PYTHON_IMAGE
elif docker image inspect "$OFFICIAL" >/dev/null 2>&1 || docker pull -q "$OFFICIAL" >&2; then
  base=$OFFICIAL
else
  echo "$OFFICIAL cannot be pulled: building the base from Debian's packages" >&2
  base=$(deploy/image/debian-base.sh)
fi

docker build --build-arg PYTHON_IMAGE="$base" --build-arg EXTRAS="$EXTRAS" -t "$IMAGE" . >&2
if [ "$base" != "$OFFICIAL" ]; then
  for service in nginx prometheus; do
    docker build -q --build-arg BASE_IMAGE="$base" -t "motion-style-$service:debian" \
      -f "deploy/image/$service.Dockerfile" deploy/image >&2
  done
fi
echo "$base"
