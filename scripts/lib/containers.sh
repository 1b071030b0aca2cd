# Shared by the container checks (scripts/compose-check.sh, scripts/swarm-check.sh); sourced.
#
# The caller sets CHECK (its name in messages) and OUT (its output folder) and may define
# `on_failure` (print its logs) and `on_exit` (stop what it started); the EXIT trap here calls
# them, stops the dockerd this check started (by pid) and prints the stage timings.
# Ports (MOCK_PORT, BRIDGE_PORT, BALISE_PORT, PERCEPTION_PORT, MAP_PORT, MAP_HTTP_PORT) default
# away from the usual ones, so a developer's `make demo` does not collide.

export MOCK_PORT=${MOCK_PORT:-12150} BRIDGE_PORT=${BRIDGE_PORT:-15061}
export BALISE_PORT=${BALISE_PORT:-15062} MAP_PORT=${MAP_PORT:-15071}
export PERCEPTION_PORT=${PERCEPTION_PORT:-15063}
export MAP_HTTP_PORT=${MAP_HTTP_PORT:-18080}
export OPENRAILS_URL=http://127.0.0.1:$MOCK_PORT
export COUPLER_TAG=check RUN_ARGS=""
UV=$(command -v uv || echo .venv-uv/bin/uv)

START=$SECONDS
STAGE_START=$SECONDS
TIMINGS=()
DOCKERD_PID=""
ENGINE_UP=""

say() { echo "$CHECK: $*"; }
skip() {
  say "SKIPPED: $*"
  exit 0
}
stage() {
  if [[ -n ${STAGE:-} ]]; then TIMINGS+=("$STAGE $((SECONDS - STAGE_START)) s"); fi
  STAGE=$1
  STAGE_START=$SECONDS
  say "== $1"
}

