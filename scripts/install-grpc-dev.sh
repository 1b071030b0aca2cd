#!/usr/bin/env bash
# Debian's C++ gRPC tool chain, for building the binary of `coupler export-fmu`'s FMUs
# and of the orchestrator's native step channel (g++, libgrpc++-dev, libprotobuf-dev,
# protobuf-compiler-grpc, patchelf). Only as root with apt; never fatal:
# without it, export-fmu says what to install and its tests skip.
set -u
if command -v grpc_cpp_plugin >/dev/null && command -v patchelf >/dev/null \
   && command -v g++ >/dev/null && pkg-config --exists grpc++ protobuf 2>/dev/null; then
  exit 0
fi
if [ "$(id -u)" != 0 ] || ! command -v apt-get >/dev/null; then
  echo "install-grpc-dev: not root or no apt-get; coupler export-fmu cannot build its binary" \
       "(install g++ pkg-config libgrpc++-dev libprotobuf-dev protobuf-compiler-grpc patchelf)" >&2
  exit 0
fi
export DEBIAN_FRONTEND=noninteractive
apt-get update -qq >/dev/null \
  && apt-get install -y -qq --no-install-recommends g++ pkg-config libgrpc++-dev \
       libprotobuf-dev protobuf-compiler-grpc patchelf >/dev/null \
  || echo "install-grpc-dev: apt-get install failed; the export-fmu tests will skip" >&2
exit 0
