#!/usr/bin/env bash
# Local stand-ins for the two registry images services/Dockerfile starts from, for machines that
# reach no container registry:
#
#   python:3.11-slim            Debian bookworm (minbase) + python3 3.11, from debootstrap
#   ghcr.io/astral-sh/uv:VER    the host's uv binary at /uv (VER = services/Dockerfile's default)
#
# Tagged with the names services/Dockerfile uses, so it builds unchanged (a local image is used
# before any pull). Each is skipped when `docker image inspect` already finds it; the
# debootstrap tarball is cached in $COUPLER_CACHE (default ~/.cache/coupler).
#
#   bash scripts/base-image.sh            # both, when missing
#   FORCE=1 bash scripts/base-image.sh    # rebuild both
set -euo pipefail
cd "$(dirname "$0")/.."

DOCKER=${DOCKER:-docker}
BASE_TAG=${BASE_TAG:-python:3.11-slim}
SUITE=${SUITE:-bookworm}
MIRROR=${DEBIAN_MIRROR:-http://deb.debian.org/debian}
CACHE=${COUPLER_CACHE:-${HOME:-/root}/.cache/coupler}
TARBALL="$CACHE/rootfs-$SUITE-python3.tar"
# The uv image services/Dockerfile names by default (ARG UV_IMAGE=...).
UV_TAG=${UV_TAG:-$(sed -n 's/^ARG UV_IMAGE=//p' services/Dockerfile | head -n1)}

say() { echo "base-image: $*"; }
have() { [[ -z ${FORCE:-} ]] && "$DOCKER" image inspect "$1" >/dev/null 2>&1; }

base_image() {
  if have "$BASE_TAG"; then
    say "$BASE_TAG present, skipped"
    return
  fi
  if [[ ! -s $TARBALL || -n ${FORCE:-} ]]; then
    command -v debootstrap >/dev/null || {
      say "installing debootstrap"
      DEBIAN_FRONTEND=noninteractive apt-get install -y -qq debootstrap >/dev/null
    }
    local rootfs
    rootfs=$(mktemp -d /tmp/coupler-rootfs.XXXXXX)
    say "debootstrap $SUITE (minbase + python3) into $rootfs"
    # The same contents as the official slim image where it matters: python3 (3.11 on
    # bookworm), ca-certificates; no compilers (the FMUs are built on the host).
    debootstrap --variant=minbase --include=python3,python3-venv,ca-certificates \
      "$SUITE" "$rootfs" "$MIRROR" >"$CACHE.debootstrap.log" 2>&1 || {
        tail -n 20 "$CACHE.debootstrap.log" >&2
        rm -rf "$rootfs"
        return 1
      }
    # Slim it: apt lists, docs, man pages and caches are no use in an image.
    rm -rf "$rootfs"/var/lib/apt/lists/* "$rootfs"/var/cache/apt/*.bin \
      "$rootfs"/var/cache/apt/archives/*.deb "$rootfs"/usr/share/doc/* "$rootfs"/usr/share/man/*
    # The official image's `python` and `python3` are on PATH; give this one both as well.
    ln -sf python3 "$rootfs/usr/bin/python"
    mkdir -p "$CACHE"
    tar -C "$rootfs" --numeric-owner -cf "$TARBALL.tmp" .
    mv "$TARBALL.tmp" "$TARBALL"
    rm -rf "$rootfs"
  fi
  say "importing $TARBALL as $BASE_TAG"
  "$DOCKER" import \
    --change 'ENV PATH=/usr/local/sbin:/usr/local/bin:/usr/sbin:/usr/bin:/sbin:/bin' \
    --change 'ENV LANG=C.UTF-8' \
    --change 'CMD ["python3"]' \
    "$TARBALL" "$BASE_TAG" >/dev/null
}

uv_image() {
  if [[ -z $UV_TAG ]]; then
    say "no 'ARG UV_IMAGE=' in services/Dockerfile" >&2
    return 1
  fi
  if have "$UV_TAG"; then
    say "$UV_TAG present, skipped"
    return
  fi
  local uv want got dir
  uv=$(command -v uv || echo .venv-uv/bin/uv)
  # A version manager's shim is a script; the image needs the binary itself.
  if command -v pyenv >/dev/null && pyenv which uv >/dev/null 2>&1; then uv=$(pyenv which uv); fi
  uv=$(readlink -f "$uv")
  want=${UV_TAG##*:}
  got=$("$uv" --version | awk '{print $2}')
  if [[ $got != "$want" || $(head -c 4 "$uv" | tr -d '\0') != $'\x7fELF' ]]; then
    say "host uv is $got ($uv), services/Dockerfile wants $want: installing uv==$want into build/uv"
    python3 -m venv build/uv && build/uv/bin/pip install --quiet "uv==$want"
    uv=$(readlink -f build/uv/bin/uv)
  fi
  dir=$(mktemp -d /tmp/coupler-uv.XXXXXX)
  cp "$uv" "$dir/uv"
  if [[ -x $(dirname "$uv")/uvx ]]; then cp "$(dirname "$uv")/uvx" "$dir/uvx"; fi
  say "importing uv $want as $UV_TAG"
  tar -C "$dir" -c . | "$DOCKER" import - "$UV_TAG" >/dev/null
  rm -rf "$dir"
}

base_image
uv_image
