#!/bin/sh
# The balise-fmu image (services/Dockerfile, SERVICE=balise-fmu): the FMU host participant with
# the TrackBalises FMU (any FMU: BALISE_FMU_FMU=/path). Port 50062.
set -eu
PACKAGES="balise-fmu"

build() { # in the build stage, in /app: the FMU, built on the host (`make track-fmu`)
  test -f /tmp/host/TrackBalises.fmu || {
    echo "Dockerfile: build/fmus/TrackBalises.fmu is missing: run 'make track-fmu' (or 'make setup') on the host first" >&2
    exit 1
  }
  mkdir -p build/fmus && mv /tmp/host/TrackBalises.fmu build/fmus/
}

start() {
  export BALISE_FMU_HOST="${BALISE_FMU_HOST:-0.0.0.0}"
  export BALISE_FMU_FMU="${BALISE_FMU_FMU:-/app/build/fmus/TrackBalises.fmu}"
  export BALISE_FMU_NAME="${BALISE_FMU_NAME:-TrackBalises}"
  exec python -m balise_fmu "$@"
}

health() { # the standard gRPC health service (with TLS: its plaintext health-only port)
  exec python -m coupler.health "grpc://127.0.0.1:${BALISE_FMU_HEALTH_PORT:-${BALISE_FMU_PORT:-50062}}"
}

if [ $# -gt 0 ]; then "$@"; fi
