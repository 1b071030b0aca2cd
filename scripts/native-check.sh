#!/usr/bin/env bash
# The built wheels where nothing can be compiled (CI, `make native-check`):
#
#   1. the wheels (`make wheels`: coupler-native compiled and repaired by auditwheel, coupler)
#   2. a participant written against the coupler wheel alone (scripts/lib/
#      standalone_participant.py in a fresh venv holding only that wheel and its dependencies;
#      the wheel holds no build helper: those are coupler-tools') serves, and the workspace's
#      `coupler run` drives it: the values it answered are right
#   3. engine (scripts/lib), the local base image (scripts/base-image.sh) and the orchestrator
#      image built from it (services/Dockerfile, SERVICE=orchestrator: installs coupler-native's wheel)
#   4. in a container of that image, where no compiler and no system gRPC may be found:
#      `coupler run -v` of the benchmark's in-process FMU chain steps in C (the native FMU
#      step) and of a remote gain participant over the native step channel, as summary.json
#      says; `coupler export-fmu` exports that participant and FMPy runs the FMU
#
# Stage 2 runs without Docker; when the engine cannot be installed or started the rest prints
# "native-check: SKIPPED: <why>" and exits 0; any failure exits 1. Everything started here is
# stopped on the way out. Environment: NATIVE_CHECK_OUT (default build/native-check),
# NATIVE_CHECK_CA (CA bundle for the image build behind a TLS-intercepting proxy; default:
# the host's bundle, "none" to build without).
set -euo pipefail
cd "$(dirname "$0")/.."

CHECK=native-check
OUT=${NATIVE_CHECK_OUT:-build/native-check}
CHECK_CA=${NATIVE_CHECK_CA:-}
IMAGE=coupler/orchestrator:native-check
PARTICIPANT_PID=""
# shellcheck source=scripts/lib/containers.sh
source scripts/lib/containers.sh
on_failure() { [[ -f $OUT/participant.log ]] && tail -n 20 "$OUT/participant.log"; }
stop_participant() {
  [[ -n $PARTICIPANT_PID ]] && kill "$PARTICIPANT_PID" 2>/dev/null
  PARTICIPANT_PID=""
}
# the participant is stopped whether or not the engine came up (the shared trap's on_exit runs
# only once it has); the exit code goes on to the shared trap
trap 'code=$?; stop_participant; (exit $code); _cleanup' EXIT

