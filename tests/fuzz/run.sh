#!/usr/bin/env bash
# tests/fuzz/run.sh [SECONDS] [FUZZER...]: builds the libFuzzer harnesses with clang in a build
# directory of their own (build-fuzz, or $KILN_FUZZ_BUILD_DIR) and runs each fuzzer for SECONDS
# (default 20) over a scratch copy of its seed corpus, through CTest (label `fuzz`). FUZZER is
# gltf, kprobe or klppv (default: all three). Exit non-zero on a finding; the input that caused
# it is in <build>/tests/fuzz/smoke_<fuzzer>/.
#
# Longer runs, straight through libFuzzer (the corpus directory grows with what it finds):
#   build-fuzz/tests/fuzz/fuzz_gltf -max_total_time=600 -timeout=10 -rss_limit_mb=2048 \
#       -malloc_limit_mb=2048 CORPUS_DIR tests/fuzz/corpus/gltf
set -euo pipefail
cd "$(dirname "$0")/../.."
seconds="${1:-20}"
shift || true
fuzzers=("$@")
[ ${#fuzzers[@]} -gt 0 ] || fuzzers=(gltf kprobe klppv)
build="${KILN_FUZZ_BUILD_DIR:-build-fuzz}"
cxx="$(command -v clang++ || command -v clang++-14 || true)"
cc="$(command -v clang || command -v clang-14 || true)"
if [ -z "$cxx" ] || [ -z "$cc" ]; then
  echo "tests/fuzz/run.sh: clang not found (bash tools/install_deps.sh --test installs it)" >&2
  exit 2
fi
launcher=()
if command -v ccache > /dev/null; then
  launcher=(-DCMAKE_CXX_COMPILER_LAUNCHER=ccache -DCMAKE_C_COMPILER_LAUNCHER=ccache)
fi
cmake -S . -B "$build" -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo \
  -DCMAKE_CXX_COMPILER="$cxx" -DCMAKE_C_COMPILER="$cc" "${launcher[@]}" \
  -DKILN_FUZZ=ON -DKILN_BUILD_TESTS=OFF -DKILN_BUILD_BENCHMARKS=OFF \
  -DKILN_FUZZ_SMOKE_SECONDS="$seconds" > /dev/null
targets=()
regex=""
for f in "${fuzzers[@]}"; do
  targets+=("fuzz_$f")
  regex="${regex:+$regex|}^fuzz_${f}_smoke\$"
done
cmake --build "$build" --target "${targets[@]}" -j "${KILN_FUZZ_JOBS:-2}"
ctest --test-dir "$build" -L fuzz -R "$regex" --output-on-failure
