#!/usr/bin/env bash
# The container check (CI, `make compose-check`): the railway scenario from real containers
# must give the same balise sequence as the same scenario run as local processes.
#
#   1. engine: Debian's docker.io and docker-compose when missing, dockerd when not running
#   2. host artifacts: FMUs and Leaflet (`make setup` when missing)
#   3. local stand-ins for the registry images (scripts/base-image.sh: debootstrap, cached)
#   4. every image built (compose.yaml + compose.loopback.yaml: host network, loopback only)
#   5. the scenario as local processes (scripts/fleet.py --exit), unpaced
#   6. the scenario from the containers (`up --exit-code-from orchestrator`), unpaced
#   7. assertions: exit 0, results.csv and summary.json, status completed, and the
#      TrackBalises.last_balise_id / balises_passed sequence equal to the local run's
#
# When the engine cannot be installed or started it prints "compose-check: SKIPPED: <why>"
# and exits 0 so the rest of CI runs; any failure after that exits 1 with the service logs.
# Everything started here is stopped on the way out (compose down -v, our dockerd by pid).
#
# Environment: COMPOSE_CHECK_OUT (default build/compose-check), COMPOSE_CHECK_CA (CA bundle
# for the image builds behind a TLS-intercepting proxy; default: the host's bundle, "none" to
# build without), COMPOSE_CHECK_TIMEOUT (s, the container run; default 600), MOCK_PORT,
# BRIDGE_PORT, BALISE_PORT, MAP_PORT, MAP_HTTP_PORT (defaults away from the usual ones, so a
# developer's `make demo` does not collide).
set -euo pipefail
cd "$(dirname "$0")/.."

PROJECT=coupler-check
OUT=${COMPOSE_CHECK_OUT:-build/compose-check}
RUN_TIMEOUT=${COMPOSE_CHECK_TIMEOUT:-600}
export MOCK_PORT=${MOCK_PORT:-12150} BRIDGE_PORT=${BRIDGE_PORT:-15061}
export BALISE_PORT=${BALISE_PORT:-15062} MAP_PORT=${MAP_PORT:-15071}
export MAP_HTTP_PORT=${MAP_HTTP_PORT:-18080}
export OPENRAILS_URL=http://127.0.0.1:$MOCK_PORT
export COUPLER_TAG=check RUN_ARGS=""
UV=$(command -v uv || echo .venv-uv/bin/uv)

START=$SECONDS
STAGE_START=$SECONDS
TIMINGS=()
DOCKERD_PID=""
ENGINE_UP=""

say() { echo "compose-check: $*"; }
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
# The scenario's compose files, merged (compose.yaml + compose.loopback.yaml) and without the
# map's published port: docker-compose 1.29 refuses `ports` under host networking, and an
# override cannot remove a list before Compose v2.24 (`!reset`).
loopback_config() {
  docker-compose -f compose.yaml -f compose.loopback.yaml config | python3 -c '
import sys, yaml
config = yaml.safe_load(sys.stdin)
for service in config["services"].values():
    if service.get("network_mode") == "host":
        service.pop("ports", None)
yaml.safe_dump(config, sys.stdout, sort_keys=False)' >"$OUT/compose.loopback.merged.yaml"
}
compose() { docker-compose -p "$PROJECT" -f "$OUT/compose.loopback.merged.yaml" "$@"; }