_cleanup() {
  local code=$?
  set +e
  if [[ -n $ENGINE_UP ]]; then
    if [[ $code -ne 0 ]]; then
      say "FAILED (exit $code); logs follow"
      declare -F on_failure >/dev/null && on_failure
      for log in "$OUT"/local-logs/*.log; do
        [[ -f $log ]] && { echo "--- local $log"; tail -n 30 "$log"; }
      done
    fi
    declare -F on_exit >/dev/null && on_exit
  fi
  if [[ -n $DOCKERD_PID ]]; then
    say "stopping the dockerd started here (pid $DOCKERD_PID)"
    kill "$DOCKERD_PID" 2>/dev/null
    for _ in $(seq 50); do kill -0 "$DOCKERD_PID" 2>/dev/null || break; sleep 0.2; done
    kill -9 "$DOCKERD_PID" 2>/dev/null
  fi
  [[ -n ${STAGE:-} ]] && TIMINGS+=("$STAGE $((SECONDS - STAGE_START)) s")
  if [[ ${#TIMINGS[@]} -gt 0 ]]; then
    say "timings: $(IFS=';'; echo "${TIMINGS[*]}" | sed 's/;/, /g'); total $((SECONDS - START)) s"
  fi
  exit "$code"
}
trap _cleanup EXIT

# The engine: Debian's docker.io and docker-compose when missing, dockerd when none runs (with
# the arguments given: the caller's address pools). Any failure here skips the check.
engine_up() {
  if ! command -v docker-compose >/dev/null || ! command -v dockerd >/dev/null; then
    [[ $(id -u) -eq 0 ]] || skip "docker.io/docker-compose are missing and this is not root"
    command -v apt-get >/dev/null || skip "docker.io/docker-compose are missing and there is no apt-get"
    say "installing Debian's docker.io and docker-compose"
    { apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq \
        docker.io docker-compose >/dev/null; } 2>&1 | tail -n 5 ||
      skip "apt-get could not install docker.io docker-compose"
    command -v docker-compose >/dev/null || skip "docker-compose is still missing after apt-get"
  fi
  command -v docker >/dev/null || skip "no docker client on PATH"
  if ! docker info >/dev/null 2>&1; then
    [[ $(id -u) -eq 0 ]] || skip "no Docker engine is running and this is not root to start one"
    mkdir -p "$OUT"
    say "starting dockerd (log: $OUT/dockerd.log)"
    setsid dockerd "$@" >"$OUT/dockerd.log" 2>&1 &
    DOCKERD_PID=$!
    for _ in $(seq 60); do
      docker info >/dev/null 2>&1 && break
      kill -0 "$DOCKERD_PID" 2>/dev/null || break
      sleep 0.5
    done
    if ! docker info >/dev/null 2>&1; then
      reason=$(tail -n 3 "$OUT/dockerd.log" | tr '\n' ' ')
      kill "$DOCKERD_PID" 2>/dev/null || true
      DOCKERD_PID=""
      skip "dockerd did not start: $reason"
    fi
  fi
  ENGINE_UP=1
  say "engine: Docker $(docker version --format '{{.Server.Version}}'), $(docker-compose version --short)"
}

# The CA bundle for image builds behind a TLS-intercepting proxy: the build stage only (see the
# Dockerfile); the images never contain it. ${CHECK_CA}: a bundle, "none", or the host's.
build_ca() {
  local ca=${CHECK_CA:-${SSL_CERT_FILE:-/etc/ssl/certs/ca-certificates.crt}}
  if [[ $ca != none && -f $ca ]]; then
    mkdir -p build/ca && cp "$ca" build/ca/ca-certificates.crt
    export CA_CERTS=build/ca/ca-certificates.crt
    say "builds trust the CA bundle $ca (build argument CA_CERTS)"
  else
    export CA_CERTS=""
  fi
}

# FMUs, Leaflet and coupler-native's wheel (the images copy them), and the check's ports free
# on 127.0.0.1.
host_artifacts() {
  if [[ ! -f build/fmus/Driver2.fmu || ! -f build/fmus/TrackBalises.fmu ||
        ! -f services/mapserver/src/mapserver/static/vendor/leaflet/leaflet.js ]]; then
    make setup
  fi
  make --no-print-directory wheels
  python3 - "$CHECK" "$MOCK_PORT" "$BRIDGE_PORT" "$BALISE_PORT" "$PERCEPTION_PORT" "$MAP_PORT" \
      "$MAP_HTTP_PORT" \
      "$@" <<'PY'
import socket, sys
taken = []
for port in map(int, sys.argv[2:]):
    with socket.socket() as s:
        s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)  # as servers do: TIME_WAIT is fine
        try:
            s.bind(("127.0.0.1", port))
        except OSError:
            taken.append(port)
if taken:
    sys.exit(f"{sys.argv[1]}: ports {taken} on 127.0.0.1 are in use; set MOCK_PORT, BRIDGE_PORT, "
             "BALISE_PORT, PERCEPTION_PORT, MAP_PORT, MAP_HTTP_PORT to free ones")
PY
}

# The railway scenario as local processes with the check's ports, unpaced, into $1.
local_run() {
  local out=$1
  # The fleet file takes the check's ports from the exported *_PORT variables (as the SSD
  # does); run unpaced like the containers (fleet.toml paces the demo at 20x real time).
  "$UV" run --frozen python scripts/fleet.py scenarios/railway/fleet.toml --exit \
      --realtime-factor 0 --out "$out" ||
    { mkdir -p "$OUT/local-logs" && cp -r build/logs/. "$OUT/local-logs/" 2>/dev/null; exit 1; }
}

# Local and container results: the same balise sequence, and whether byte-identical. $2 is the
# orchestrator's /results copied out: its run's folder is railway/latest (a folder per run).
compare_runs() {
  local local_run=$1 container_run=$2/railway/latest
  python3 scripts/compare-runs.py "$CHECK" "$local_run" "$container_run"
  if cmp -s "$local_run/results.csv" "$container_run/results.csv"; then
    say "results.csv of the two runs are byte-identical (every channel, every step)"
  else
    say "results.csv of the two runs differ outside the balise columns (see $OUT)"
  fi
}

# The scenario's compose files merged for loopback (compose.yaml + compose.loopback.yaml, then
# any further files given), into $1, without the map's published port: docker-compose 1.29
# refuses `ports` under host networking, and an override cannot remove a list before Compose
# v2.24 (`!reset`).
loopback_compose() {
  local out=$1 extra=()
  shift
  for file in "$@"; do extra+=(-f "$file"); done
  docker-compose -f compose.yaml -f compose.loopback.yaml "${extra[@]}" config | python3 -c '
import sys, yaml
config = yaml.safe_load(sys.stdin)
for service in config["services"].values():
    if service.get("network_mode") == "host":
        service.pop("ports", None)
yaml.safe_dump(config, sys.stdout, sort_keys=False)' >"$out"
}
