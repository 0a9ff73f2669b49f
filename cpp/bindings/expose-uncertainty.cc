// Bindings of the uncertainty tools (fivecal/uncertainty/): Monte Carlo and
// GUM with input covariance. Long computations release the GIL;
// the Monte Carlo progress callback is called from the calling thread only,
// with the GIL re-acquired for the call (the worker threads never touch Python).
#include <pybind11/eigen.h>
#include <pybind11/functional.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <limits>
#include <optional>

#include "fivecal/uncertainty/gum.h"
#include "fivecal/solve/identify.h"
#include "fivecal/uncertainty/monte_carlo.h"
#include "identify_options.h"

namespace py = pybind11;
using namespace fivecal;

namespace {

std::vector<bool> Bools(const std::vector<bool>& v) { return v; }

}  // namespace

void BindUncertainty(py::module_& m) {
  // ---- Monte Carlo ------------------------------------------------------------------
  py::class_<MonteCarloResult>(m, "MonteCarloResult")
      .def_readonly("estimated", &MonteCarloResult::estimated)
      .def_readonly("reference", &MonteCarloResult::reference)
      .def_readonly("truth", &MonteCarloResult::truth)
      .def_readonly("trials", &MonteCarloResult::trials)
      .def_readonly("used", &MonteCarloResult::used)
      .def_readonly("not_converged", &MonteCarloResult::not_converged)
      .def_readonly("failed", &MonteCarloResult::failed)
      .def_readonly("threads", &MonteCarloResult::threads)
      .def_readonly("seed", &MonteCarloResult::seed)
      .def_readonly("seconds", &MonteCarloResult::seconds)
      .def_readonly("probability", &MonteCarloResult::probability)
      .def_readonly("mean", &MonteCarloResult::mean)
      .def_readonly("std", &MonteCarloResult::std)
      .def_readonly("covariance", &MonteCarloResult::covariance)
      .def_readonly("correlation", &MonteCarloResult::correlation)
      .def_readonly("low", &MonteCarloResult::low)
      .def_readonly("high", &MonteCarloResult::high)
      .def_readonly("symmetric_low", &MonteCarloResult::symmetric_low)
      .def_readonly("symmetric_high", &MonteCarloResult::symmetric_high)
      .def_readonly("gum_covariance", &MonteCarloResult::gum_covariance)
      .def_readonly("gum_std", &MonteCarloResult::gum_std)
      .def_readonly("gum_low", &MonteCarloResult::gum_low)
      .def_readonly("gum_high", &MonteCarloResult::gum_high)
      .def_readonly("gum_k", &MonteCarloResult::gum_k)
      .def_readonly("tolerance", &MonteCarloResult::tolerance)
      .def_readonly("d_low", &MonteCarloResult::d_low)
      .def_readonly("d_high", &MonteCarloResult::d_high)
      .def_property_readonly("validated", [](const MonteCarloResult& r) { return Bools(r.validated); })
      .def_property_readonly("stable", [](const MonteCarloResult& r) { return Bools(r.stable); })
      .def_readonly("stability", &MonteCarloResult::stability)
      .def_readonly("std_ratio", &MonteCarloResult::std_ratio)
      .def_readonly("significant_digits", &MonteCarloResult::significant_digits)
      .def_readonly("samples", &MonteCarloResult::samples)
      .def_readonly("trial_std", &MonteCarloResult::trial_std)
      .def_readonly("usable", &MonteCarloResult::usable)
      .def("to_json", &MonteCarloResult::ToJson, py::arg("include_samples") = false);

  m.def(
      "monte_carlo",
      [](const SimulationPlan& plan, const std::vector<std::string>& estimate, const std::vector<std::string>& fix,
         const std::map<std::string, double>& initial, const std::string& robust, double robust_scale,
         int max_iterations, bool include_default_setup, double selection_tolerance, int trials, int threads,
         uint64_t seed, double probability, int significant_digits, int blocks,
         const std::optional<Eigen::MatrixXd>& input_covariance, bool trial_std, bool keep_samples,
         const std::optional<py::function>& progress) {
        const IdentifyOptions io = MakeOptions(estimate, fix, initial, robust, robust_scale, max_iterations,
                                               include_default_setup, selection_tolerance);
        MonteCarloOptions mo;
        mo.trials = trials;
        mo.threads = threads;
        mo.seed = seed;
        mo.probability = probability;
        mo.significant_digits = significant_digits;
        mo.blocks = blocks;
        if (input_covariance) mo.input_covariance = *input_covariance;
        mo.trial_std = trial_std;
        mo.keep_samples = keep_samples;
        ProgressCallback cb;
        if (progress) {
          // Called on this (the calling) thread with the GIL released: take it
          // for the call. A Python exception (KeyboardInterrupt from the signal
          // check, or raised by the callback) cancels the run and is re-raised.
          py::function f = *progress;
          cb = [f](int done, int total) -> bool {
            py::gil_scoped_acquire gil;
            if (PyErr_CheckSignals() != 0) return false;
            try {
              py::object r = f(done, total);
              return r.is_none() || r.cast<bool>();
            } catch (py::error_already_set& e) {
              e.restore();
              return false;
            }
          };
        } else {
          cb = [](int, int) -> bool {
            py::gil_scoped_acquire gil;
            return PyErr_CheckSignals() == 0;
          };
        }
        try {
          py::gil_scoped_release release;
          return MonteCarlo(plan, io, mo, cb);
        } catch (const std::runtime_error& e) {
          if (PyErr_Occurred()) throw py::error_already_set();
          throw;
        }
      },
      py::arg("plan"), py::arg("estimate"), py::arg("fix"), py::arg("initial"), py::arg("robust") = "",
      py::arg("robust_scale") = 0.0, py::arg("max_iterations") = 200, py::arg("include_default_setup") = true,
      py::arg("selection_tolerance") = IdentifyOptions().selection_tolerance, py::arg("trials") = 10000,
      py::arg("threads") = 0, py::arg("seed") = 1, py::arg("probability") = 0.95,
      py::arg("significant_digits") = 2, py::arg("blocks") = 10, py::arg("input_covariance") = py::none(),
      py::arg("trial_std") = false, py::arg("keep_samples") = true, py::arg("progress") = py::none());

  m.def("trial_seed", &TrialSeed, py::arg("seed"), py::arg("trial"));
  m.def(
      "coverage_interval",
      [](const std::vector<double>& v, double p) {
        double lo, hi, slo, shi;
        CoverageInterval(v, p, &lo, &hi, &slo, &shi);
        return py::make_tuple(lo, hi, slo, shi);
      },
      py::arg("values"), py::arg("probability"),
      "(shortest low, shortest high, symmetric low, symmetric high), JCGM 101 §7.7.");
  m.def("numerical_tolerance", &NumericalTolerance, py::arg("u"), py::arg("significant_digits") = 2);

  // ---- GUM ----------------------------------------------------------------------------
  py::class_<CoverageFactor>(m, "CoverageFactor")
      .def_readonly("probability", &CoverageFactor::probability)
      .def_readonly("dof", &CoverageFactor::dof)
      .def_readonly("k", &CoverageFactor::k)
      .def_readonly("k_joint", &CoverageFactor::k_joint)
      .def_readonly("outputs", &CoverageFactor::outputs)
      .def_readonly("method", &CoverageFactor::method);
  m.def("coverage_factor", &MakeCoverageFactor, py::arg("probability"),
        py::arg("dof") = std::numeric_limits<double>::infinity(), py::arg("outputs") = 0, py::arg("k") = 0.0);
  m.def("normal_quantile", &NormalQuantile, py::arg("p"));
  m.def("student_t_quantile", &StudentTQuantile, py::arg("p"), py::arg("dof"));
  m.def("chi_square_quantile", &ChiSquareQuantile, py::arg("p"), py::arg("dof"));
  m.def("f_quantile", &FQuantile, py::arg("p"), py::arg("dof1"), py::arg("dof2"));

  py::class_<PooledCovariance>(m, "PooledCovariance")
      .def_readonly("covariance", &PooledCovariance::covariance)
      .def_readonly("mean", &PooledCovariance::mean)
      .def_readonly("group_means", &PooledCovariance::group_means)
      .def_readonly("group_labels", &PooledCovariance::group_labels)
      .def_readonly("group_sizes", &PooledCovariance::group_sizes)
      .def_readonly("dof", &PooledCovariance::dof);
  m.def("pool_covariance", &PoolCovariance, py::arg("samples"), py::arg("groups"));

  py::class_<GumResult>(m, "GumResult")
      .def_readonly("names", &GumResult::names)
      .def_readonly("values", &GumResult::values)
      .def_readonly("covariance", &GumResult::covariance)
      .def_readonly("std", &GumResult::std)
      .def_readonly("correlation", &GumResult::correlation)
      .def_readonly("coverage", &GumResult::coverage)
      .def_readonly("expanded", &GumResult::expanded)
      .def("to_json", &GumResult::ToJson);
  m.def(
      "gum_propagate",
      [](const Eigen::MatrixXd& C, const Eigen::MatrixXd& Ux, const std::vector<std::string>& names,
         const Eigen::VectorXd& values, const CoverageFactor& cf, const Eigen::MatrixXd& prior_term) {
        return PropagateCovariance(C, Ux, names, values, cf, prior_term);
      },
      py::arg("C"), py::arg("Ux"), py::arg("names"), py::arg("values"), py::arg("coverage"),
      py::arg("prior_term") = Eigen::MatrixXd());

  py::class_<Sensitivity>(m, "Sensitivity")
      .def_readonly("names", &Sensitivity::names)
      .def_readonly("values", &Sensitivity::values)
      .def_readonly("C", &Sensitivity::C)
      .def_readonly("input_rows", &Sensitivity::input_rows)
      .def_readonly("input_source", &Sensitivity::input_source)
      .def_readonly("prior_term", &Sensitivity::prior_term);
  m.def("sensitivity_matrix", &SensitivityMatrix, py::arg("dataset"), py::arg("result"),
        py::call_guard<py::gil_scoped_release>());

  py::class_<CyclesUncertainty>(m, "CyclesUncertainty")
      .def_readonly("gum", &CyclesUncertainty::gum)
      .def_readonly("inputs", &CyclesUncertainty::inputs)
      .def_readonly("estimated", &CyclesUncertainty::estimated)
      .def_readonly("cycle_values", &CyclesUncertainty::cycle_values)
      .def_readonly("output_pooled", &CyclesUncertainty::output_pooled)
      .def_readonly("day", &CyclesUncertainty::day)
      .def_readonly("cycle", &CyclesUncertainty::cycle)
      .def_readonly("pooling", &CyclesUncertainty::pooling)
      .def("to_json", &CyclesUncertainty::ToJson);
  m.def(
      "gum_from_cycles",
      [](const std::vector<const Dataset*>& cycles, const std::vector<int>& day, const std::vector<int>& cycle,
         const std::vector<std::string>& estimate, const std::vector<std::string>& fix,
         const std::map<std::string, double>& initial, const std::string& pooling, double probability,
         double coverage_factor, int reference, bool include_default_setup) {
        std::vector<Dataset> ds;
        for (const Dataset* d : cycles) ds.push_back(*d);
        const IdentifyOptions io = MakeOptions(estimate, fix, initial, "", 0.0, 200, include_default_setup,
                                               IdentifyOptions().selection_tolerance);
        CyclesOptions co;
        co.pooling = pooling;
        co.probability = probability;
        co.coverage_factor = coverage_factor;
        co.reference = reference;
        py::gil_scoped_release release;
        return GumFromCycles(ds, day, cycle, io, co);
      },
      py::arg("cycles"), py::arg("day"), py::arg("cycle"), py::arg("estimate"), py::arg("fix"),
      py::arg("initial"), py::arg("pooling") = "cycles", py::arg("probability") = 0.95,
      py::arg("coverage_factor") = 0.0, py::arg("reference") = 0, py::arg("include_default_setup") = true);
}
