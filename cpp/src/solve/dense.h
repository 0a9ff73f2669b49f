// The dense decompositions of identify's analyses (identifiability.cc,
// identify_covariance.cc), run with the widest instruction set the CPU has
// (dense_kernels.h: AVX2 + FMA where present, else the core's generic
// x86-64 build). The answers of the two paths differ by rounding only (FMA
// rounds once where SSE2 rounds twice, and the blocking differs).
#ifndef FIVECAL_SOLVE_DENSE_H_
#define FIVECAL_SOLVE_DENSE_H_

#include <Eigen/Core>

namespace fivecal {
namespace dense {

// The table in use: the AVX2 one when the CPU has AVX2 and FMA and neither
// ForceGeneric(true) nor FIVECAL_DENSE=generic (environment, read once)
// says otherwise.
const char* ActiveIsa();
// Tests: run the generic kernels whatever the CPU (false: back to the
// choice above).
void ForceGeneric(bool generic);

// N = A^T A (both triangles).
Eigen::MatrixXd Gram(const Eigen::MatrixXd& A);
// R of A's Householder QR (A has more rows than columns).
Eigen::MatrixXd QrR(const Eigen::MatrixXd& A);

// The Cholesky factor of a symmetric N (Eigen::LLT's storage and rules).
struct Cholesky {
  Eigen::MatrixXd L;  // lower triangle; the strictly upper part is N's
  bool ok = false;    // every pivot positive
  Eigen::VectorXd Diagonal() const { return L.diagonal(); }
  Eigen::MatrixXd Inverse() const;  // (L L^T)^-1
};
Cholesky Llt(const Eigen::MatrixXd& N);

// Eigenvalues (ascending) and, with `vectors`, eigenvectors of a symmetric N.
bool SymmetricEigen(const Eigen::MatrixXd& N, bool vectors, Eigen::VectorXd* lambda, Eigen::MatrixXd* V);

// A B, and A^T B.
Eigen::MatrixXd Product(const Eigen::MatrixXd& A, const Eigen::MatrixXd& B);
Eigen::MatrixXd TransposeProduct(const Eigen::MatrixXd& A, const Eigen::MatrixXd& B);

}  // namespace dense
}  // namespace fivecal

#endif  // FIVECAL_SOLVE_DENSE_H_
