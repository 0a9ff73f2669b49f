#include "fivecal/solve/long_kernel.h"

namespace fivecal {
namespace {

// As kinematic_model.cc: clones per ISA level, dispatched at load time.
// The sanitizer build and other compilers take the plain loop.
#if defined(__x86_64__) && defined(__GNUC__) && !defined(__clang__) && defined(__linux__) && \
    !defined(__SANITIZE_ADDRESS__)
#define FIVECAL_SIMD_CLONES __attribute__((target_clones("avx512f", "arch=x86-64-v3", "default")))
#else
#define FIVECAL_SIMD_CLONES
#endif

// One row's rank-1 update at a width W known at compile time: the inner
// loop is W / 8 AVX-512 (W / 4 AVX2) fused multiply-adds per parameter.
template <int W>
__attribute__((always_inline)) inline void Rows(const double* J, const double* r, int m, int p, double* N,
                                                double* g) {
  for (int i = 0; i < m; ++i) {
    const double* row = J + static_cast<long>(i) * W;
    const double ri = r[i];
    for (int a = 0; a < p; ++a) {
      const double ja = row[a];
      double* Na = N + a * W;
      for (int b = 0; b < W; ++b) Na[b] += ja * row[b];
      g[a] += ja * ri;
    }
  }
}

}  // namespace

FIVECAL_SIMD_CLONES void AccumulateNormal(const double* J, const double* r, int m, int p, int ld, double* N,
                                          double* g) {
  switch (ld) {
    case 4: return Rows<4>(J, r, m, p, N, g);
    case 8: return Rows<8>(J, r, m, p, N, g);
    case 16: return Rows<16>(J, r, m, p, N, g);
    case 24: return Rows<24>(J, r, m, p, N, g);
    case 32: return Rows<32>(J, r, m, p, N, g);
    default:
      for (int i = 0; i < m; ++i) {
        const double* row = J + static_cast<long>(i) * ld;
        for (int a = 0; a < p; ++a) {
          const double ja = row[a];
          for (int b = 0; b < ld; ++b) N[a * ld + b] += ja * row[b];
          g[a] += ja * r[i];
        }
      }
  }
}

const char* NormalKernelIsa() {
#if defined(__x86_64__) && defined(__GNUC__) && !defined(__clang__) && defined(__linux__) && \
    !defined(__SANITIZE_ADDRESS__)
  __builtin_cpu_init();
  if (__builtin_cpu_supports("avx512f")) return "avx512f";
  if (__builtin_cpu_supports("avx2") && __builtin_cpu_supports("fma")) return "x86-64-v3";
#endif
  return "default";
}

}  // namespace fivecal
