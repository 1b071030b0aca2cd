#!/usr/bin/env bash
# The Swarm check (CI, `make swarm-check`): the railway scenario deployed with
# `docker stack deploy` from compose.yaml + compose.tls.yaml + compose.swarm.yaml on a
# one-node swarm, over mutual TLS with the certificates and the token as docker secrets, must
# give the same balise sequence as the scenario run as local processes.
#
#   1. engine: as the compose check (Debian's docker.io; dockerd with address pools from the
#      benchmarking range 198.18.0.0/15 when started here)
#   2. swarm: `docker swarm init` on this node (127.0.0.1; overlay pool 198.19.64.0/18) unless
#      it is in a swarm already; the node labelled coupler.openrails=true (the bridge's placement)
#   3. host artifacts, base images, every image built (as the compose check; shared steps in
#      scripts/lib/containers.sh)
#   4. a development PKI (coupler_dev.devcerts: CA, participant and orchestrator certificates, token)
#   5. the stack file: `docker stack config` of compose.yaml, compose.loopback.yaml (servers on
#      127.0.0.1), compose.tls.yaml and compose.swarm.yaml, every service on the host's network
#      (test traffic stays on loopback) and without the map's published port (none under host
#      networking)
#   6. the scenario as local processes (scripts/fleet.py --exit), unpaced
#   7. `docker stack deploy`; wait until the orchestrator's task is Complete (or Failed);
#      its /results copied out
#   8. assertions: task Complete with exit 0, results.csv and summary.json, status completed,
#      the balise sequence equal to the local run's (and whether byte-identical)
#
# When the engine or the swarm cannot start it prints "swarm-check: SKIPPED: <why>" and exits 0;
# any failure after that exits 1 with the services' tasks and logs. On every exit: `docker
# stack rm`, its volume and secrets removed, the swarm left (if initialized here), the dockerd
# started here stopped (by pid).
#
# Environment: SWARM_CHECK_OUT (default build/swarm-check), SWARM_CHECK_CA (as COMPOSE_CHECK_CA),
# SWARM_CHECK_TIMEOUT (s, the orchestrator's task; default 600), the ports of the compose check
# and BRIDGE_HEALTH_PORT, BALISE_HEALTH_PORT, MAP_HEALTH_PORT (the plaintext health-only ports).
set -euo pipefail
cd "$(dirname "$0")/.."

CHECK=swarm-check
STACK=coupler-check
OUT=${SWARM_CHECK_OUT:-build/swarm-check}
RUN_TIMEOUT=${SWARM_CHECK_TIMEOUT:-600}
CHECK_CA=${SWARM_CHECK_CA:-}
export BRIDGE_HEALTH_PORT=${BRIDGE_HEALTH_PORT:-15081} BALISE_HEALTH_PORT=${BALISE_HEALTH_PORT:-15082}
export MAP_HEALTH_PORT=${MAP_HEALTH_PORT:-15083}
# shellcheck source=scripts/lib/containers.sh
source scripts/lib/containers.sh

SWARM_STARTED=""
SERVICES=(openrails-mock openrails-bridge balise-fmu mapserver orchestrator)

on_failure() {
  docker stack ps "$STACK" --no-trunc --format '{{.Name}} {{.CurrentState}} {{.Error}}' 2>&1
  for service in "${SERVICES[@]}"; do
    echo "--- $service"
    docker service logs --no-task-ids --tail 60 "${STACK}_$service" 2>&1
  done
}
remove_stack() {
  if docker stack ls --format '{{.Name}}' 2>/dev/null | grep -qx "$STACK"; then
    docker stack rm "$STACK" >/dev/null 2>&1
    # the stack's containers go asynchronously; its volume can go only after them
    for _ in $(seq 60); do
      [[ -z $(docker ps -aq --filter "label=com.docker.stack.namespace=$STACK") ]] && break
      sleep 0.5
    done
  fi
  docker volume rm "${STACK}_results" >/dev/null 2>&1 || true
}
on_exit() {
  remove_stack
  if [[ -n $SWARM_STARTED ]]; then
    say "leaving the swarm started here"
    docker swarm leave --force >/dev/null 2>&1
  fi
}

# --- 1. the engine: a failure here skips the check -----------------------------------------
stage engine
engine_up --bip 198.19.0.1/24 --default-address-pool base=198.19.128.0/17,size=24

