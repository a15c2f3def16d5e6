#!/usr/bin/env bash
# Installs tarmac's build and test dependencies from Debian 12 packages only.
# Idempotent: when every package is already installed it does nothing (no apt-get update).
# Used by the README's quick-start commands and by .ci/run. Needs root (or sudo) when it installs.
set -euo pipefail

packages=(
  build-essential cmake pkg-config ninja-build default-jre-headless
  libfastrtps-dev libfastcdr-dev libfoonathan-memory-dev fastddsgen fastdds-tools
  libopenvdb-dev libboost-iostreams-dev libtbb-dev libblosc-dev libimath-dev zlib1g-dev
  libeigen3-dev libspdlog-dev libfmt-dev libyaml-cpp-dev libgtest-dev libgmock-dev
  libcli11-dev nlohmann-json3-dev                # command lines (CLI11), JSON outputs
  libsystemd-dev openssl libssl-dev cyclonedds-dev cyclonedds-tools liboctomap-dev libdynamicedt3d-dev
  libpng-dev iproute2 systemd clang-format
  stress-ng                                      # other load on the cores (tools/load-test.sh)
  rosidl-tools python3-catkin-pkg python3-empy   # ROS 2's msg -> IDL translator (msg_idl_agreement test)
  clang libclang-rt-14-dev                       # libFuzzer and its sanitizers (tools/fuzz.sh)
)

missing=()
for p in "${packages[@]}"; do
  if ! dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q 'install ok installed'; then
    missing+=("$p")
  fi
done

if [ ${#missing[@]} -eq 0 ]; then
  echo "install-deps: all ${#packages[@]} packages present"
  exit 0
fi

sudo_cmd=()
if [ "$(id -u)" -ne 0 ]; then
  command -v sudo >/dev/null || { echo "install-deps: need root or sudo to install: ${missing[*]}" >&2; exit 1; }
  sudo_cmd=(sudo)
fi

echo "install-deps: installing ${#missing[@]} package(s): ${missing[*]}"
"${sudo_cmd[@]}" apt-get update -qq
DEBIAN_FRONTEND=noninteractive "${sudo_cmd[@]}" apt-get install -y -qq --no-install-recommends "${missing[@]}"
