#!/bin/sh
# The openrails-mock image (services/Dockerfile, SERVICE=openrails-mock): OpenRails' web API with
# train physics, on the railway scenario's line (the OpenRails route exported from its railML
# file while the image is built). Port 2150.
set -eu
PACKAGES="openrails-mock"

build() {
  /app/.venv/bin/coupler-railway export-openrails \
    scenarios/railway/data/annaberg-schwarzenberg.railml --out routes/annaberg-schwarzenberg
}

start() {
  # The renderer's compiled kernels are cached where the unprivileged user may write.
  export NUMBA_CACHE_DIR="${NUMBA_CACHE_DIR:-/tmp/numba}"
  export OPENRAILS_MOCK_HOST="${OPENRAILS_MOCK_HOST:-0.0.0.0}"
  export OPENRAILS_MOCK_ROUTE="${OPENRAILS_MOCK_ROUTE:-/app/routes/annaberg-schwarzenberg}"
  export OPENRAILS_MOCK_PATH="${OPENRAILS_MOCK_PATH:-PATHS/ocp_ABU-ocp_SZB.pat}"
  exec python -m openrails_mock "$@"
}

health() { # healthy once GET /API/READY answers 200 (425 while the "simulator" loads)
  exec python -c "import sys, urllib.request; urllib.request.urlopen(sys.argv[1], timeout=3)" \
    "http://127.0.0.1:${OPENRAILS_MOCK_PORT:-2150}/API/READY"
}

if [ $# -gt 0 ]; then "$@"; fi
