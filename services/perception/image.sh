#!/bin/sh
# The perception image (services/Dockerfile, SERVICE=perception): balises found in camera
# frames, a system under test. Port 50063.
set -eu
PACKAGES="perception"

build() { :; }

start() {
  # The learned detector's compiled pass is cached where the unprivileged user may write.
  export NUMBA_CACHE_DIR="${NUMBA_CACHE_DIR:-/tmp/numba}"
  export PERCEPTION_HOST="${PERCEPTION_HOST:-0.0.0.0}"
  exec python -m perception "$@"
}

health() { # the standard gRPC health service (with TLS: its plaintext health-only port)
  exec python -m coupler.health "grpc://127.0.0.1:${PERCEPTION_HEALTH_PORT:-${PERCEPTION_PORT:-50063}}"
}

if [ $# -gt 0 ]; then "$@"; fi
