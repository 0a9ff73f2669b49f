// The numbers behind the core's design choices, on one dataset and preset:
//
//   fivecal_bench_choices DATASET.json PRESET [REPEAT]
//
// prints one JSON object (median milliseconds over REPEAT runs) comparing
//   jacobian:  analytic one-block residuals vs the autodiff functors (the
//              reference path, also used by robust losses);
//   solve:     Ceres DENSE_NORMAL_CHOLESKY (used) vs DENSE_QR, from zero;
//   analysis:  the normal-matrix eigenvalue path of AnalyzeJacobian (used for
//              condition numbers below 1e4) vs QR + SVD of the scaled Jacobian.
// bench/run.py runs it when the C++ build (build/ctest) has it.
#include <Eigen/Dense>
#include <algorithm>
#include <chrono>
#include <fstream>
#include <functional>
#include <iostream>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

#include "fivecal/solve/identifiability.h"
#include "fivecal/solve/identify.h"
#include "fivecal/solve/problem.h"

using namespace fivecal;

namespace {

double MedianMs(int repeat, const std::function<void()>& f) {
  std::vector<double> t;
  for (int i = 0; i < repeat; ++i) {
    const auto a = std::chrono::steady_clock::now();
    f();
    t.push_back(std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - a).count());
  }
  std::sort(t.begin(), t.end());
  return t[t.size() / 2];
}

struct Solve {
  double ms = 0;
  int iterations = 0;
};

Solve TimeSolve(const Dataset& ds, const ParameterTable& table, const std::vector<int>& est,
                ceres::LinearSolverType type, int repeat) {
  Solve out;
  out.ms = MedianMs(repeat, [&] {
    Problem problem(ds, table, Eigen::VectorXd::Zero(table.size()), est);
    ceres::Solver::Options so = Problem::SolverOptions(200, 1);
    so.linear_solver_type = type;
    ceres::Solver::Summary summary;
    ceres::Solve(so, &problem.ceres_problem(), &summary);
    out.iterations = static_cast<int>(summary.iterations.size()) - 1;
  });
  return out;
}

}  // namespace

int main(int argc, char** argv) {
  try {
    if (argc < 3) throw std::invalid_argument("usage: fivecal_bench_choices DATASET.json PRESET [REPEAT]");
    std::ifstream f(argv[1]);
    if (!f) throw std::invalid_argument(std::string("cannot read ") + argv[1]);
    std::stringstream text;
    text << f.rdbuf();
    const Dataset ds = Dataset::FromJson(text.str());
    const int repeat = argc > 3 ? std::max(1, std::stoi(argv[3])) : 21;
    IdentifyOptions opt;
    opt.estimate = {argv[2]};
    // S4 on the TANGO plan leaves several motions undetermined (identify refuses
    // it as a request); the bench times the solver paths on that problem size,
    // so it fits anyway (minimum-norm steps), as test_tango does for S4.
    opt.allow_unidentifiable = true;
    const Result fit = Identify(ds, opt);
    const ParameterTable table(ds);
    std::vector<int> est;
    for (const std::string& n : fit.estimated) est.push_back(table.Require(n));

    Problem analytic(ds, table, fit.values, est, "", 0.0, true);
    Problem autodiff(ds, table, fit.values, est, "", 0.0, false);
    Eigen::VectorXd r;
    Eigen::MatrixXd J;
    const double jac_analytic = MedianMs(repeat, [&] { analytic.Evaluate(&r, &J); });
    const double jac_autodiff = MedianMs(repeat, [&] { autodiff.Evaluate(&r, &J); });

    const Solve normal = TimeSolve(ds, table, est, ceres::DENSE_NORMAL_CHOLESKY, repeat);
    const Solve qr = TimeSolve(ds, table, est, ceres::DENSE_QR, repeat);

    analytic.Evaluate(&r, &J);
    const double eig_path = MedianMs(repeat, [&] { AnalyzeJacobian(J); });
    const double svd_path = MedianMs(repeat, [&] {
      const Eigen::VectorXd inv = J.colwise().norm().cwiseInverse().transpose();
      const Eigen::MatrixXd Js = J * inv.asDiagonal();
      Eigen::HouseholderQR<Eigen::MatrixXd> h(Js);
      const Eigen::MatrixXd R = h.matrixQR().topRows(Js.cols()).triangularView<Eigen::Upper>();
      Eigen::BDCSVD<Eigen::MatrixXd> svd(R, Eigen::ComputeFullV);
      const Eigen::VectorXd s = svd.singularValues();
      volatile double keep = s[0] / s[s.size() - 1];
      (void)keep;
    });

    std::cout << "{\"dataset\": \"" << argv[1] << "\", \"preset\": \"" << argv[2] << "\", \"rows\": " << J.rows()
              << ", \"unknowns\": " << J.cols() << ", \"repeat\": " << repeat
              << ", \"jacobian_ms\": {\"analytic\": " << jac_analytic << ", \"autodiff\": " << jac_autodiff
              << "}, \"solve_ms\": {\"dense_normal_cholesky\": " << normal.ms
              << ", \"dense_qr\": " << qr.ms << "}, \"solve_iterations\": {\"dense_normal_cholesky\": "
              << normal.iterations << ", \"dense_qr\": " << qr.iterations
              << "}, \"analysis_ms\": {\"normal_eigen\": " << eig_path << ", \"qr_svd\": " << svd_path
              << "}, \"condition_number\": " << fit.condition_number << "}\n";
    return 0;
  } catch (const std::exception& e) {
    std::cerr << "fivecal_bench_choices: " << e.what() << "\n";
    return 2;
  }
}
