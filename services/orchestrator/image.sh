#!/bin/sh
# The orchestrator image (services/Dockerfile, SERVICE=orchestrator): the `coupler` CLI with the
# railway scenario and its in-process FMUs, and the railway's message types (coupler-railway's
# `coupler.messages` entry point: train states are written to results.csv as JSON, as in a
# local run). It compiles nothing (no compiler in the image), yet steps natively: the wheel
# bundles what its native FMU step, step channel and exported-FMU binaries load.
set -eu
PACKAGES="coupler-orchestrator coupler-railway"

build() { # in the build stage, in /app: coupler-native's wheel and the FMUs, built on the host
  ls /tmp/host/coupler_native-*.whl >/dev/null 2>&1 || {
    echo "Dockerfile: build/wheels/coupler_native-*.whl is missing: run 'make wheels' on the host first" >&2
    exit 1
  }
  uv pip install --python /app/.venv/bin/python --no-deps --no-index /tmp/host/coupler_native-*.whl
  for f in Driver2.fmu; do
    test -f "/tmp/host/$f" || {
      echo "Dockerfile: build/fmus/$f is missing: run 'make fmus track-fmu' (or 'make setup') on the host first" >&2
      exit 1
    }
  done
  mkdir -p build/fmus && mv /tmp/host/*.fmu build/fmus/
}

start() {
  # Each run writes a folder of its own in the volume: /results/<scenario>/<UTC time>-<run
  # id>/, /results/<scenario>/latest linking to the newest (docs/orchestrator.md).
  export COUPLER_RESULTS_DIR="${COUPLER_RESULTS_DIR:-/results}"
  if [ $# -eq 0 ]; then set -- run scenarios/railway/SystemStructure.ssd --no-progress; fi
  exec coupler "$@"
}

health() { exit 0; } # a run, not a server: its participants' health is what it waits for

if [ $# -gt 0 ]; then "$@"; fi
