#!/usr/bin/env bash
# Prepares this machine to run fivecal's headless LinuxCNC simulators
# (scripts/linuxcnc/sim): installs Debian's linuxcnc-uspace if missing and,
# when run as root, creates the unprivileged user the simulator runs as
# (LinuxCNC's realtime layer refuses to run as root). Idempotent.
set -euo pipefail
cd "$(dirname "$0")/.."
CNC_USER=${FIVECAL_CNC_USER:-fivecal-cnc}

SUDO=""
if [ "$(id -u)" != "0" ]; then SUDO="sudo"; fi
if ! dpkg -s linuxcnc-uspace >/dev/null 2>&1; then
  echo "fivecal: installing linuxcnc-uspace"
  $SUDO apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq linuxcnc-uspace >/dev/null
fi
for kins in xyzac-trt-kins xyzbc-trt-kins; do
  if [ ! -e "/usr/lib/linuxcnc/modules/$kins.so" ]; then
    echo "fivecal: LinuxCNC has no $kins module (/usr/lib/linuxcnc/modules)" >&2
    exit 2
  fi
done

if [ "$(id -u)" = "0" ]; then
  if ! id "$CNC_USER" >/dev/null 2>&1; then
    echo "fivecal: creating user $CNC_USER for the LinuxCNC simulator"
    useradd --create-home --shell /bin/bash --comment "fivecal LinuxCNC simulator" "$CNC_USER"
  fi
  # The simulator configs are copied into a work directory the user owns at
  # each start (tests/python/linuxcnc_harness.py); this only checks that the
  # user can read the templates.
  runuser -u "$CNC_USER" -- test -r scripts/linuxcnc/sim/xyzac-trt.ini || {
    echo "fivecal: user $CNC_USER cannot read $(pwd)/scripts/linuxcnc/sim;" \
         "the harness copies the configs to a directory it owns" >&2; }
fi
echo "fivecal: LinuxCNC $(dpkg-query -W -f='${Version}' linuxcnc-uspace) ready" \
     "(simulator user: $( [ "$(id -u)" = "0" ] && echo "$CNC_USER" || id -un))"
