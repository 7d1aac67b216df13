#!/usr/bin/env bash
# Make a Python 3.11 base image from Debian's own packages, for machines where no registry
# image (python:3.11-slim-bookworm, nginx) can be pulled:
#
#   deploy/image/debian-base.sh            # prints the tag, e.g. motion-style-base:3f2a9c1e04b7
#
# debootstrap a bookworm minbase with python3 and apt, trim what no container reads (docs,
# man pages, locales, apt's lists), and `docker import` it. The tag is a hash of this script
# and the CA bundle it copies in, so the base is made once and remade only when either
# changes. Needs root, debootstrap and a running dockerd.
set -euo pipefail

SUITE=bookworm
MIRROR=${DEBIAN_MIRROR:-http://deb.debian.org/debian}
PACKAGES=python3,python3-venv,python-is-python3,ca-certificates
# Where pip and apt in a build look for trusted roots: this machine's bundle, so that a
# TLS-inspecting proxy the host trusts is trusted in the build too.
CA_BUNDLE=/etc/ssl/certs/ca-certificates.crt
REPO_NAME=${BASE_REPOSITORY:-motion-style-base}

inputs_hash=$(cat "$0" "$CA_BUNDLE" | sha256sum | cut -c1-12)
tag="$REPO_NAME:$inputs_hash"
if docker image inspect "$tag" >/dev/null 2>&1; then
  echo "$tag"
  exit 0
fi

root=$(mktemp -d /tmp/motion-style-base.XXXXXX)
trap 'rm -rf "$root"' EXIT
echo "debootstrap $SUITE ($PACKAGES) from $MIRROR into $root" >&2
debootstrap --variant=minbase --include="$PACKAGES" "$SUITE" "$root" "$MIRROR" >&2

cp "$CA_BUNDLE" "$root/etc/ssl/certs/ca-certificates.crt"
cat >"$root/etc/apt/sources.list" <<SOURCES
deb $MIRROR $SUITE main
deb $MIRROR $SUITE-updates main
deb http://deb.debian.org/debian-security $SUITE-security main
SOURCES
# What the official slim images also leave out: docs, man pages, translations, apt's caches.
cat >"$root/etc/dpkg/dpkg.cfg.d/slim" <<DPKG
path-exclude /usr/share/doc/*
path-exclude /usr/share/man/*
path-exclude /usr/share/info/*
path-exclude /usr/share/locale/*
path-exclude /usr/share/lintian/*
DPKG
echo 'APT::Install-Recommends "false";' >"$root/etc/apt/apt.conf.d/90no-recommends"
# No package's maintainer script starts a daemon during a build (as in Debian's own images).
printf '#!/bin/sh\nexit 101\n' >"$root/usr/sbin/policy-rc.d"
chmod +x "$root/usr/sbin/policy-rc.d"
echo "debootstrap made $(du -sh --exclude=proc --exclude=sys "$root" | cut -f1)" >&2
rm -rf "$root"/usr/share/{doc,man,info,locale,lintian}/* \
  "$root"/var/lib/apt/lists/* "$root"/var/cache/apt/*.bin "$root"/var/cache/apt/archives/*.deb \
  "$root"/var/log/*.log "$root"/var/log/apt/* "$root"/tmp/*

echo "trimmed to $(du -sh --exclude=proc --exclude=sys "$root" | cut -f1)" >&2
tar -C "$root" --numeric-owner -c . |
  docker import \
    --change 'ENV LANG=C.UTF-8 PATH=/usr/local/sbin:/usr/local/bin:/usr/sbin:/usr/bin:/sbin:/bin PIP_CERT=/etc/ssl/certs/ca-certificates.crt' \
    --change 'CMD ["python3"]' \
    - "$tag" >&2
echo "$tag"
