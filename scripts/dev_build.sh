#!/usr/bin/env bash
# Developer build: compiles the C++ core, the Python module and the gtests in
# build/dev and copies the module into python/fivecal/, so that the tree's own
# code is what runs under PYTHONPATH=python (no pip install after each change).
# Expects scripts/install.sh to have run once (compilers, Eigen, Ceres, pybind11).
set -euo pipefail
cd "$(dirname "$0")/.."
PY=${PYTHON:-python3}
source scripts/ccache_env.sh
if [ ! -f build/dev/CMakeCache.txt ]; then
  cmake -S . -B build/dev -G Ninja -DCMAKE_BUILD_TYPE=Release -DFIVECAL_BUILD_PYTHON=ON \
    -DFIVECAL_BUILD_TESTS=ON -Dpybind11_DIR="$($PY -m pybind11 --cmakedir)" >/dev/null
fi
cmake --build build/dev -j "${JOBS:-2}"
# Copy then rename: overwriting the module in place crashes a Python process
# that has it loaded (a test run, a bench) instead of leaving it the old file.
for so in build/dev/_core*.so; do
  cp "$so" "python/fivecal/.$(basename "$so").tmp"
  mv -f "python/fivecal/.$(basename "$so").tmp" "python/fivecal/$(basename "$so")"
done
echo "built build/dev; module copied to python/fivecal/ (use PYTHONPATH=$PWD/python)"
