#!/usr/bin/env bash
# Installs kiln's build and test dependencies from Debian 12's packages (run as root).
set -euo pipefail
export DEBIAN_FRONTEND=noninteractive
apt-get update -qq
apt-get install -y -qq --no-install-recommends \
  build-essential cmake ninja-build python3 \
  libembree-dev libtet1.5-dev libcgal-dev libglm-dev libopenexr-dev libtinygltf-dev \
  libstb-dev libeigen3-dev libtbb-dev nlohmann-json3-dev libcli11-dev libgtest-dev libbenchmark-dev \
  gnuplot-nox \
  > /dev/null
