#!/usr/bin/env bash
# Builds the C++ core and the gtest suite once more with AddressSanitizer and
# UndefinedBehaviorSanitizer (float-cast-overflow included) and runs ctest.
# Any finding aborts its test (-fno-sanitize-recover=all, halt_on_error), so
# the run passes only when it is clean. Called by scripts/test.sh.
#
# Debug build type on purpose: it keeps Eigen's index assertions, which catch
# out-of-bounds access inside fixed-size matrices that ASan cannot see.
set -euo pipefail
cd "$(dirname "$0")/.."
JOBS=${JOBS:-2}
BUILD=build/sanitize

launcher=()
if command -v ccache >/dev/null 2>&1; then
  export CCACHE_BASEDIR=${CCACHE_BASEDIR:-$PWD} CCACHE_DIR=${CCACHE_DIR:-$HOME/.cache/ccache}
  launcher=(-DCMAKE_CXX_COMPILER_LAUNCHER=ccache)
fi

cmake -S . -B "$BUILD" -G Ninja -DCMAKE_BUILD_TYPE=Debug -DFIVECAL_SANITIZE=ON \
  -DFIVECAL_BUILD_PYTHON=OFF -DFIVECAL_BUILD_TESTS=ON "${launcher[@]}" >/dev/null
# Only the test binary: the benchmark built alongside in the plain build is
# not run by ctest.
cmake --build "$BUILD" -j "$JOBS" --target fivecal_tests fivecal_kind_plugin_tests

# Suppressions cover leaks inside third-party libraries only (see the file).
export ASAN_OPTIONS="detect_leaks=1:abort_on_error=0:strict_string_checks=1:check_initialization_order=1"
export LSAN_OPTIONS="suppressions=$PWD/scripts/lsan.supp:print_suppressions=0"
export UBSAN_OPTIONS="print_stacktrace=1:halt_on_error=1"
ctest --test-dir "$BUILD" --output-on-failure -j "$JOBS" --timeout 900
