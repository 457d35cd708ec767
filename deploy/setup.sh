#!/usr/bin/env bash
# Installs every Debian 12 (bookworm) package that bsn needs to build, test and run its demo.
# Does nothing when all of them are already installed. Needs root or sudo to install.
set -euo pipefail

packages=(
  build-essential cmake ninja-build pkg-config git   # toolchain
  libfastrtps-dev libfastcdr-dev fastddsgen fastdds-tools default-jre-headless  # Fast DDS 2.9 + IDL generator
  libeigen3-dev libyaml-cpp-dev libcli11-dev libhdf5-dev  # core math, configuration, command line, HDF5 recordings
  libgtest-dev libgmock-dev libbenchmark-dev         # tests and benchmarks
  cyclonedds-dev cyclonedds-tools                    # another vendor's DDS, for the interoperability test
  clang-format procps                                # formatting check in CI; ps for diagnostics
  openssl libssl-dev systemd iproute2               # PKI for DDS-Security and its cost bench, unit files, netns
  clang libclang-rt-14-dev                           # the fuzz targets (libFuzzer, sanitizers) in CI
  libcivetweb-dev libjs-three libjs-chart.js         # bsn view: HTTP/WebSocket server, 3D and plots (offline)
  chromium                                           # bsn view's browser test (headless)
)

missing=()
for p in "${packages[@]}"; do
  if ! dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed"; then
    missing+=("$p")
  fi
done

if [ ${#missing[@]} -eq 0 ]; then
  echo "bsn setup: all ${#packages[@]} packages are installed; nothing to do."
  exit 0
fi

if [ "$(id -u)" -eq 0 ]; then
  sudo=()
elif command -v sudo >/dev/null 2>&1; then
  sudo=(sudo)
else
  echo "bsn setup: error: these packages are missing and installing them needs root, but this is user" \
       "'$(id -un)' and sudo is not installed:" >&2
  echo "  ${missing[*]}" >&2
  echo "Run this script as root, or have an administrator run: apt-get install ${missing[*]}" >&2
  exit 1
fi

echo "bsn setup: installing ${missing[*]}"
"${sudo[@]}" apt-get update -q
"${sudo[@]}" env DEBIAN_FRONTEND=noninteractive apt-get install -y -q --no-install-recommends "${missing[@]}"
echo "bsn setup: done."
