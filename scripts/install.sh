#!/usr/bin/env bash
# Installs everything fivecal needs on a Debian machine (system packages with
# apt-get, Python packages with pip) and installs fivecal itself.
set -euo pipefail
cd "$(dirname "$0")/.."

SUDO=""
if [ "$(id -u)" != "0" ]; then SUDO="sudo"; fi
# chromium: headless browser the report test renders the HTML report with
# ccache: the wheel build and scripts/test.sh compile the same core with the same
# flags; the second build takes the first one's objects from the cache.
DEB_PACKAGES=(libeigen3-dev libceres-dev nlohmann-json3-dev libgtest-dev chromium linuxcnc-uspace ccache)
missing=()
for p in "${DEB_PACKAGES[@]}"; do
  dpkg -s "$p" >/dev/null 2>&1 || missing+=("$p")
done
if [ ${#missing[@]} -gt 0 ]; then
  echo "fivecal: installing Debian packages: ${missing[*]}"
  $SUDO apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq "${missing[@]}" >/dev/null
fi

PY=${PYTHON:-python3}
source scripts/ccache_env.sh
command -v cmake >/dev/null 2>&1 || $PY -m pip install -q cmake
command -v ninja >/dev/null 2>&1 || $PY -m pip install -q ninja
# test: pytest and what the tests run (nbclient and ipykernel for the example
# notebook); fleet: Dask and pyarrow, which the calibration history tests use
$PY -m pip install -q --disable-pip-version-check ".[test,fleet]"
command -v pyenv >/dev/null 2>&1 && pyenv rehash || true
echo "fivecal: installed ($($PY -c 'import fivecal; print(fivecal.__version__)'))"
