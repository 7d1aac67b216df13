#!/usr/bin/env bash
# What `make image-test` needs on a machine of CI's kind (Debian, root, no registry): Debian's
# docker.io, docker-compose (1.29) and debootstrap, installed with apt when missing, and a
# running dockerd (started here, logging to /var/log/dockerd.log, when none answers).
set -euo pipefail

missing=()
command -v dockerd >/dev/null || missing+=(docker.io)
command -v docker-compose >/dev/null || docker compose version >/dev/null 2>&1 \
  || missing+=(docker-compose)
command -v debootstrap >/dev/null || missing+=(debootstrap)
if [ ${#missing[@]} -gt 0 ]; then
  if command -v apt-get >/dev/null && [ "$(id -u)" = 0 ]; then
    apt-get update -qq
    DEBIAN_FRONTEND=noninteractive apt-get install -y -qq "${missing[@]}" >/dev/null
  else
    echo "missing ${missing[*]} and no apt-get as root to install them" >&2
    exit 1
  fi
fi

if ! docker info >/dev/null 2>&1; then
  if [ "$(id -u)" != 0 ]; then
    echo "no Docker engine answers, and only root starts one here" >&2
    exit 1
  fi
  echo "starting dockerd (log: /var/log/dockerd.log)" >&2
  setsid dockerd >/var/log/dockerd.log 2>&1 </dev/null &
  for _ in $(seq 60); do
    docker info >/dev/null 2>&1 && break
    sleep 1
  done
  docker info >/dev/null || { tail -20 /var/log/dockerd.log >&2; exit 1; }
fi
docker info --format 'Docker {{.ServerVersion}}, {{.Driver}}, cgroup {{.CgroupVersion}}' >&2
