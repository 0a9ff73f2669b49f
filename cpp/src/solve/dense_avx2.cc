// The dense kernels for x86-64-v3 (AVX2 + FMA), dense_kernels.h. CMake
// compiles this file alone with -mavx2 -mfma (x86-64 with GCC or Clang);
// dense.cc calls it only on a CPU that has both.
//
// Eigen's templates instantiated here would have the same names as the
// generic ones everywhere else in the core, and the linker keeps one copy
// of each: this file's Eigen is renamed, so every instantiation made here is
// its own symbol. tests/cpp/test_dense_dispatch.cc checks the object for any
// other shared (weak) symbol.
#if defined(__AVX2__) && defined(__FMA__)
// The standard headers Eigen includes, first and under their own names (a
// std:: function made here and inlined nowhere would be shared with the
// generic code; the test above looks for that too).
#include <algorithm>
#include <cmath>
#include <complex>
#include <cstddef>
#include <cstdlib>
#include <cstring>
#include <functional>
#include <iosfwd>
#include <limits>
#include <new>
#include <type_traits>

// The sanitizer build tells every other file that malloc already aligns
// (CMakeLists.txt: the prebuilt Ceres frees what the core allocates). That
// is 16 bytes; AVX packets need 32. Nothing allocated by this file's renamed
// Eigen is freed elsewhere, so it keeps Eigen's own aligned allocator.
#undef EIGEN_MALLOC_ALREADY_ALIGNED
#define EIGEN_MALLOC_ALREADY_ALIGNED 0
#define Eigen fivecal_avx2_Eigen
#define FIVECAL_DENSE_ISA avx2
#define FIVECAL_DENSE_NAME "avx2"
#include "solve/dense_kernels.inc"
#undef Eigen

namespace fivecal {
namespace dense {

const Kernels* Avx2Kernels() { return &avx2::kTable; }

}  // namespace dense
}  // namespace fivecal

#else
#include "solve/dense_kernels.h"

namespace fivecal {
namespace dense {

const Kernels* Avx2Kernels() { return nullptr; }

}  // namespace dense
}  // namespace fivecal
#endif
