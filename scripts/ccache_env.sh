# Sourced by install.sh and test.sh. With ccache on the machine, every CMake
# build directory created afterwards compiles through it (CMake reads
# CMAKE_CXX_COMPILER_LAUNCHER from the environment). Paths are rewritten
# relative to the repository, so build/<wheel_tag> (pip) and build/ctest, which
# compile the core with identical flags, share its objects: the core is
# compiled once per fresh clone instead of twice.
if command -v ccache >/dev/null 2>&1; then
  export CMAKE_CXX_COMPILER_LAUNCHER=${CMAKE_CXX_COMPILER_LAUNCHER:-ccache}
  export CCACHE_BASEDIR=${CCACHE_BASEDIR:-$PWD}
  export CCACHE_NOHASHDIR=${CCACHE_NOHASHDIR:-1}
  export CCACHE_DIR=${CCACHE_DIR:-$HOME/.cache/ccache}
  # ccache tells compilers apart by name too: pip's build takes Python's own
  # (sysconfig CXX, g++ on Debian) where CMake alone would pick c++, the same
  # g++ under another name; name the one pip uses for every build.
  if [ -z "${CXX:-}" ]; then
    _cxx=$(${PYTHON:-python3} -c "import sysconfig; print((sysconfig.get_config_var('CXX') or '').split(' ')[0])" 2>/dev/null || true)
    if [ -n "$_cxx" ] && command -v "$_cxx" >/dev/null 2>&1; then export CXX="$_cxx"; fi
    unset _cxx
  fi
fi
