#!/bin/sh
# The mapserver image (services/Dockerfile, SERVICE=mapserver): a participant (inputs only) and
# the live web map of the run. Ports 50071 (gRPC), 8080 (the map).
set -eu
PACKAGES="mapserver"

build() { # in the build stage, in /app: Leaflet, copied on the host (`make assets`)
  test -f services/mapserver/src/mapserver/static/vendor/leaflet/leaflet.js || {
    echo "Dockerfile: services/mapserver/src/mapserver/static/vendor/leaflet is missing: run 'make assets' (or 'make setup') on the host first" >&2
    exit 1
  }
}

start() {
  export MAPSERVER_GRPC_HOST="${MAPSERVER_GRPC_HOST:-0.0.0.0}"
  export MAPSERVER_HTTP_HOST="${MAPSERVER_HTTP_HOST:-0.0.0.0}"
  export MAPSERVER_RAILML="${MAPSERVER_RAILML:-/app/scenarios/railway/data/annaberg-schwarzenberg.railml}"
  exec python -m mapserver "$@"
}

health() { # the participant's standard gRPC health service (the web app starts with it)
  exec python -m coupler.health "grpc://127.0.0.1:${MAPSERVER_HEALTH_PORT:-${MAPSERVER_GRPC_PORT:-50071}}"
}

if [ $# -gt 0 ]; then "$@"; fi
