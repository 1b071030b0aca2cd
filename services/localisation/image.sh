#!/bin/sh
# The localisation image (services/Dockerfile, SERVICE=localisation): the balise-based train
# localisation under test and the onboard sensor models that feed it (odometer, balise
# transmission); LOCALISATION_ROLE picks the participant. Ports 50064, 50065, 50066.
set -eu
PACKAGES="localisation"

build() { :; } # the line's railML comes with scenarios/railway

start() {
  export LOCALISATION_HOST="${LOCALISATION_HOST:-0.0.0.0}"
  export LOCALISATION_RAILML="${LOCALISATION_RAILML:-/app/scenarios/railway/data/annaberg-schwarzenberg.railml}"
  exec python -m localisation "$@"
}

health() { # the standard gRPC health service (with TLS: its plaintext health-only port)
  exec python -m coupler.health "grpc://127.0.0.1:${LOCALISATION_HEALTH_PORT:-${LOCALISATION_PORT:-50064}}"
}

if [ $# -gt 0 ]; then "$@"; fi
