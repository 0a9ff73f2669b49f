#!/usr/bin/env bash
# Runs the whole test suite: the C++ gtest suite through ctest (plain, then
# under the sanitizers: scripts/sanitize.sh), then pytest.
# Expects scripts/install.sh to have run.
set -euo pipefail
cd "$(dirname "$0")/.."
PY=${PYTHON:-python3}
JOBS=${JOBS:-2}
source scripts/ccache_env.sh

cmake -S . -B build/ctest -G Ninja -DFIVECAL_BUILD_PYTHON=OFF -DFIVECAL_BUILD_TESTS=ON >/dev/null
cmake --build build/ctest -j "$JOBS"
ctest --test-dir build/ctest --output-on-failure -j "$JOBS"

# The same gtests once more under AddressSanitizer + UndefinedBehaviorSanitizer.
bash scripts/sanitize.sh

# The C++ core as an embedder uses it: install, find_package(fivecal), run.
cmake --install build/ctest --prefix build/prefix >/dev/null
cmake -S examples/cpp -B build/example -G Ninja -DCMAKE_PREFIX_PATH="$PWD/build/prefix" >/dev/null
cmake --build build/example
./build/example/compensate examples/machines/hu40t.json examples/cpp/errors_example.json

# Two workers (pytest-xdist); the LinuxCNC tests share one (tests/python/conftest.py).
$PY -m pytest -q -n "$JOBS" --dist loadgroup tests/python
