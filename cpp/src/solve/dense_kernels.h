// The dense decompositions of identify (Gram matrices, Householder QR,
// Cholesky, symmetric eigensolver, products) on raw column-major arrays, one
// table per instruction set. dense_generic.cc builds them for the core's
// target (generic x86-64: SSE2), dense_avx2.cc for x86-64-v3 (AVX2 + FMA);
// dense.cc picks one at run time from what the CPU supports. The table speaks
// no Eigen types: each implementation file has its own copy of Eigen, in a
// namespace of its own (dense_avx2.cc renames Eigen by macro), so that the
// linker never merges an AVX2 instantiation of an Eigen template with the
// generic one (an ODR violation that would run AVX2 code on a CPU without it,
// or SSE2 code in the AVX2 path).
#ifndef FIVECAL_SOLVE_DENSE_KERNELS_H_
#define FIVECAL_SOLVE_DENSE_KERNELS_H_

namespace fivecal {
namespace dense {

// Every matrix is column-major with its leading dimension its row count.
struct Kernels {
  const char* name;
  // N (p x p, both triangles) = A^T A, A n x p.
  void (*gram)(const double* a, long n, long p, double* N);
  // R (p x p, upper triangular, zero below) of the Householder QR of A (n x p, n > p).
  void (*qr_r)(const double* a, long n, long p, double* R);
  // Cholesky of N (p x p): L's lower triangle as Eigen::LLT stores it (the
  // strictly upper part keeps N's); returns 0 on success, 1 when a pivot is
  // not positive (L then holds what LLT computed up to it).
  int (*llt)(const double* N, long p, double* L);
  // X = (L L^T)^-1 from llt's L (p x p).
  void (*llt_inverse)(const double* L, long p, double* X);
  // Eigenvalues ascending of the symmetric N (p x p) and, when V is not
  // null, its eigenvectors (columns); returns 0 on success.
  int (*sym_eig)(const double* N, long p, double* lambda, double* V);
  // C (m x n) = op(A) B with op(A) = A (m x k) or, with `trans_a`, A^T (A k x m).
  void (*gemm)(const double* a, const double* b, long m, long k, long n, int trans_a, double* C);
};

const Kernels& GenericKernels();
// The AVX2 + FMA table, or null where it was not built (another
// architecture or compiler).
const Kernels* Avx2Kernels();

}  // namespace dense
}  // namespace fivecal

#endif  // FIVECAL_SOLVE_DENSE_KERNELS_H_
