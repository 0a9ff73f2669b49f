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
fi
