// Identify's dense decompositions run on AVX2 + FMA where the CPU has them
// and on the core's generic build otherwise (cpp/src/solve/dense.h). Both
// paths give the same answers to rounding, kernel by kernel and through
// Identify on TANGO S3 and S4 (the same undetermined groups); the generic
// path runs when forced; and the AVX2 object shares no symbol with the rest
// of the core that the linker could merge (dense_avx2.cc's Eigen is renamed).
#include <gtest/gtest.h>

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <nlohmann/json.hpp>
#include <random>
#include <string>

#include "fivecal/observations/simulate.h"
#include "fivecal/solve/identify.h"
#include "../../cpp/src/solve/dense.h"  // the core's private header
#include "../../cpp/src/solve/dense_kernels.h"
#include "test_files.h"

namespace fivecal {
namespace {

bool CpuHasAvx2() {
#if defined(__GNUC__) && defined(__x86_64__)
  __builtin_cpu_init();
  return __builtin_cpu_supports("avx2") && __builtin_cpu_supports("fma");
#else
  return false;
#endif
}

// Runs `f` on the generic kernels, then on the CPU's choice.
template <class F>
auto BothPaths(F f) {
  dense::ForceGeneric(true);
  EXPECT_STREQ(dense::ActiveIsa(), "generic");
  auto generic = f();
  dense::ForceGeneric(false);
  auto best = f();
  return std::make_pair(generic, best);
}

Eigen::MatrixXd Random(int n, int p, unsigned seed) {
  std::mt19937 rng(seed);
  std::normal_distribution<double> g;
  Eigen::MatrixXd A(n, p);
  for (int j = 0; j < p; ++j)
    for (int i = 0; i < n; ++i) A(i, j) = g(rng) * std::pow(10.0, (j % 7) - 3);
  return A;
}

TEST(DenseDispatch, TheAvx2PathRunsWhereTheCpuHasIt) {
  dense::ForceGeneric(false);
  if (CpuHasAvx2() && dense::Avx2Kernels()) {
    EXPECT_STREQ(dense::ActiveIsa(), "avx2");
  } else {
    EXPECT_STREQ(dense::ActiveIsa(), "generic");
  }
  dense::ForceGeneric(true);
  EXPECT_STREQ(dense::ActiveIsa(), "generic");
  dense::ForceGeneric(false);
}

TEST(DenseDispatch, EveryKernelAgreesWithTheGenericOneToRounding) {
  const Eigen::MatrixXd A = Random(389, 121, 7);
  const double eps = 1e-12;
  const auto gram = BothPaths([&] { return dense::Gram(A); });
  EXPECT_LE((gram.first - gram.second).norm(), eps * gram.first.norm());
  EXPECT_TRUE(gram.first.isApprox(gram.first.transpose(), 0));  // both triangles
  // R is unique up to the signs of its rows; Householder picks them from the same columns.
  const auto r = BothPaths([&] { return dense::QrR(A); });
  EXPECT_LE((r.first - r.second).norm(), 1e-10 * r.first.norm());
  EXPECT_TRUE(r.second.triangularView<Eigen::StrictlyLower>().toDenseMatrix().isZero(0));
  EXPECT_LE((r.second.transpose() * r.second - gram.first).norm(), 1e-12 * gram.first.norm());
  // Cholesky and the inverse from it, against Eigen's LLT in this file
  const Eigen::MatrixXd N = gram.first;
  const auto llt = BothPaths([&] { return dense::Llt(N); });
  ASSERT_TRUE(llt.first.ok && llt.second.ok);
  const Eigen::LLT<Eigen::MatrixXd> ref(N);
  EXPECT_LE((llt.second.L.triangularView<Eigen::Lower>().toDenseMatrix() -
             Eigen::MatrixXd(ref.matrixL())).norm(), 1e-12 * N.norm());
  const auto inv = BothPaths([&] { return llt.first.Inverse(); });
  const Eigen::MatrixXd X = ref.solve(Eigen::MatrixXd::Identity(121, 121));
  EXPECT_LE((inv.first - X).norm(), 1e-9 * X.norm());
  EXPECT_LE((inv.second - X).norm(), 1e-9 * X.norm());
  // a matrix that is not positive definite fails on both paths
  Eigen::MatrixXd bad = N;
  bad(60, 60) = -1.0;
  const auto fail = BothPaths([&] { return dense::Llt(bad).ok; });
  EXPECT_FALSE(fail.first);
  EXPECT_FALSE(fail.second);
  // eigenpairs: the same values; the same vectors up to sign
  const auto eig = BothPaths([&] {
    Eigen::VectorXd l;
    Eigen::MatrixXd V;
    EXPECT_TRUE(dense::SymmetricEigen(N, true, &l, &V));
    return std::make_pair(l, V);
  });
  EXPECT_LE((eig.first.first - eig.second.first).cwiseAbs().maxCoeff(), 1e-12 * eig.first.first.maxCoeff());
  for (int k = 0; k < 121; ++k) {
    const double c = std::abs(eig.first.second.col(k).dot(eig.second.second.col(k)));
    EXPECT_NEAR(c, 1.0, 1e-6) << k;
  }
  const auto vals = BothPaths([&] {
    Eigen::VectorXd l;
    EXPECT_TRUE(dense::SymmetricEigen(N, false, &l, nullptr));
    return l;
  });
  EXPECT_LE((vals.first - eig.first.first).cwiseAbs().maxCoeff(), 1e-12 * eig.first.first.maxCoeff());
  EXPECT_LE((vals.second - eig.first.first).cwiseAbs().maxCoeff(), 1e-12 * eig.first.first.maxCoeff());
  // products
  const Eigen::MatrixXd B = Random(121, 40, 8);
  const auto ab = BothPaths([&] { return dense::Product(r.first, B); });
  const Eigen::MatrixXd want = r.first * B;
  EXPECT_LE((ab.first - want).norm(), 1e-13 * want.norm());
  EXPECT_LE((ab.second - want).norm(), 1e-13 * want.norm());
  const auto atb = BothPaths([&] { return dense::TransposeProduct(A, Random(389, 5, 9)); });
  const Eigen::MatrixXd want2 = A.transpose() * Random(389, 5, 9);
  EXPECT_LE((atb.first - want2).norm(), 1e-13 * want2.norm());
  EXPECT_LE((atb.second - want2).norm(), 1e-13 * want2.norm());
}

Dataset Tango(bool s3) {
  const std::string data = std::string(FIVECAL_SOURCE_DIR) + "/tests/data/";
  nlohmann::json spec = nlohmann::json::parse(ReadFile(data + "tango_hu40t_spec.json"));
  if (s3) spec["errors"] = nlohmann::json::parse(ReadFile(data + "errors_tango_hu40t_s3.json"));
  return Simulate(spec.dump());
}

// Identify on either path: the same values, sigmas, rank, condition number
// and undetermined groups (S4, allow_unidentifiable) to rounding.
TEST(DenseDispatch, IdentifyGivesTheSameResultOnBothPaths) {
  for (bool s3 : {true, false}) {
    const Dataset ds = Tango(s3);
    IdentifyOptions opt;
    opt.estimate = {s3 ? "S3" : "S4"};
    opt.allow_unidentifiable = true;
    const auto res = BothPaths([&] { return Identify(ds, opt); });
    const Result& g = res.first;
    const Result& b = res.second;
    ASSERT_EQ(g.estimated, b.estimated);
    EXPECT_EQ(g.unidentifiable, b.unidentifiable);
    EXPECT_EQ(g.undetermined, b.undetermined);
    EXPECT_EQ(g.rank, b.rank);
    EXPECT_EQ(g.converged, b.converged);
    EXPECT_NEAR(g.condition_number, b.condition_number, 1e-8 * g.condition_number);
    for (int j = 0; j < g.std.size(); ++j) {
      const int i = static_cast<int>(std::find(g.names.begin(), g.names.end(), g.estimated[j]) - g.names.begin());
      EXPECT_NEAR(g.values[i], b.values[i], 1e-6 * g.std[j] + 1e-15) << g.estimated[j];
      EXPECT_NEAR(g.std[j], b.std[j], 1e-8 * g.std[j]) << g.estimated[j];
    }
    if (!s3) {
      EXPECT_FALSE(g.undetermined.empty());
    }
  }
}

// The AVX2 object defines no symbol the linker could merge with the
// generic code's: every weak (COMDAT) definition in it is in its renamed
// Eigen or its own namespace.
TEST(DenseDispatch, TheAvx2ObjectSharesNoWeakSymbol) {
#ifndef FIVECAL_DENSE_AVX2_OBJECT
  GTEST_SKIP() << "object path not known to this build";
#else
  const std::string obj = FIVECAL_DENSE_AVX2_OBJECT;
  std::FILE* probe = std::fopen(obj.c_str(), "rb");
  if (!probe) GTEST_SKIP() << "no " << obj;
  std::fclose(probe);
  std::FILE* nm = popen(("nm -C '" + obj + "' 2>/dev/null").c_str(), "r");
  if (!nm) GTEST_SKIP() << "no nm";
  char line[8192];
  int weak = 0, own = 0;
  std::string shared;
  while (std::fgets(line, sizeof line, nm)) {
    std::string s(line);
    if (s.size() < 20) continue;
    const char type = s[17];
    const std::string name = s.substr(19);
    if (type != 'W' && type != 'V' && type != 'u') continue;
    ++weak;
    if (name.find("fivecal_avx2_Eigen") != std::string::npos || name.find("fivecal::dense::avx2") != std::string::npos ||
        name.rfind("DW.ref.__gxx_personality_v0", 0) == 0)
      ++own;
    else
      shared += name;
  }
  const int status = pclose(nm);
  if (weak == 0 && status != 0) GTEST_SKIP() << "nm failed";
  EXPECT_GT(own, 0) << "the AVX2 object has no Eigen of its own: is it built?";
  EXPECT_TRUE(shared.empty()) << "weak symbols the linker could take from the AVX2 object:\n" << shared;
#endif
}

}  // namespace
}  // namespace fivecal
