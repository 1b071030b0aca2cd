#!/bin/sh
# The openrails-bridge image (services/Dockerfile, SERVICE=openrails-bridge): a participant over
# OpenRails' web API (real or the mock; OPENRAILS_BRIDGE_OPENRAILS_URL, default
# http://127.0.0.1:2150). Port 50061.
set -eu
PACKAGES="openrails-bridge"

build() { :; } # OpenRails' sensor configuration of the perception variant: scenarios/railway

start() {
  export OPENRAILS_BRIDGE_HOST="${OPENRAILS_BRIDGE_HOST:-0.0.0.0}"
  exec python -m openrails_bridge "$@"
}

health() { # SERVING once OpenRails answers, NOT_SERVING with the reason before
  exec python -m coupler.health "grpc://127.0.0.1:${OPENRAILS_BRIDGE_HEALTH_PORT:-${OPENRAILS_BRIDGE_PORT:-50061}}"
}

if [ $# -gt 0 ]; then "$@"; fi
