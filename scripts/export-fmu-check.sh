#!/usr/bin/env bash
# The exported FMU runs where gRPC is not installed (CI, `make export-fmu-check`):
#
#   1. engine: Debian's docker.io when missing, dockerd when not running (scripts/lib)
#   2. the local base image (scripts/base-image.sh: Debian minbase + python3, no gRPC)
#   3. the example gain participant on the host's loopback, exported with `coupler export-fmu`
#   4. the FMU run on the host by scripts/lib/fmi2_master.py (standard library + ctypes only)
#   5. the same in a container of the base image (host network: loopback only): the image must
#      hold no gRPC or protobuf library, `ldd` must resolve every library the binary needs,
#      and the values must equal the host's
#
# When the engine cannot be installed or started it prints "export-fmu-check: SKIPPED: <why>"
# and exits 0; any failure after that exits 1. Everything started here is stopped on the way
# out. Environment: EXPORT_FMU_CHECK_OUT (default build/export-fmu-check).
set -euo pipefail
cd "$(dirname "$0")/.."

CHECK=export-fmu-check
OUT=${EXPORT_FMU_CHECK_OUT:-build/export-fmu-check}
BASE_TAG=${BASE_TAG:-python:3.11-slim}
GAIN_PID=""
# shellcheck source=scripts/lib/containers.sh
source scripts/lib/containers.sh
on_failure() { [[ -f $OUT/gain.log ]] && tail -n 20 "$OUT/gain.log"; }
on_exit() { [[ -n $GAIN_PID ]] && kill "$GAIN_PID" 2>/dev/null; }

stage engine
engine_up

stage base-image
bash scripts/base-image.sh

stage export
[[ -x .venv/bin/coupler ]] || make setup
rm -rf "$OUT/Gain" "$OUT/Gain.fmu" "$OUT"/*.txt
mkdir -p "$OUT/Gain"
PORT=$(.venv/bin/python -c 'from coupler.testing import free_port; print(free_port())')
.venv/bin/python -m coupler.examples gain --port "$PORT" >"$OUT/gain.log" 2>&1 &
GAIN_PID=$!
.venv/bin/coupler export-fmu "grpc://127.0.0.1:$PORT" --out "$OUT/Gain.fmu" 2>/dev/null
python3 -m zipfile -e "$OUT/Gain.fmu" "$OUT/Gain"
chmod -R a+rX "$OUT/Gain"
cp scripts/lib/fmi2_master.py "$OUT/"
RUN=(--step 0.125 --stop 1 --set u=1.1 --set gain=3 --output y --output x)

stage host
python3 "$OUT/fmi2_master.py" "$OUT/Gain" "${RUN[@]}" >"$OUT/host.txt"

stage container
docker run --rm --network host -v "$PWD/$OUT:/check:ro" "$BASE_TAG" sh -c '
  set -e
  if ls /usr/lib/x86_64-linux-gnu /usr/lib /usr/local/lib 2>/dev/null | grep -E "^lib(grpc|protobuf)"; then
    echo "the base image has gRPC or protobuf installed" >&2; exit 1
  fi
  echo "== ldd, empty environment"
  env -i ldd /check/Gain/binaries/linux64/CouplerProxy.so
  echo "== run"
  python3 /check/fmi2_master.py /check/Gain '"${RUN[*]}"' >/tmp/container.txt
  cat /tmp/container.txt
' | tee "$OUT/container.log"
if grep -q "not found" "$OUT/container.log"; then
  say "a library the binary needs is missing from the FMU"; exit 1
fi
sed -n '/^== run$/,$p' "$OUT/container.log" | tail -n +2 >"$OUT/container.txt"
diff "$OUT/host.txt" "$OUT/container.txt"
say "PASSED: the exported FMU ran in $BASE_TAG (no gRPC installed), $(wc -l <"$OUT/host.txt") communication points equal to the host's: $(tail -n 1 "$OUT/host.txt")"
