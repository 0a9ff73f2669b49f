#include "solve/dense.h"

#include <atomic>
#include <cstdlib>
#include <cstring>

#include "solve/dense_kernels.h"

namespace fivecal {
namespace dense {
namespace {

// The CPU's choice, made once: AVX2 and FMA both (x86-64-v3's arithmetic),
// unless FIVECAL_DENSE=generic says otherwise.
const Kernels* Best() {
  const Kernels* avx2 = Avx2Kernels();
  const char* env = std::getenv("FIVECAL_DENSE");
  if (env && std::strcmp(env, "generic") == 0) return &GenericKernels();
#if defined(__GNUC__) && (defined(__x86_64__) || defined(__i386__))
  __builtin_cpu_init();
  if (avx2 && __builtin_cpu_supports("avx2") && __builtin_cpu_supports("fma")) return avx2;
#else
  (void)avx2;
#endif
  return &GenericKernels();
}

std::atomic<bool> force_generic{false};

const Kernels& K() {
  static const Kernels* best = Best();
  return force_generic.load(std::memory_order_relaxed) ? GenericKernels() : *best;
}

}  // namespace

const char* ActiveIsa() { return K().name; }
void ForceGeneric(bool generic) { force_generic.store(generic); }

Eigen::MatrixXd Gram(const Eigen::MatrixXd& A) {
  Eigen::MatrixXd N(A.cols(), A.cols());
  K().gram(A.data(), A.rows(), A.cols(), N.data());
  return N;
}

Eigen::MatrixXd QrR(const Eigen::MatrixXd& A) {
  Eigen::MatrixXd R(A.cols(), A.cols());
  K().qr_r(A.data(), A.rows(), A.cols(), R.data());
  return R;
}

Cholesky Llt(const Eigen::MatrixXd& N) {
  Cholesky c;
  c.L.resize(N.rows(), N.cols());
  c.ok = K().llt(N.data(), N.rows(), c.L.data()) == 0;
  return c;
}

Eigen::MatrixXd Cholesky::Inverse() const {
  Eigen::MatrixXd X(L.rows(), L.cols());
  K().llt_inverse(L.data(), L.rows(), X.data());
  return X;
}

bool SymmetricEigen(const Eigen::MatrixXd& N, bool vectors, Eigen::VectorXd* lambda, Eigen::MatrixXd* V) {
  lambda->resize(N.rows());
  if (vectors) V->resize(N.rows(), N.cols());
  return K().sym_eig(N.data(), N.rows(), lambda->data(), vectors ? V->data() : nullptr) == 0;
}

Eigen::MatrixXd Product(const Eigen::MatrixXd& A, const Eigen::MatrixXd& B) {
  Eigen::MatrixXd C(A.rows(), B.cols());
  K().gemm(A.data(), B.data(), A.rows(), A.cols(), B.cols(), 0, C.data());
  return C;
}

Eigen::MatrixXd TransposeProduct(const Eigen::MatrixXd& A, const Eigen::MatrixXd& B) {
  Eigen::MatrixXd C(A.cols(), B.cols());
  K().gemm(A.data(), B.data(), A.cols(), A.rows(), B.cols(), 1, C.data());
  return C;
}

}  // namespace dense
}  // namespace fivecal
