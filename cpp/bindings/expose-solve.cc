// Bindings of the solver (fivecal/solve/): Identify and its Result, the
// prior classes, the estimate resolution, predicted residuals and the
// prepared-row counters of the streaming fit.
#include <algorithm>
#include <optional>

#include <pybind11/eigen.h>
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include "fivecal/observations/dataset.h"
#include "fivecal/solve/analytic_residuals.h"
#include "fivecal/solve/identify.h"
#include "fivecal/solve/priors.h"
#include "identify_options.h"

namespace py = pybind11;
using namespace fivecal;

void BindSolve(py::module_& m) {
  py::class_<Result>(m, "Result")
      .def_readonly("names", &Result::names)
      .def_readonly("values", &Result::values)
      .def_readonly("estimated", &Result::estimated)
      .def_readonly("std", &Result::std)
      .def_readonly("covariance", &Result::covariance)
      .def_readonly("correlation", &Result::correlation)
      .def_readonly("residuals", &Result::residuals)
      // An int64 array, not a list: a list of the rows of long data (3e6 for
      // 1e6 R-test samples) costs a Python int per row.
      .def_property_readonly("residual_source",
                             [](const Result& r) {
                               py::array_t<int64_t> a(static_cast<py::ssize_t>(r.residual_source.size()));
                               std::copy(r.residual_source.begin(), r.residual_source.end(), a.mutable_data());
                               return a;
                             })
      .def_readonly("residual_vectors", &Result::residual_vectors)
      .def_readonly("points", &Result::points)
      .def_readonly("rms", &Result::rms)
      .def_readonly("max_abs", &Result::max_abs)
      .def_readonly("sigma", &Result::sigma)
      .def_readonly("residual_units", &Result::residual_units)
      .def_readonly("condition_number", &Result::condition_number)
      .def_readonly("rank", &Result::rank)
      .def_readonly("unidentifiable", &Result::unidentifiable)
      .def_readonly("converged", &Result::converged)
      .def_readonly("iterations", &Result::iterations)
      .def_readonly("message", &Result::message)
      .def_readonly("n_observations", &Result::n_observations)
      .def_readonly("n_parameters", &Result::n_parameters)
      .def_readonly("outliers", &Result::outliers)
      .def_readonly("robust_scale", &Result::robust_scale)
      .def_readonly("prior_std", &Result::prior_std)
      .def_readonly("informed", &Result::informed)
      .def_readonly("placement", &Result::placement)
      .def_readonly("undetermined", &Result::undetermined)
      .def_readonly("implausible", &Result::implausible)
      .def_readonly("map_fit", &Result::map_fit)
      .def_readonly("fit_path", &Result::fit_path)
      .def_readonly("class_scales", &Result::class_scales)
      .def_readonly("variance_components", &Result::variance_components)
      .def_readonly("chi2", &Result::chi2)
      .def_readonly("dof", &Result::dof)
      .def_readonly("chi2_p", &Result::chi2_p)
      .def_readonly("adequate", &Result::adequate)
      .def_readonly("adequacy", &Result::adequacy)
      .def_readonly("plausible", &Result::plausible)
      .def_readonly("plausibility", &Result::plausibility)
      .def_readonly("finite", &Result::finite)
      .def_readonly("seeks_machine_errors", &Result::seeks_machine_errors)
      .def_readonly("identified_machine_errors", &Result::identified_machine_errors)
      .def_readonly("held", &Result::held)
      .def_readonly("left_out", &Result::left_out)
      .def_property_readonly("left_out_moves",
                             [](const Result& r) {
                               py::dict out;
                               for (const LeftOutMoves& m : r.left_out_moves)
                                 out[py::str(m.name)] = py::make_tuple(m.plausible, m.moves);
                               return out;
                             })
      .def_property_readonly("not_determined",
                             [](const Result& r) {
                               py::list out;
                               for (const NotDetermined& f : r.not_determined) {
                                 py::dict d;
                                 d["family"] = f.family;
                                 d["machine"] = f.machine;
                                 d["estimated"] = f.estimated;
                                 d["names"] = f.names;
                                 d["why"] = f.why;
                                 out.append(d);
                               }
                               return out;
                             })
      .def_property_readonly("verdict", &Result::verdict)
      .def("to_json", &Result::ToJson);

  m.def("prior_classes", []() {
    std::vector<py::dict> out;
    for (const PriorClass& c : PriorClasses()) {
      py::dict d;
      d["name"] = c.name;
      d["sigma"] = c.sigma;
      d["unit"] = c.unit;
      d["description"] = c.description;
      out.push_back(d);
    }
    return out;
  });
  m.def("informed_threshold", []() { return kInformedThreshold; });
  m.def("absent_class_scale", []() { return kAbsentClassScale; });
  m.def("identified_ratio", []() { return kIdentifiedRatio; });
  m.def("significant_sigmas", []() { return kSignificantSigmas; });

  m.def(
      "identify",
      [](const Dataset& ds, const std::vector<std::string>& estimate,
         const std::vector<std::string>& fix, const std::map<std::string, double>& initial,
         const std::string& robust, double robust_scale, int max_iterations,
         bool allow_unidentifiable, bool include_default_setup, int num_threads,
         double selection_tolerance, const std::map<std::string, double>& priors, bool prior,
         bool variance_components, const std::string& fit_path, bool setup_priors) {
        IdentifyOptions o = MakeOptions(estimate, fix, initial, robust, robust_scale, max_iterations,
                                        include_default_setup, selection_tolerance,
                                        allow_unidentifiable, num_threads, priors, prior);
        o.variance_components = variance_components;
        o.fit_path = fit_path;
        o.setup_priors = setup_priors;
        py::gil_scoped_release release;
        return Identify(ds, o);
      },
      py::arg("dataset"), py::arg("estimate"), py::arg("fix"), py::arg("initial"),
      py::arg("robust") = "", py::arg("robust_scale") = 0.0, py::arg("max_iterations") = 200,
      py::arg("allow_unidentifiable") = false, py::arg("include_default_setup") = true,
      py::arg("num_threads") = 0, py::arg("selection_tolerance") = IdentifyOptions().selection_tolerance,
      py::arg("priors") = std::map<std::string, double>(), py::arg("prior") = false,
      py::arg("variance_components") = false, py::arg("fit_path") = "auto", py::arg("setup_priors") = true);

  py::class_<UnitResiduals>(m, "UnitResiduals")
      .def_readonly("unit", &UnitResiduals::unit)
      .def_readonly("rows", &UnitResiduals::rows)
      .def_readonly("rms", &UnitResiduals::rms)
      .def_readonly("max_abs", &UnitResiduals::max_abs)
      .def_readonly("sigma", &UnitResiduals::sigma)
      .def_readonly("dof", &UnitResiduals::dof);

  py::class_<VarianceComponent>(m, "VarianceComponent")
      .def_readonly("group", &VarianceComponent::group)
      .def_readonly("rows", &VarianceComponent::rows)
      .def_readonly("redundancy", &VarianceComponent::redundancy)
      .def_readonly("declared", &VarianceComponent::declared)
      .def_readonly("factor", &VarianceComponent::factor)
      .def_readonly("sigma", &VarianceComponent::sigma)
      .def_readonly("estimated", &VarianceComponent::estimated);

  m.def(
      "resolve_estimate",
      [](const Dataset& ds, const std::vector<std::string>& estimate,
         const std::vector<std::string>& fix, const std::map<std::string, double>& initial,
         const std::map<std::string, double>& priors) {
        IdentifyOptions o;
        o.estimate = estimate;
        o.fix = fix;
        o.initial = initial;
        o.priors = priors;
        return ResolveEstimate(ds, o);
      },
      py::arg("dataset"), py::arg("estimate"), py::arg("fix"), py::arg("initial"),
      py::arg("priors") = std::map<std::string, double>());

  m.def(
      "predict_residuals",
      [](const Dataset& ds, const std::map<std::string, double>& values) {
        std::vector<int> source;
        Eigen::VectorXd r = PredictResiduals(ds, values, &source);
        return py::make_tuple(r, source);
      },
      py::arg("dataset"), py::arg("values"));

  // How many prepared residual rows are alive, and the most at once since the
  // last reset (solve/analytic_residuals.h): what shows that the streaming
  // fit of a long dataset holds a chunk of them per thread, not one per sample.
  m.def(
      "prepared_rows",
      [](bool reset_peak) {
        if (reset_peak) ResetPreparedRowsPeak();
        py::dict d;
        d["alive"] = PreparedRowsAlive();
        d["peak"] = PreparedRowsPeak();
        d["chunk"] = kPreparedChunk;
        return d;
      },
      py::arg("reset_peak") = false);
}
