// Bindings of test design (fivecal/design/).
#include <pybind11/eigen.h>
#include <pybind11/functional.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include "fivecal/observations/dataset.h"
#include "fivecal/design/design.h"

namespace py = pybind11;
using namespace fivecal;

namespace {

DesignOptions MakeDesignOptions(const std::vector<std::string>& estimate, const std::vector<std::string>& fix,
                                const std::map<std::string, double>& values, double sigma,
                                double characteristic_length, bool include_default_setup) {
  DesignOptions o;
  o.estimate = estimate;
  o.fix = fix;
  o.values = values;
  o.sigma = sigma;
  o.characteristic_length = characteristic_length;
  o.include_default_setup = include_default_setup;
  return o;
}

std::vector<Eigen::Vector3d> Rows(const Eigen::MatrixXd& m, const char* what) {
  if (m.size() && m.cols() != 3) throw std::invalid_argument(std::string(what) + ": expected N x 3");
  std::vector<Eigen::Vector3d> out;
  for (int i = 0; i < m.rows(); ++i) out.push_back(m.row(i).transpose());
  return out;
}

}  // namespace

void BindDesign(py::module_& m) {
  // ---- design ------------------------------------------------------------
  py::class_<PlanQuality>(m, "PlanQuality")
      .def_readonly("parameters", &PlanQuality::parameters)
      .def_readonly("n_observations", &PlanQuality::n_observations)
      .def_readonly("n_rows", &PlanQuality::n_rows)
      .def_readonly("n_parameters", &PlanQuality::n_parameters)
      .def_readonly("n_machine", &PlanQuality::n_machine)
      .def_readonly("condition_number", &PlanQuality::condition_number)
      .def_readonly("rank", &PlanQuality::rank)
      .def_readonly("log_det_per_parameter", &PlanQuality::log_det_per_parameter)
      .def_readonly("d_criterion", &PlanQuality::d_criterion)
      .def_readonly("d_std", &PlanQuality::d_std)
      .def_readonly("predicted_std", &PlanQuality::predicted_std)
      .def_readonly("confounded", &PlanQuality::confounded)
      .def("to_json", &PlanQuality::ToJson);

  py::class_<DesignResult>(m, "DesignResult")
      .def_readonly("groups", &DesignResult::groups)
      .def_readonly("observations", &DesignResult::observations)
      .def_readonly("quality", &DesignResult::quality)
      .def_readonly("reference", &DesignResult::reference)
      .def_readonly("history", &DesignResult::history)
      .def_readonly("evaluations", &DesignResult::evaluations)
      .def_readonly("stopped", &DesignResult::stopped)
      .def("to_json", &DesignResult::ToJson);

  m.def("characteristic_scale", &CharacteristicScale, py::arg("machine"), py::arg("name"),
        py::arg("length") = 400.0);

  m.def(
      "plan_quality",
      [](const Dataset& ds, const std::vector<std::string>& estimate, const std::vector<std::string>& fix,
         const std::map<std::string, double>& values, double sigma, double characteristic_length,
         bool include_default_setup, const std::optional<std::vector<int>>& subset) {
        const DesignOptions o =
            MakeDesignOptions(estimate, fix, values, sigma, characteristic_length, include_default_setup);
        py::gil_scoped_release release;
        return AssessPlan(ds, o, subset ? &*subset : nullptr);
      },
      py::arg("dataset"), py::arg("estimate"), py::arg("fix") = std::vector<std::string>{},
      py::arg("values") = std::map<std::string, double>{}, py::arg("sigma") = 0.0006,
      py::arg("characteristic_length") = 400.0, py::arg("include_default_setup") = true,
      py::arg("subset") = py::none());

  m.def(
      "design_plan",
      [](const Dataset& ds, const std::vector<int>& group, const std::vector<std::string>& estimate,
         const std::vector<std::string>& fix, const std::map<std::string, double>& values, double sigma,
         double characteristic_length, int k, const std::vector<int>& required, const std::string& criterion,
         const std::string& method, int max_passes, int max_touches,
         const std::function<bool(const std::string&, int, int, double)>& progress) {
        const DesignOptions o = MakeDesignOptions(estimate, fix, values, sigma, characteristic_length, true);
        SearchOptions s;
        s.k = k;
        s.required = required;
        s.criterion = criterion;
        s.method = method;
        s.max_passes = max_passes;
        s.max_touches = max_touches;
        if (progress) {
          s.progress = [progress](const std::string& phase, int done, int total, double best) {
            py::gil_scoped_acquire acquire;
            return progress(phase, done, total, best);
          };
        }
        py::gil_scoped_release release;
        return DesignPlan(ds, group, o, s);
      },
      py::arg("dataset"), py::arg("group"), py::arg("estimate"), py::arg("fix") = std::vector<std::string>{},
      py::arg("values") = std::map<std::string, double>{}, py::arg("sigma") = 0.0006,
      py::arg("characteristic_length") = 400.0, py::arg("k"), py::arg("required") = std::vector<int>{},
      py::arg("criterion") = "condition", py::arg("method") = "exchange", py::arg("max_passes") = 50,
      py::arg("max_touches") = 0, py::arg("progress") = nullptr);

  m.def(
      "candidate_plan",
      [](const Dataset& setup, const Eigen::MatrixXd& indexations, const std::optional<Eigen::MatrixXi>& directions,
         const Eigen::MatrixXd& sphere_normals, const std::map<std::string, std::pair<double, double>>& limits,
         double min_dot, const std::vector<std::string>& targets) {
        Accessibility a;
        for (const auto& [axis, lim] : limits) {
          const char c = axis == "C1" ? 'S' : (axis.size() == 1 ? axis[0] : '?');
          if (c == '?') throw std::invalid_argument("candidate_plan.limits: bad axis name '" + axis + "'");
          a.limits[c] = lim;
        }
        a.min_dot = min_dot;
        a.targets = targets;
        const std::vector<Eigen::Vector3d> normals = Rows(sphere_normals, "sphere_normals");
        std::vector<int> group;
        std::string plan;
        {
          py::gil_scoped_release release;
          plan = CandidatePlan(setup, indexations, directions ? &*directions : nullptr, normals, a, &group);
        }
        return py::make_tuple(plan, group);
      },
      py::arg("setup"), py::arg("indexations"), py::arg("directions"), py::arg("sphere_normals"),
      py::arg("limits"), py::arg("min_dot") = -0.02, py::arg("targets") = std::vector<std::string>{});
}
