// Bindings of the identification engine: Dataset, Simulate, Identify, Result.
#include <algorithm>
#include <limits>
#include <optional>

#include <pybind11/eigen.h>
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include "fivecal/observations/dataset.h"
#include "fivecal/observations/registry.h"
#include "fivecal/solve/identify.h"
#include "fivecal/solve/priors.h"
#include "fivecal/observations/simulate.h"
#include "identify_options.h"

namespace py = pybind11;
using namespace fivecal;

void BindIdentification(py::module_& m) {
  py::class_<Dataset>(m, "Dataset")
      .def_static("from_json", &Dataset::FromJson, py::arg("text"),
                  py::arg("require_observations") = true)
      .def("to_json", &Dataset::ToJson)
      .def("subset", &Dataset::Subset, py::arg("indices"))
      .def_static(
          "balls",
          [](const Machine& m, const std::string& type, const std::string& setup,
             const Eigen::MatrixXd& axes, const std::optional<Eigen::MatrixXi>& dirs,
             const Eigen::Vector3d& tool_ball, const Eigen::Vector3d& table_ball, double length,
             const Eigen::MatrixXd& values, const std::optional<Eigen::MatrixXd>& sigma) {
            Dataset d(m);
            ObservationType t = type == "dbb" ? ObservationType::kDbb : ObservationType::kBall3d;
            if (type != "dbb" && type != "ball3d")
              throw std::invalid_argument("ball samples: type must be 'dbb' or 'ball3d'");
            d.AppendBallSamples(t, setup, axes, dirs ? &*dirs : nullptr, tool_ball, table_ball,
                                length, values);
            if (sigma) {
              // The declared noise of each sample: N x rows (one value per
              // residual row) or N x 1 (every row of the sample).
              const Eigen::Index n = axes.rows(), rows = ResidualRows(t);
              if (sigma->rows() != n || (sigma->cols() != 1 && sigma->cols() != rows))
                throw std::invalid_argument("ball samples: sigma must be " + std::to_string(n) + " x " +
                                            (rows == 1 ? "1" : "1 or " + std::to_string(rows)) + ", got " +
                                            std::to_string(sigma->rows()) + " x " +
                                            std::to_string(sigma->cols()));
              for (Eigen::Index r = 0; r < n; ++r)
                d.observations[r].sigma = sigma->cols() == rows ? Eigen::VectorXd(sigma->row(r).transpose())
                                                                : Eigen::VectorXd::Constant(rows, (*sigma)(r, 0));
            }
            d.Validate();  // names the sample of a sigma out of range
            return d;
          },
          py::arg("machine"), py::arg("type"), py::arg("setup"), py::arg("axes"),
          py::arg("directions"), py::arg("tool_ball"), py::arg("table_ball"), py::arg("length"),
          py::arg("values"), py::arg("sigma") = std::nullopt)
      .def(
          "columns",
          // The observations as arrays (what the plausibility checks read):
          // 10^6 observations without a JSON round trip. Every observation
          // has axes, a type code (ObservationType order) and a target index
          // (facet, sphere or cylinder, else -1); the ball-bar and 3D ball fields only
          // exist for the rows listed in "ball" (NaN where not of its type).
          [](const Dataset& d) {
            const Eigen::Index n = static_cast<Eigen::Index>(d.observations.size());
            const int na = d.machine().num_axes();
            using RowMajor = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;
            RowMajor axes(n, na);
            Eigen::VectorXi type(n), target(n);
            std::vector<int> ball;
            for (Eigen::Index i = 0; i < n; ++i) {
              const Observation& o = d.observations[i];
              axes.row(i) = o.axes.transpose();
              type[i] = static_cast<int>(o.type);
              target[i] = o.type == ObservationType::kFacet      ? d.artefact.FacetIndex(o.target)
                          : o.type == ObservationType::kSphere   ? d.artefact.SphereIndex(o.target)
                          : o.type == ObservationType::kCylinder ? d.artefact.CylinderIndex(o.target)
                                                                 : -1;
              if (o.type == ObservationType::kDbb || o.type == ObservationType::kBall3d)
                ball.push_back(static_cast<int>(i));
            }
            const Eigen::Index k = static_cast<Eigen::Index>(ball.size());
            const double nan = std::numeric_limits<double>::quiet_NaN();
            Eigen::VectorXd reading = Eigen::VectorXd::Constant(k, nan), length = reading;
            RowMajor measured = RowMajor::Constant(k, 3, nan), tool(k, 3), table(k, 3);
            for (Eigen::Index j = 0; j < k; ++j) {
              const Observation& o = d.observations[ball[j]];
              if (o.type == ObservationType::kDbb) {
                reading[j] = o.reading;
                length[j] = o.length;
              } else {
                measured.row(j) = o.measured.transpose();
              }
              tool.row(j) = o.tool_ball.transpose();
              table.row(j) = o.table_ball.transpose();
            }
            py::dict out;
            out["axes"] = axes;
            out["type"] = type;
            out["target"] = target;
            out["ball"] = Eigen::VectorXi(Eigen::Map<const Eigen::VectorXi>(ball.data(), k));
            out["reading"] = reading;
            out["length"] = length;
            out["measured"] = measured;
            out["tool_ball"] = tool;
            out["table_ball"] = table;
            return out;
          })
      .def_property_readonly("machine", &Dataset::machine)
      .def_readonly("tip_radius", &Dataset::tip_radius)
      .def_property_readonly("num_observations",
                             [](const Dataset& d) { return d.observations.size(); })
      .def_property_readonly("observation_types", [](const Dataset& d) {
        std::vector<std::string> t;
        for (const auto& o : d.observations) t.push_back(ObservationTypeName(o.type));
        return t;
      });

  // The registered observation kinds (observations/registry.cc): what a
  // report needs to label and scale their rows.
  m.def("observation_kinds", [] {
    py::list out;
    for (const ObservationKind* k : ObservationKinds()) {
      py::dict d;
      d["name"] = k->name();
      d["code"] = static_cast<int>(k->type());  // the type code of Dataset.columns
      d["label"] = k->label();
      d["unit"] = k->unit();
      d["rows"] = k->rows();
      d["default_sigma"] = k->default_sigma();
      d["noise_class"] = k->noise_class();
      d["noise_classes"] = k->noise_classes();
      // Per residual row: its unit and its simulator noise class.
      std::vector<std::string> units, classes;
      for (int r = 0; r < k->rows(); ++r) {
        units.push_back(k->unit_row(r));
        classes.push_back(k->noise_class_row(r));
      }
      d["row_units"] = units;
      d["row_noise_classes"] = classes;
      // The keys of a dataset observation and of a plan entry: the schemas
      // of a kind no schema file describes are built from them.
      const auto keys = k->json_keys();
      d["json_keys"] = std::vector<std::string>(keys.begin(), keys.end());
      const auto plan = k->plan_keys();
      d["plan_keys"] = std::vector<std::string>(plan.begin(), plan.end());
      out.append(d);
    }
    return out;
  });

  m.def("noise_classes", &NoiseClasses);
  // class -> "mm" | "rad": which simulator noise levels are in rad.
  m.def("noise_class_units", [] {
    std::map<std::string, std::string> out;
    for (const std::string& c : NoiseClasses()) out[c] = NoiseClassUnit(c);
    return out;
  });

  m.def("simulate", &Simulate, py::arg("spec_json"), py::call_guard<py::gil_scoped_release>());

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
  // The unit of a setup parameter's prior class ("mm", "rad"; "" for a name
  // of no kind): how reports show it, whatever kind it belongs to.
  m.def("setup_parameter_unit", [](const std::string& name) {
    for (const ObservationKind* k : ObservationKinds())
      if (const char* cls = k->PriorClassOfName(name))
        for (const PriorClass& c : k->prior_classes())
          if (c.name == cls) return c.unit;
    return std::string();
  });
  // Machine.theta skips these (a result's set-up values) and refuses any
  // other unknown name, so a typo such as EX0C.x is never silently dropped.
  m.def("is_setup_parameter_name", &IsSetupParameterName, py::arg("name"));
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
         bool variance_components, const std::string& fit_path) {
        IdentifyOptions o = MakeOptions(estimate, fix, initial, robust, robust_scale, max_iterations,
                                        include_default_setup, selection_tolerance,
                                        allow_unidentifiable, num_threads, priors, prior);
        o.variance_components = variance_components;
        o.fit_path = fit_path;
        py::gil_scoped_release release;
        return Identify(ds, o);
      },
      py::arg("dataset"), py::arg("estimate"), py::arg("fix"), py::arg("initial"),
      py::arg("robust") = "", py::arg("robust_scale") = 0.0, py::arg("max_iterations") = 200,
      py::arg("allow_unidentifiable") = false, py::arg("include_default_setup") = true,
      py::arg("num_threads") = 0, py::arg("selection_tolerance") = IdentifyOptions().selection_tolerance,
      py::arg("priors") = std::map<std::string, double>(), py::arg("prior") = false,
      py::arg("variance_components") = false, py::arg("fit_path") = "auto");

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
}
