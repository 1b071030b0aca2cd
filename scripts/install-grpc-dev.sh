#!/usr/bin/env bash
# Debian's C++ gRPC tool chain, which the coupler-native wheel is built with (`make setup`
# builds it: the native FMU step, the native step channel and the exported FMU's binaries):
# g++, pkg-config, libgrpc++-dev, libprotobuf-dev, protobuf-compiler-grpc, patchelf, and ccache
# (rebuilds of unchanged sources in seconds; CMake and ninja come from PyPI when missing). Only as root with apt; it says what to install otherwise.
# Nothing here is needed to run Coupler: the wheel bundles what it loads.
set -u
if command -v grpc_cpp_plugin >/dev/null && command -v patchelf >/dev/null \
   && command -v g++ >/dev/null && command -v ccache >/dev/null && pkg-config --exists grpc++ protobuf 2>/dev/null; then
  exit 0
fi
if [ "$(id -u)" != 0 ] || ! command -v apt-get >/dev/null; then
  echo "install-grpc-dev: not root or no apt-get; building coupler-native needs g++ pkg-config" \
       "libgrpc++-dev libprotobuf-dev protobuf-compiler-grpc patchelf (and ccache)" >&2
  exit 0
fi
export DEBIAN_FRONTEND=noninteractive
apt-get update -qq >/dev/null \
  && apt-get install -y -qq --no-install-recommends g++ pkg-config libgrpc++-dev \
       libprotobuf-dev protobuf-compiler-grpc patchelf ccache >/dev/null \
  || echo "install-grpc-dev: apt-get install failed; building coupler-native will fail" >&2
exit 0