cleanup() {
  local code=$?
  set +e
  if [[ -n $ENGINE_UP ]]; then
    if [[ $code -ne 0 ]]; then
      say "FAILED (exit $code); service logs follow"
      compose logs --no-color --tail=200 2>&1
      for log in "$OUT"/local-logs/*.log; do
        [[ -f $log ]] && { echo "--- local $log"; tail -n 30 "$log"; }
      done
    fi
    compose down -v --remove-orphans >/dev/null 2>&1
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
trap cleanup EXIT

# --- 1. the engine: a failure here skips the check -----------------------------------------
stage engine
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
  setsid dockerd >"$OUT/dockerd.log" 2>&1 &
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
# From here on, every failure fails the check.
rm -rf "$OUT/local" "$OUT/container" "$OUT/local-logs"
mkdir -p "$OUT/local" "$OUT/container"
# The CA bundle for builds behind a TLS-intercepting proxy: the build stage only (see the
# Dockerfiles); the images never contain it.
CA=${COMPOSE_CHECK_CA:-${SSL_CERT_FILE:-/etc/ssl/certs/ca-certificates.crt}}
if [[ $CA != none && -f $CA ]]; then
  mkdir -p build/ca && cp "$CA" build/ca/ca-certificates.crt
  export CA_CERTS=build/ca/ca-certificates.crt
  say "builds trust the CA bundle $CA (build argument CA_CERTS)"
else
  export CA_CERTS=""
fi
loopback_config
compose down -v --remove-orphans >/dev/null 2>&1 || true

# --- 2. host artifacts the images copy ------------------------------------------------------
stage artifacts
if [[ ! -f build/fmus/Driver2.fmu || ! -f build/fmus/TrackBalises.fmu ||
      ! -f services/mapserver/src/mapserver/static/vendor/leaflet/leaflet.js ]]; then
  make setup
fi
python3 - "$MOCK_PORT" "$BRIDGE_PORT" "$BALISE_PORT" "$MAP_PORT" "$MAP_HTTP_PORT" <<'EOF'
import socket, sys
taken = []
for port in map(int, sys.argv[1:]):
    with socket.socket() as s:
        s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)  # as servers do: TIME_WAIT is fine
        try:
            s.bind(("127.0.0.1", port))
        except OSError:
            taken.append(port)
if taken:
    sys.exit(f"compose-check: ports {taken} on 127.0.0.1 are in use; set MOCK_PORT, BRIDGE_PORT, "
             "BALISE_PORT, MAP_PORT, MAP_HTTP_PORT to free ones")
EOF

# --- 3. base images -------------------------------------------------------------------------
stage base-image
bash scripts/base-image.sh

# --- 4. images ------------------------------------------------------------------------------
stage build
compose build --parallel --force-rm
docker image ls --format '{{.Repository}}:{{.Tag}} {{.Size}}' | grep "^coupler/.*:$COUPLER_TAG " || true

# --- 5. the scenario as local processes -----------------------------------------------------
stage local-run
# The fleet file with the check's ports (the SSD takes them from the environment), run
# unpaced like the containers (fleet.toml paces the demo at 20x real time).
sed -e "s/\b2150\b/$MOCK_PORT/g; s/\b50061\b/$BRIDGE_PORT/g; s/\b50062\b/$BALISE_PORT/g" \
    -e "s/\b50071\b/$MAP_PORT/g; s/\b8080\b/$MAP_HTTP_PORT/g" \
    scenarios/railway/fleet.toml >"$OUT/fleet.toml"
"$UV" run --frozen python scripts/fleet.py "$OUT/fleet.toml" --exit --realtime-factor 0 \
    --out "$OUT/local" ||
  { mkdir -p "$OUT/local-logs" && cp build/logs/*.log "$OUT/local-logs/" 2>/dev/null; exit 1; }

# --- 6. the scenario from the containers ----------------------------------------------------
stage container-run
code=0
timeout "$RUN_TIMEOUT" docker-compose -p "$PROJECT" -f "$OUT/compose.loopback.merged.yaml" \
  up --no-color --exit-code-from orchestrator >"$OUT/compose-up.log" 2>&1 || code=$?
tail -n 5 "$OUT/compose-up.log"
orchestrator=$(docker ps -aq --filter "label=com.docker.compose.project=$PROJECT" \
  --filter "label=com.docker.compose.service=orchestrator" | head -n1)
[[ -n $orchestrator ]] || { say "no orchestrator container was created"; exit 1; }
docker cp "$orchestrator:/results/." "$OUT/container/"
exited=$(docker inspect --format '{{.State.ExitCode}}' "$orchestrator")
if [[ $code -ne 0 || $exited -ne 0 ]]; then
  say "the container run failed: compose up exit $code, orchestrator exit $exited"
  exit 1
fi

# --- 7. the same balise sequence ------------------------------------------------------------
stage compare
python3 - "$OUT/local" "$OUT/container" <<'EOF'
import csv, json, sys
from pathlib import Path

COLUMNS = ("TrackBalises.last_balise_id", "TrackBalises.balises_passed")

def load(folder: Path) -> tuple[list[tuple[str, ...]], list[tuple[str, ...]]]:
    for name in ("results.csv", "summary.json"):
        if not (folder / name).is_file():
            sys.exit(f"compose-check: {folder / name} is missing")
    summary = json.loads((folder / "summary.json").read_text())
    if summary.get("status") != "completed":
        sys.exit(f"compose-check: {folder}: status {summary.get('status')!r}, "
                 f"reason {summary.get('reason')!r}")
    with (folder / "results.csv").open(newline="") as f:
        rows = list(csv.DictReader(f))
    missing = [c for c in COLUMNS if rows and c not in rows[0]]
    if not rows or missing:
        sys.exit(f"compose-check: {folder}/results.csv has no rows or lacks {missing}")
    columns = [tuple(r[c] for c in COLUMNS) for r in rows]
    # The balise sequence: each change of (last balise, count), with the time it happened.
    sequence, last = [], None
    for row, value in zip(rows, columns):
        if value != last:
            sequence.append((row["time"], *value))
            last = value
    return columns, sequence

local_columns, local_seq = load(Path(sys.argv[1]))
container_columns, container_seq = load(Path(sys.argv[2]))
passed = int(local_seq[-1][2] or 0)
print(f"compose-check: local run: {len(local_columns)} rows, {passed} balises passed; "
      f"container run: {len(container_columns)} rows, {container_seq[-1][2]} passed")
if passed == 0:
    sys.exit("compose-check: the local run passed no balise; nothing to compare")
if [s[1:] for s in local_seq] != [s[1:] for s in container_seq]:
    for i, (a, b) in enumerate(zip(local_seq, container_seq)):
        if a[1:] != b[1:]:
            sys.exit(f"compose-check: balise sequences differ at reading {i}: local (time, id, "
                     f"passed) {a} vs container {b} ({len(local_seq)} vs {len(container_seq)})")
    sys.exit(f"compose-check: balise sequences differ in length: {len(local_seq)} local vs "
             f"{len(container_seq)} container readings")
same_times = local_seq == container_seq and local_columns == container_columns
print(f"compose-check: the same balise sequence ({len(local_seq) - 1} readings, "
      f"ids {local_seq[1][1]} .. {local_seq[-1][1]})"
      + ("; identical at every step" if same_times else "; passage times differ"))
EOF
if cmp -s "$OUT/local/results.csv" "$OUT/container/results.csv"; then
  say "results.csv of the two runs are byte-identical (every channel, every step)"
else
  say "results.csv of the two runs differ outside the balise columns (see $OUT)"
fi
stage done
say "PASSED"
