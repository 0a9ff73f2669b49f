#!/usr/bin/env bash
# Runs the whole test suite: the C++ gtest suite through ctest, then pytest.
# Expects scripts/install.sh to have run.
set -euo pipefail
cd "$(dirname "$0")/.."
PY=${PYTHON:-python3}
JOBS=${JOBS:-2}

cmake -S . -B build/ctest -G Ninja -DFIVECAL_BUILD_PYTHON=OFF -DFIVECAL_BUILD_TESTS=ON >/dev/null
cmake --build build/ctest -j "$JOBS"
ctest --test-dir build/ctest --output-on-failure -j "$JOBS"

$PY -m pytest -q tests/python
