#!/usr/bin/env bash
# Installs lensopt's build and run dependencies from Debian 12 packages.
# Skips apt entirely when every package is already installed.
set -euo pipefail
packages=(
  build-essential cmake ninja-build pkg-config
  libceres-dev libeigen3-dev libcli11-dev libfmt-dev libtomlplusplus-dev
  libpng-dev libopenimageio-dev doctest-dev libyaml-cpp-dev nlohmann-json3-dev
  fonts-dejavu-core
  libfftw3-dev
  openimageio-tools
  libtorch-dev
  python3
  python3-dev pybind11-dev python3-numpy python3-torch python3-pytest
  ccache
)
missing=()
for p in "${packages[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if ((${#missing[@]})); then
  echo "install-deps: installing ${missing[*]}" >&2
  sudo_cmd=""
  [ "$(id -u)" -eq 0 ] || sudo_cmd="sudo"
  $sudo_cmd apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $sudo_cmd apt-get install -y -qq --no-install-recommends "${missing[@]}"
fi