stage wheels
[[ -x .venv/bin/coupler ]] || make setup
make --no-print-directory wheels
[[ -f build/fmus/Feedthrough2.fmu ]] || make --no-print-directory fmus
rm -rf "$OUT" && mkdir -p "$OUT"
chmod a+rwx "$OUT"
ls -l build/wheels/*.whl | awk '{print "native-check: wheel " $NF " " $5 " bytes"}'

stage standalone-participant
"$UV" venv --quiet --python python3 "$OUT/sdk-venv" 2>/dev/null
"$UV" pip install --quiet --python "$OUT/sdk-venv/bin/python" build/wheels/coupler-*.whl
installed=$("$UV" pip list --python "$OUT/sdk-venv/bin/python" --format freeze 2>/dev/null |
  grep -ci '^coupler' || true)
[[ $installed -eq 1 ]] || { say "the fresh venv holds more than the coupler wheel"; exit 1; }
# the SDK carries no tooling: the FMU builder and the browser files are coupler-tools'
"$OUT/sdk-venv/bin/python" -c 'import importlib.util as u, sys
sys.exit(any(u.find_spec(m) for m in ("coupler.fmubuild", "coupler.vendor", "coupler_tools")))' ||
  { say "the coupler wheel carries the build helpers (coupler.fmubuild, coupler.vendor)"; exit 1; }
"$OUT/sdk-venv/bin/python" scripts/lib/standalone_participant.py "$OUT/sum.port" \
  >"$OUT/participant.log" 2>&1 &
PARTICIPANT_PID=$!
for _ in $(seq 100); do [[ -s $OUT/sum.port ]] && break; sleep 0.2; done
[[ -s $OUT/sum.port ]] || { cat "$OUT/participant.log"; say "the participant did not start"; exit 1; }
cat >"$OUT/sum.ssd" <<SSD
<?xml version="1.0" encoding="UTF-8"?>
<ssd:SystemStructureDescription version="1.0" name="Sum"
    xmlns:ssd="http://ssp-standard.org/SSP1/SystemStructureDescription"
    xmlns:ssc="http://ssp-standard.org/SSP1/SystemStructureCommon">
  <ssd:System name="Sum">
    <ssd:Elements>
      <ssd:Component name="Sum" type="application/x-coupler-grpc"
                     source="grpc://127.0.0.1:$(cat "$OUT/sum.port")">
        <ssd:Connectors>
          <ssd:Connector name="scale" kind="parameter"><ssc:Real/></ssd:Connector>
          <ssd:Connector name="u" kind="input"><ssc:Real/></ssd:Connector>
          <ssd:Connector name="total" kind="output"><ssc:Real/></ssd:Connector>
        </ssd:Connectors>
      </ssd:Component>
    </ssd:Elements>
  </ssd:System>
  <ssd:DefaultExperiment startTime="0" stopTime="1"/>
</ssd:SystemStructureDescription>
SSD
.venv/bin/coupler run "$OUT/sum.ssd" --step 0.125 --param Sum.scale=2 --param Sum.u=1.5 \
  --out "$OUT/sum" --no-progress -v | tee "$OUT/sum.txt"
last=$(tail -n 1 "$OUT/sum/results.csv")
[[ $last == "1.0,24.0" ]] || { say "Sum.total at t=1 is '$last', expected 1.0,24.0"; exit 1; }
stop_participant
say "PASSED: a participant on the coupler wheel alone served 8 steps to coupler run ($last)"

stage engine
engine_up
build_ca

stage image
bash scripts/base-image.sh
docker build --quiet -f services/Dockerfile --build-arg SERVICE=orchestrator \
  --build-arg CA_CERTS="$CA_CERTS" \
  -t "$IMAGE" . >/dev/null
docker image ls --format '{{.Repository}}:{{.Tag}} {{.Size}}' "$IMAGE"

stage container
# the benchmark's chain, with the image's FMUs
.venv/bin/python - "$OUT" <<'PY'
import sys
from pathlib import Path

sys.path.insert(0, "benchmarks")
from sections import common

common.FMUS = Path("/app/build/fmus")
common.chain_ssd(Path(sys.argv[1]), 2)
common.ring_ssd(Path(sys.argv[1]), [int(common.free_ports(1)[0])])
PY
cp scripts/lib/fmpy_run.py "$OUT/"
docker run --rm --network host -v "$PWD/$OUT:/check" --entrypoint sh "$IMAGE" -c '
  set -e
  for compiler in gcc cc g++ c++ clang; do
    if command -v "$compiler" >/dev/null; then echo "the image has a compiler: $compiler" >&2; exit 1; fi
  done
  if ls /usr/lib/x86_64-linux-gnu /usr/lib /usr/local/lib 2>/dev/null | grep -E "^lib(grpc|protobuf)"; then
    echo "the image has gRPC or protobuf installed" >&2; exit 1
  fi
  python -c "import coupler_native, importlib.metadata as m; print(\"coupler-native\", m.version(\"coupler-native\"), coupler_native.__file__)"
  echo "== chain"
  coupler run /check/chain2.ssd --stop-time 20 --step 0.001 --out /tmp/chain --no-progress -v
  cp /tmp/chain/summary.json /check/chain-summary.json
  echo "== remote"
  port=$(sed -n "s|.*grpc://127.0.0.1:\([0-9]*\).*|\1|p" /check/ring1.ssd | head -n1)
  python -m coupler.examples gain --port "$port" >/tmp/gain.log 2>&1 &
  gain=$!
  coupler run /check/ring1.ssd --stop-time 20 --step 0.01 --out /tmp/ring --no-progress -v --connect-timeout 30
  cp /tmp/ring/summary.json /check/ring-summary.json
  echo "== export-fmu"
  coupler export-fmu "grpc://127.0.0.1:$port" --out /tmp/Gain.fmu
  python /check/fmpy_run.py /tmp/Gain.fmu
  kill "$gain"
' | tee "$OUT/container.log"
python3 - "$OUT" <<'PY'
import json, sys
from pathlib import Path

out = Path(sys.argv[1])
expected = {"chain-summary.json": "native FMU step", "ring-summary.json": "native step channel"}
for name, path in expected.items():
    summary = json.loads((out / name).read_text())
    paths = {m: p["step_path"] for m, p in summary["participants"].items()}
    wrong = {m: p for m, p in paths.items() if p["path"] != path}
    if summary["status"] != "completed" or wrong:
        sys.exit(f"native-check: {name}: status {summary['status']}, not '{path}': {wrong}")
    print(f"native-check: {name}: {len(paths)} members, every one: {path}")
PY
grep -q "^fmpy: ok" "$OUT/container.log" || { say "FMPy did not run the exported FMU"; exit 1; }
say "PASSED: in $IMAGE (no compiler, no system gRPC) the chain stepped in C, the remote gain over the native step channel, and FMPy ran the exported FMU"
