#!/usr/bin/env bash
# Installs kiln's build and test dependencies from Debian 12's packages (run as root), and the
# npm packages of tools/web (three.js, puppeteer-core, gltf-validator, pngjs: the browser and
# glTF-Validator tests, docs/threejs.md) from the npm registry with `npm ci` (the versions
# pinned in tools/web/package-lock.json). Safe to run again.
set -euo pipefail
export DEBIAN_FRONTEND=noninteractive
apt-get update -qq
apt-get install -y -qq --no-install-recommends \
  build-essential cmake ninja-build python3 \
  libembree-dev libtet1.5-dev libcgal-dev libglm-dev libopenexr-dev libtinygltf-dev \
  libstb-dev libeigen3-dev libtbb-dev nlohmann-json3-dev libcli11-dev libgtest-dev libbenchmark-dev \
  gnuplot-nox \
  > /dev/null
# The browser test drives Debian's Chromium (headless, SwiftShader WebGL) through
# puppeteer-core, which downloads no browser of its own.
apt-get install -y -qq --no-install-recommends chromium ca-certificates > /dev/null
# Node.js and npm: Debian's, unless a node with npm is installed already (another
# distribution's nodejs package ships npm itself and conflicts with Debian's npm).
if ! command -v node > /dev/null || ! command -v npm > /dev/null; then
  apt-get install -y -qq --no-install-recommends nodejs npm > /dev/null
fi
web="$(cd "$(dirname "$0")" && pwd)/web"
(cd "$web" && npm ci --no-audit --no-fund --loglevel=error)
