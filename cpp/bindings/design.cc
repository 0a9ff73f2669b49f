// Bindings of test design (design.h), the machine-as-CMM sphere test
// (sphere_test.h) and machining tests (machining_test.h).
#include <pybind11/eigen.h>
#include <pybind11/functional.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include "fivecal/observations/dataset.h"
#include "fivecal/design/design.h"
#include "fivecal/procedures/machining_test.h"
#include "fivecal/procedures/sphere_test.h"

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

Eigen::MatrixXd Stack(const std::vector<Eigen::Vector3d>& v) {
  Eigen::MatrixXd m(v.size(), 3);
  for (size_t i = 0; i < v.size(); ++i) m.row(i) = v[i].transpose();
  return m;
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

  // ---- sphere test -------------------------------------------------------------
  py::class_<SphereFit>(m, "SphereFit")
      .def_readonly("center", &SphereFit::center)
      .def_readonly("radius", &SphereFit::radius)
      .def_readonly("residuals", &SphereFit::residuals)
      .def_readonly("out_of_sphericity", &SphereFit::out_of_sphericity)
      .def_readonly("max_residual", &SphereFit::max_residual)
      .def_readonly("min_residual", &SphereFit::min_residual)
      .def_readonly("std_residual", &SphereFit::std_residual)
      .def_readonly("rms", &SphereFit::rms)
      .def_readonly("iterations", &SphereFit::iterations)
      .def_readonly("converged", &SphereFit::converged);

  py::class_<SphereTestResult>(m, "SphereTestResult")
      .def_readonly("sphere", &SphereTestResult::sphere)
      .def_readonly("observations", &SphereTestResult::observations)
      .def_readonly("points", &SphereTestResult::points)
      .def_readonly("fit", &SphereTestResult::fit)
      .def_readonly("size_error", &SphereTestResult::size_error)
      .def("to_json", &SphereTestResult::ToJson);

  m.def(
      "sphere_points",
      [](const std::vector<std::pair<double, int>>& rings, const Eigen::Vector3d& pole) {
        return Stack(SpherePoints(rings, pole));
      },
      py::arg("rings") = std::vector<std::pair<double, int>>{}, py::arg("pole") = Eigen::Vector3d(0, 0, 1));

  m.def("fit_sphere", &FitSphere, py::arg("points"), py::arg("max_iterations") = 50,
        py::arg("tolerance") = 1e-13);

  py::class_<SphereCentreFit>(m, "SphereCentreFit")
      .def_readonly("center", &SphereCentreFit::center)
      .def_readonly("residuals", &SphereCentreFit::residuals)
      .def_readonly("rms", &SphereCentreFit::rms)
      .def_readonly("iterations", &SphereCentreFit::iterations)
      .def_readonly("converged", &SphereCentreFit::converged);
  m.def("fit_sphere_centre", &FitSphereCentre, py::arg("points"), py::arg("radius"), py::arg("start"),
        py::arg("max_iterations") = 50, py::arg("tolerance") = 1e-12);

  m.def("table_points", &TablePoints, py::arg("dataset"), py::arg("values"), py::arg("indices"),
        py::call_guard<py::gil_scoped_release>());

  m.def("sphere_test", &SphereTest, py::arg("dataset"), py::arg("sphere"), py::arg("values"),
        py::call_guard<py::gil_scoped_release>());

  m.def(
      "sphere_sensitivity",
      [](const Dataset& setup, const std::string& plan_json, const std::string& sphere,
         const std::vector<std::string>& names, const std::map<std::string, double>& values,
         double characteristic_length) {
        std::vector<SensitivityRow> rows;
        {
          py::gil_scoped_release release;
          rows = SphereSensitivity(setup, plan_json, sphere, names, values, characteristic_length);
        }
        py::list out;
        for (const SensitivityRow& r : rows) {
          py::dict d;
          d["name"] = r.name;
          d["value"] = r.value;
          d["size_error"] = r.size_error;
          d["out_of_sphericity"] = r.out_of_sphericity;
          d["max_residual"] = r.max_residual;
          d["min_residual"] = r.min_residual;
          out.append(d);
        }
        return out;
      },
      py::arg("setup"), py::arg("plan_json"), py::arg("sphere"), py::arg("names"),
      py::arg("values") = std::map<std::string, double>{}, py::arg("characteristic_length") = 400.0);

  // ---- machining tests ------------------------------------------------------------
  py::class_<MachiningTest>(m, "MachiningTest")
      .def(py::init([](const std::string& id, const Eigen::Vector3d& point, const Eigen::Vector3d& direction,
                       const Eigen::VectorXd& pose, const std::optional<Eigen::VectorXd>& reference,
                       double measured) {
             MachiningTest t;
             t.id = id;
             t.point = point;
             t.direction = direction;
             t.pose = pose;
             if (reference) t.reference = *reference;
             t.measured = measured;
             return t;
           }),
           py::arg("id"), py::arg("point"), py::arg("direction"), py::arg("pose"),
           py::arg("reference") = py::none(), py::arg("measured") = 0.0)
      .def_readonly("id", &MachiningTest::id)
      .def_readonly("point", &MachiningTest::point)
      .def_readonly("direction", &MachiningTest::direction)
      .def_readonly("pose", &MachiningTest::pose)
      .def_readonly("reference", &MachiningTest::reference)
      .def_readonly("measured", &MachiningTest::measured);

  py::class_<MachiningResult>(m, "MachiningResult")
      .def_readonly("estimated", &MachiningResult::estimated)
      .def_readonly("values", &MachiningResult::values)
      .def_readonly("std", &MachiningResult::std)
      .def_readonly("covariance", &MachiningResult::covariance)
      .def_readonly("predicted", &MachiningResult::predicted)
      .def_readonly("residuals", &MachiningResult::residuals)
      .def_readonly("sigma", &MachiningResult::sigma)
      .def_readonly("condition_number", &MachiningResult::condition_number)
      .def_readonly("rank", &MachiningResult::rank)
      .def_readonly("converged", &MachiningResult::converged)
      .def_readonly("iterations", &MachiningResult::iterations)
      .def("to_json", &MachiningResult::ToJson);

  m.def("workpiece_setup_names", &WorkpieceSetupNames);
  m.def("zhang_zhang_tests", &ZhangZhangTests, py::arg("machine"), py::arg("L"), py::arg("H"));
  m.def("zhang_zhang_first_order", &ZhangZhangFirstOrder, py::arg("L"), py::arg("H"), py::arg("a_delta"),
        py::arg("a_xi"), py::arg("c_delta"), py::arg("c_xi"));
  m.def("machining_poses", &MachiningPoses, py::arg("machine"), py::arg("tests"));
  m.def("predict_machining", &PredictMachining, py::arg("machine"), py::arg("tests"), py::arg("values"),
        py::call_guard<py::gil_scoped_release>());
  m.def("machining_jacobian", &MachiningJacobian, py::arg("machine"), py::arg("tests"), py::arg("names"),
        py::arg("values"), py::call_guard<py::gil_scoped_release>());
  m.def(
      "identify_machining",
      [](const Machine& mc, const std::vector<MachiningTest>& tests, const std::vector<std::string>& estimate,
         const std::map<std::string, double>& values, double sigma, int max_iterations) {
        MachiningOptions o;
        o.estimate = estimate;
        o.values = values;
        o.sigma = sigma;
        o.max_iterations = max_iterations;
        py::gil_scoped_release release;
        return IdentifyMachining(mc, tests, o);
      },
      py::arg("machine"), py::arg("tests"), py::arg("estimate"), py::arg("values"), py::arg("sigma") = 0.0,
      py::arg("max_iterations") = 50);
}
