#!/usr/bin/env bash
# Installs what kiln needs from Debian 12's packages (run as root). Safe to run again.
#
#   bash tools/install_deps.sh          what building kiln needs (compilers, CMake, Embree, ...)
#   bash tools/install_deps.sh --test   that, plus what the tests need besides: pkg-config (the
#                                       installed-package test), Debian's Chromium and Node.js,
#                                       and the npm packages of tools/web (three.js,
#                                       puppeteer-core, gltf-validator, pngjs: the browser and
#                                       glTF-Validator tests, docs/threejs.md) with `npm ci`, at
#                                       the versions pinned in tools/web/package-lock.json;
#                                       and clang with libFuzzer (tests/fuzz/run.sh, the fuzz
#                                       smoke run of .ci/run)
set -euo pipefail
test_tools=0
case "${1:-}" in
  "") ;;
  --test) test_tools=1 ;;
  *) echo "usage: install_deps.sh [--test]" >&2; exit 2 ;;
esac
export DEBIAN_FRONTEND=noninteractive
apt-get update -qq
apt-get install -y -qq --no-install-recommends \
  build-essential cmake ninja-build python3 \
  libembree-dev libtet1.5-dev libcgal-dev libglm-dev libopenexr-dev libtinygltf-dev \
  libstb-dev libeigen3-dev libtbb-dev nlohmann-json3-dev libcli11-dev libgtest-dev libbenchmark-dev \
  libmeshoptimizer-dev libdraco-dev libopenmpi-dev openmpi-bin \
  gnuplot-nox \
  > /dev/null
[ "$test_tools" = 1 ] || exit 0
# The browser test drives Debian's Chromium (headless, SwiftShader WebGL) through
# puppeteer-core, which downloads no browser of its own.
apt-get install -y -qq --no-install-recommends pkg-config chromium ca-certificates > /dev/null
# libFuzzer harnesses (tests/fuzz): Debian 12's clang 14 and its libFuzzer.
apt-get install -y -qq --no-install-recommends clang libfuzzer-14-dev > /dev/null
# Node.js and npm: Debian's, unless a node with npm is installed already (another
# distribution's nodejs package ships npm itself and conflicts with Debian's npm).
if ! command -v node > /dev/null || ! command -v npm > /dev/null; then
  apt-get install -y -qq --no-install-recommends nodejs npm > /dev/null
fi
web="$(cd "$(dirname "$0")" && pwd)/web"
(cd "$web" && npm ci --no-audit --no-fund --loglevel=error)