# --- 2. a one-node swarm: a failure here skips the check too -------------------------------
stage swarm
case $(docker info --format '{{.Swarm.LocalNodeState}}') in
  active)
    [[ $(docker info --format '{{.Swarm.ControlAvailable}}') == true ]] ||
      skip "this engine is a swarm worker; the check needs a manager"
    say "this engine is a swarm manager already; deploying there"
    ;;
  *)
    if ! error=$(docker swarm init --advertise-addr 127.0.0.1 --listen-addr 127.0.0.1:2377 \
        --default-addr-pool 198.19.64.0/18 2>&1); then
      skip "docker swarm init failed: $error"
    fi
    SWARM_STARTED=1
    ;;
esac
docker node update --label-add coupler.openrails=true "$(docker info --format '{{.Swarm.NodeID}}')" \
  >/dev/null
say "swarm: node $(docker info --format '{{.Swarm.NodeID}}') labelled coupler.openrails=true"
# From here on, every failure fails the check.
remove_stack
rm -rf "$OUT/local" "$OUT/container" "$OUT/local-logs" "$OUT/pki"
mkdir -p "$OUT/local" "$OUT/container"
build_ca

# --- 3. artifacts, base images, images ------------------------------------------------------
stage artifacts
host_artifacts "$BRIDGE_HEALTH_PORT" "$BALISE_HEALTH_PORT" "$MAP_HEALTH_PORT"
stage base-image
bash scripts/base-image.sh
stage build
loopback_compose "$OUT/compose.build.yaml"
docker-compose -p "$STACK" -f "$OUT/compose.build.yaml" build --parallel --force-rm \
  >"$OUT/build.log" 2>&1 || { tail -n 40 "$OUT/build.log"; exit 1; }

# --- 4. certificates and token: docker secrets ----------------------------------------------
stage pki
"$UV" run --frozen python -m coupler_dev.devcerts "$OUT/pki"
export COUPLER_PKI=$OUT/pki

# --- 5. the stack file ----------------------------------------------------------------------
stage stack-file
docker stack config -c compose.yaml -c compose.loopback.yaml -c compose.tls.yaml \
  -c compose.swarm.yaml 2>"$OUT/stack-config.log" | python3 -c '
import sys, yaml
stack = yaml.safe_load(sys.stdin)
for service in stack["services"].values():
    for key in ("build", "network_mode", "ports"):
        service.pop(key, None)
    service["networks"] = ["hostnet"]
stack["networks"] = {"hostnet": {"external": True, "name": "host"}}
yaml.safe_dump(stack, sys.stdout, sort_keys=False)' >"$OUT/stack.yaml"
say "stack file: $OUT/stack.yaml"

# --- 6. the scenario as local processes -----------------------------------------------------
stage local-run
local_run "$OUT/local"

# --- 7. the stack ---------------------------------------------------------------------------
stage deploy
docker stack deploy --resolve-image never -c "$OUT/stack.yaml" "$STACK"
stage stack-run
deadline=$((SECONDS + RUN_TIMEOUT))
state=""
while ((SECONDS < deadline)); do
  state=$(docker service ps "${STACK}_orchestrator" --no-trunc --format '{{.CurrentState}}' |
    head -n1)
  case $state in
    Complete* | Failed* | Rejected* | Shutdown*) break ;;
  esac
  sleep 1
done
say "orchestrator task: ${state:-none}"
orchestrator=$(docker ps -aq --filter "label=com.docker.swarm.service.name=${STACK}_orchestrator" |
  head -n1)
[[ -n $orchestrator ]] || { say "no orchestrator container was created"; exit 1; }
docker logs "$orchestrator" 2>&1 | tail -n 5
docker cp "$orchestrator:/results/." "$OUT/container/"
exited=$(docker inspect --format '{{.State.ExitCode}}' "$orchestrator")
if [[ $state != Complete* || $exited -ne 0 ]]; then
  say "the stack's run failed: task ${state:-not finished in $RUN_TIMEOUT s}, exit $exited"
  exit 1
fi
# the participants ran as swarm services with their TLS secrets and healthchecks
for service in openrails-bridge balise-fmu mapserver; do
  container=$(docker ps -q --filter "label=com.docker.swarm.service.name=${STACK}_$service")
  health=$(docker inspect --format '{{.State.Health.Status}}' "$container")
  secrets=$(docker exec "$container" ls /run/secrets | tr '\n' ' ')
  say "$service: $health; /run/secrets: $secrets"
  [[ $health == healthy ]] || { say "$service is not healthy"; exit 1; }
done

# --- 8. the same balise sequence ------------------------------------------------------------
stage compare
compare_runs "$OUT/local" "$OUT/container"
stage done
say "PASSED"
