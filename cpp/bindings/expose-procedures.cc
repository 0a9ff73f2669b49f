// Bindings of the procedures (fivecal/procedures/): the double ball bar
// algorithms (circle fits, the Jiang & Cripps four-step test, the Wang et al.
// path and planar circular tests), the machine-as-CMM sphere test, the
// sphere check, the R-test, machining tests and probing statistics. Inputs are validated in the core
// (std::invalid_argument -> ValueError).
#include <pybind11/eigen.h>
#include <pybind11/functional.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <limits>
#include <optional>
#include <stdexcept>
#include <tuple>

#include "fivecal/procedures/circle_fit.h"
#include "fivecal/procedures/circular_test.h"
#include "fivecal/observations/dataset.h"
#include "fivecal/procedures/dbb_four_step.h"
#include "fivecal/procedures/dbb_setup.h"
#include "fivecal/procedures/machining_test.h"
#include "fivecal/procedures/probing_stats.h"
#include "fivecal/procedures/rtest.h"
#include "fivecal/procedures/sphere_check.h"
#include "fivecal/procedures/sphere_test.h"
#include "fivecal/procedures/wang_path.h"
#include "fivecal/solve/identify.h"

namespace py = pybind11;
using namespace fivecal;

namespace {

ARemoval ParseRemoval(const std::string& s) {
  if (s == "full") return ARemoval::kFull;
  if (s == "position") return ARemoval::kPositionOnly;
  if (s == "none") return ARemoval::kNone;
  throw std::invalid_argument("a_removal: '" + s + "' (expected full, position or none)");
}

Eigen::Vector3d OptionalVector(const std::optional<Eigen::Vector3d>& v) {
  return v ? *v : Eigen::Vector3d::Constant(std::numeric_limits<double>::quiet_NaN());
}

char AxisLetter(const std::string& axis) {
  if (axis.size() != 1) throw std::invalid_argument("axis: '" + axis + "' is not one axis letter");
  return axis[0];
}

Eigen::MatrixXd Stack(const std::vector<Eigen::Vector3d>& v) {
  Eigen::MatrixXd m(v.size(), 3);
  for (size_t i = 0; i < v.size(); ++i) m.row(i) = v[i].transpose();
  return m;
}

}  // namespace

void BindProcedures(py::module_& m) {
  // ---- double ball bar ------------------------------------------------------------
  py::class_<CircleFit>(m, "CircleFit")
      .def_readonly("centre", &CircleFit::centre)
      .def_readonly("radius", &CircleFit::radius)
      .def_readonly("residuals", &CircleFit::residuals)
      .def_readonly("rms", &CircleFit::rms)
      .def_readonly("covariance", &CircleFit::covariance)
      .def_readonly("iterations", &CircleFit::iterations);
  m.def(
      "fit_circle",
      [](const Eigen::MatrixXd& points, const std::string& method) {
        if (method == "algebraic") return FitCircleAlgebraic(points);
        if (method == "geometric") return FitCircleGeometric(points);
        throw std::invalid_argument("fit_circle.method: '" + method + "' (algebraic or geometric)");
      },
      py::arg("points"), py::arg("method") = "algebraic");

  py::class_<FourStepStep>(m, "FourStepStep")
      .def_readonly("setup", &FourStepStep::setup)
      .def_property_readonly("axis", [](const FourStepStep& s) { return std::string(1, s.axis); })
      .def_readonly("extended", &FourStepStep::extended)
      .def_readonly("spindle_ball", &FourStepStep::spindle_ball)
      .def_readonly("e1", &FourStepStep::e1)
      .def_readonly("e2", &FourStepStep::e2)
      .def_readonly("normal", &FourStepStep::normal)
      .def_readonly("nominal_radius", &FourStepStep::nominal_radius)
      .def_readonly("start_angle_error", &FourStepStep::start_angle_error)
      .def_readonly("arm", &FourStepStep::arm)
      .def_readonly("angles", &FourStepStep::angles)
      .def_readonly("points", &FourStepStep::points)
      .def_readonly("centre", &FourStepStep::centre)
      .def_readonly("radius", &FourStepStep::radius)
      .def_readonly("residuals", &FourStepStep::residuals)
      .def_readonly("rms", &FourStepStep::rms)
      .def_readonly("centre_covariance", &FourStepStep::centre_covariance)
      .def_readonly("observations", &FourStepStep::observations);
  py::class_<FourStepResult>(m, "FourStepResult")
      .def_readonly("carrier", &FourStepResult::carrier)
      .def_readonly("carried", &FourStepResult::carried)
      .def_readonly("tool_side", &FourStepResult::tool_side)
      .def_readonly("steps", &FourStepResult::steps)
      .def_readonly("a_oe", &FourStepResult::a_oe)
      .def_readonly("c_oe", &FourStepResult::c_oe)
      .def_readonly("a_direction", &FourStepResult::a_direction)
      .def_readonly("c_direction", &FourStepResult::c_direction)
      .def_readonly("a_point", &FourStepResult::a_point)
      .def_readonly("c_point", &FourStepResult::c_point)
      .def_readonly("a_delta", &FourStepResult::a_delta)
      .def_readonly("c_delta", &FourStepResult::c_delta)
      .def_readonly("names", &FourStepResult::names)
      .def_readonly("values", &FourStepResult::values)
      .def_readonly("std", &FourStepResult::std)
      .def_readonly("covariance", &FourStepResult::covariance);
  m.def(
      "four_step",
      [](const Dataset& ds, const std::vector<std::string>& setups,
         const std::map<std::string, double>& length_offsets, const Eigen::Vector2d& a_pivot_offset,
         const Eigen::Vector2d& c_pivot_offset, bool uniform_angles, bool refer_positions,
         const std::string& a_removal) {
        FourStepOptions o;
        if (!setups.empty() && setups.size() != 4)
          throw std::invalid_argument(
              "setups: expected four ids (carrier, carrier extended, carried, carried extended)");
        if (!setups.empty()) {
          o.a_setup = setups[0];
          o.a_extended_setup = setups[1];
          o.c_setup = setups[2];
          o.c_extended_setup = setups[3];
        }
        o.length_offsets = length_offsets;
        o.a_pivot_offset = a_pivot_offset;
        o.c_pivot_offset = c_pivot_offset;
        o.uniform_angles = uniform_angles;
        o.refer_positions = refer_positions;
        o.a_removal = ParseRemoval(a_removal);
        py::gil_scoped_release release;
        return AnalyzeFourStep(ds, o);
      },
      py::arg("dataset"), py::arg("setups"), py::arg("length_offsets"), py::arg("a_pivot_offset"),
      py::arg("c_pivot_offset"), py::arg("uniform_angles"), py::arg("refer_positions"),
      py::arg("a_removal"));
  m.def("four_step_parameter_names", [] { return FourStepParameterNames(); });
  m.def(
      "four_step_pair",
      [](const Machine& mc) {
        const FourStepPair t = RequireFourStepPair(mc, "four-step");
        py::dict d;
        d["carrier"] = std::string(1, mc.axis(t.carrier).name);
        d["carried"] = std::string(1, mc.axis(t.carried).name);
        d["tool_side"] = t.tool_side;
        d["setups"] = t.DefaultSetups(mc);
        d["names"] = FourStepParameterNames(mc);
        return d;
      },
      py::arg("machine"));
  m.def(
      "four_step_plan",
      [](const Machine& mc, double length, double extended_length, double a_start, double a_end,
         double c_start, double c_end, double step, const std::optional<Eigen::Vector3d>& a_pivot,
         const std::optional<Eigen::Vector3d>& c_pivot, const std::optional<Eigen::Vector3d>& tool_ball,
         double a_extension_sign, double c_extension_sign, const std::vector<std::string>& setups) {
        FourStepPlanOptions o;
        o.length = length;
        o.extended_length = extended_length;
        o.a_start = a_start;
        o.a_end = a_end;
        o.c_start = c_start;
        o.c_end = c_end;
        o.step = step;
        o.a_pivot = OptionalVector(a_pivot);
        o.c_pivot = OptionalVector(c_pivot);
        o.tool_ball = OptionalVector(tool_ball);
        o.a_extension_sign = a_extension_sign;
        o.c_extension_sign = c_extension_sign;
        if (!setups.empty() && setups.size() != 4)
          throw std::invalid_argument(
              "setups: expected four ids (carrier, carrier extended, carried, carried extended)");
        if (!setups.empty()) {
          o.a_setup = setups[0];
          o.a_extended_setup = setups[1];
          o.c_setup = setups[2];
          o.c_extended_setup = setups[3];
        }
        return FourStepPlanJson(mc, o);
      },
      py::arg("machine"), py::arg("length"), py::arg("extended_length"), py::arg("a_start"),
      py::arg("a_end"), py::arg("c_start"), py::arg("c_end"), py::arg("step"), py::arg("a_pivot"),
      py::arg("c_pivot"), py::arg("tool_ball"), py::arg("a_extension_sign"),
      py::arg("c_extension_sign"), py::arg("setups"));

  py::class_<WangPath>(m, "WangPath")
      .def_property_readonly("tilt_axis", [](const WangPath& p) { return std::string(1, p.tilt_axis); })
      .def_property_readonly("rotary_axis", [](const WangPath& p) { return std::string(1, p.rotary_axis); })
      .def_readonly("tracking", &WangPath::tracking)
      .def_readonly("tilt", &WangPath::tilt)
      .def_readonly("rotary", &WangPath::rotary)
      .def_readonly("other_tilt", &WangPath::other_tilt)
      .def_readonly("other_rotary", &WangPath::other_rotary)
      .def_readonly("tilt_direction", &WangPath::tilt_direction)
      .def_readonly("rotary_direction", &WangPath::rotary_direction)
      .def_readonly("pivot", &WangPath::pivot)
      .def_readonly("centre", &WangPath::centre)
      .def_readonly("normal", &WangPath::normal)
      .def_readonly("e1", &WangPath::e1)
      .def_readonly("e2", &WangPath::e2)
      .def_readonly("spindle_ball", &WangPath::spindle_ball)
      .def_readonly("radius", &WangPath::radius)
      .def_readonly("height", &WangPath::height)
      .def_readonly("bar_length", &WangPath::bar_length)
      .def_readonly("max_circle_error", &WangPath::max_circle_error);
  m.def(
      "wang_path",
      [](const Machine& mc, const Eigen::Vector3d& table_ball, double radius, double height,
         double start, double end, double step, double start_tilt, double start_rotary) {
        WangPathOptions o;
        o.table_ball = table_ball;
        o.radius = radius;
        o.height = height;
        o.start = start;
        o.end = end;
        o.step = step;
        o.start_tilt = start_tilt;
        o.start_rotary = start_rotary;
        return ComputeWangPath(mc, o);
      },
      py::arg("machine"), py::arg("table_ball"), py::arg("radius"), py::arg("height"),
      py::arg("start"), py::arg("end"), py::arg("step"), py::arg("start_tilt"),
      py::arg("start_rotary"));

  py::class_<WangFourPoint>(m, "WangFourPoint")
      .def_readonly("singular_values", &WangFourPoint::singular_values)
      .def_readonly("rank", &WangFourPoint::rank)
      .def_readonly("null_space", &WangFourPoint::null_space)
      .def_readonly("estimable", &WangFourPoint::estimable)
      .def_readonly("solved", &WangFourPoint::solved)
      .def_readonly("values", &WangFourPoint::values);
  m.def(
      "wang_four_point",
      [](const Eigen::MatrixXd& sensitivity, const Eigen::VectorXd& scale,
         const std::optional<Eigen::VectorXd>& readings) {
        return AnalyzeWangFourPoint(sensitivity, scale, readings ? &*readings : nullptr);
      },
      py::arg("sensitivity"), py::arg("scale"), py::arg("readings") = py::none(),
      "The Wang et al. four-point equations S e = r analysed (wang_path.h AnalyzeWangFourPoint).");

  py::class_<CircularRunResult>(m, "CircularRunResult")
      .def_readonly("direction", &CircularRunResult::direction)
      .def_readonly("centre", &CircularRunResult::centre)
      .def_readonly("mean_radius", &CircularRunResult::mean_radius)
      .def_readonly("circular_deviation", &CircularRunResult::circular_deviation)
      .def_readonly("radial_deviation_max", &CircularRunResult::radial_deviation_max)
      .def_readonly("radial_deviation_min", &CircularRunResult::radial_deviation_min)
      .def_readonly("radial", &CircularRunResult::radial);
  py::class_<CircularDiagnosis>(m, "CircularDiagnosis")
      .def_readonly("names", &CircularDiagnosis::names)
      .def_readonly("values", &CircularDiagnosis::values)
      .def_readonly("std", &CircularDiagnosis::std)
      .def_readonly("not_fitted", &CircularDiagnosis::not_fitted)
      .def_readonly("not_significant", &CircularDiagnosis::not_significant)
      .def_readonly("rms", &CircularDiagnosis::rms)
      .def_readonly("ranking", &CircularDiagnosis::ranking)
      .def_readonly("contribution", &CircularDiagnosis::contribution)
      .def_readonly("contribution_percent", &CircularDiagnosis::contribution_percent)
      .def_readonly("circularity", &CircularDiagnosis::circularity)
      .def_readonly("derived_names", &CircularDiagnosis::derived_names)
      .def_readonly("derived_values", &CircularDiagnosis::derived_values)
      .def_readonly("derived_std", &CircularDiagnosis::derived_std)
      .def_readonly("dropped_names", &CircularDiagnosis::dropped_names)
      .def_readonly("dropped_values", &CircularDiagnosis::dropped_values)
      .def_readonly("dropped_std", &CircularDiagnosis::dropped_std);
  py::class_<CircularTestResult>(m, "CircularTestResult")
      .def_readonly("nominal_radius", &CircularTestResult::nominal_radius)
      .def_readonly("runs", &CircularTestResult::runs)
      .def_readonly("hysteresis", &CircularTestResult::hysteresis)
      .def_readonly("has_hysteresis", &CircularTestResult::has_hysteresis)
      .def_readonly("diagnosis", &CircularTestResult::diagnosis)
      .def_readonly("cyclic_pitch1", &CircularTestResult::cyclic_pitch1)
      .def_readonly("cyclic_pitch2", &CircularTestResult::cyclic_pitch2)
      .def_readonly("cyclic_pitches_tried1", &CircularTestResult::cyclic_pitches_tried1)
      .def_readonly("cyclic_pitches_tried2", &CircularTestResult::cyclic_pitches_tried2);
  m.def(
      "circular_test",
      [](const std::vector<std::tuple<Eigen::VectorXd, Eigen::VectorXd, int>>& runs, double radius,
         double feed, bool reversal_spikes, double spike_width, bool lateral_play, bool straightness,
         bool radial_play, double cyclic_pitch1, double cyclic_pitch2, double significance,
         bool search_cyclic_pitch1, bool search_cyclic_pitch2) {
        std::vector<CircularRun> rs;
        for (const auto& t : runs) {
          CircularRun r;
          r.angles = std::get<0>(t);
          r.readings = std::get<1>(t);
          r.direction = std::get<2>(t);
          rs.push_back(r);
        }
        CircularDiagnosisOptions o;
        o.reversal_spikes = reversal_spikes;
        o.spike_width = spike_width;
        o.lateral_play = lateral_play;
        o.straightness = straightness;
        o.radial_play = radial_play;
        o.cyclic_pitch1 = cyclic_pitch1;
        o.cyclic_pitch2 = cyclic_pitch2;
        o.significance = significance;
        o.search_cyclic_pitch1 = search_cyclic_pitch1;
        o.search_cyclic_pitch2 = search_cyclic_pitch2;
        py::gil_scoped_release release;
        return AnalyzeCircularTest(rs, radius, feed, o);
      },
      py::arg("runs"), py::arg("radius"), py::arg("feed") = 0.0, py::arg("reversal_spikes") = true,
      py::arg("spike_width") = 3.0, py::arg("lateral_play") = true, py::arg("straightness") = true,
      py::arg("radial_play") = true, py::arg("cyclic_pitch1") = 0.0, py::arg("cyclic_pitch2") = 0.0,
      py::arg("significance") = 3.0, py::arg("search_cyclic_pitch1") = false,
      py::arg("search_cyclic_pitch2") = false);
  m.def(
      "trim_overshoot",
      [](const Eigen::VectorXd& angles, const Eigen::VectorXd& readings, int direction, double data_arc,
         double feed_in) {
        CircularRun r;
        r.angles = angles;
        r.readings = readings;
        r.direction = direction;
        const TrimmedRun t = TrimOvershoot(r, data_arc, feed_in);
        py::dict d;
        d["angles"] = t.run.angles;
        d["readings"] = t.run.readings;
        d["direction"] = t.run.direction;
        d["removed_start"] = t.removed_start;
        d["removed_end"] = t.removed_end;
        d["arc_start"] = t.arc_start;
        d["arc_end"] = t.arc_end;
        d["data_first"] = t.data_first;
        d["data_last"] = t.data_last;
        return d;
      },
      py::arg("angles"), py::arg("readings"), py::arg("direction"), py::arg("data_arc") = 360.0,
      py::arg("feed_in") = std::numeric_limits<double>::quiet_NaN(),
      "Feed-in and feed-out arcs removed from a run (circular_test.h TrimOvershoot).");
  m.def(
      "dbb_ball_positions",
      [](const Machine& mc, const Eigen::MatrixXd& axes, const Eigen::Vector3d& tool_ball,
         const Eigen::Vector3d& table_ball) {
        if (axes.cols() != mc.num_axes())
          throw std::invalid_argument("axes: expected N x " + std::to_string(mc.num_axes()) + " (" +
                                      mc.axis_names() + ")");
        Eigen::MatrixXd S(axes.rows(), 3), B(axes.rows(), 3);
        for (int i = 0; i < axes.rows(); ++i) {
          const Eigen::VectorXd q = axes.row(i).transpose();
          S.row(i) = NominalToolBallInF(mc, q, tool_ball).transpose();
          B.row(i) = NominalTableBallInF(mc, q, table_ball).transpose();
        }
        return py::make_tuple(S, B);
      },
      py::arg("machine"), py::arg("axes"), py::arg("tool_ball"), py::arg("table_ball"),
      "Nominal spindle-ball and table-ball positions in F (N x 3 each, mm).");
  m.def("bar_length_commands", &BarLengthCommands, py::arg("machine"), py::arg("tool_ball"),
        py::arg("table_ball"), py::arg("length"), py::arg("poses"),
        "Poses (N x num_axes) with the linear axes moved along the bar to the nominal `length` "
        "(dbb_setup.h BarLengthCommands).");
  m.def(
      "diagnosis_contribution",
      [](const std::string& name, double value, double radius, double spike_width, double cyclic_pitch1,
         double cyclic_pitch2) {
        CircularDiagnosisOptions o;
        o.spike_width = spike_width;
        o.cyclic_pitch1 = cyclic_pitch1;
        o.cyclic_pitch2 = cyclic_pitch2;
        return DiagnosisContribution(name, value, radius, o);
      },
      py::arg("name"), py::arg("value"), py::arg("radius"), py::arg("spike_width") = 3.0,
      py::arg("cyclic_pitch1") = 0.0, py::arg("cyclic_pitch2") = 0.0,
      "Contribution to circularity (mm) of one diagnosis alone (circular_test.h DiagnosisContribution).");
  m.def(
      "compensate_bar_temperature",
      [](const Eigen::VectorXd& readings, double nominal_length, double alpha_bar, double t_bar,
         double alpha_machine, double t_machine, double t_ref) {
        BarThermal th;
        th.alpha_bar = alpha_bar;
        th.t_bar = t_bar;
        th.alpha_machine = alpha_machine;
        th.t_machine = t_machine;
        th.t_ref = t_ref;
        return CompensateBarTemperature(readings, nominal_length, th);
      },
      py::arg("readings"), py::arg("nominal_length"), py::arg("alpha_bar"), py::arg("t_bar"),
      py::arg("alpha_machine"), py::arg("t_machine"), py::arg("t_ref") = 20.0,
      "Ball bar readings referred to 20 deg C (circular_test.h CompensateBarTemperature).");
  m.def("trace_harmonics", &TraceHarmonics, py::arg("angles"), py::arg("values"),
        py::arg("max_order"));

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

  // ---- sphere check and R-test ----------------------------------------------------
  m.def("spindle_equivalent", &SpindleEquivalent, py::arg("machine"), py::arg("name"));
  m.def("spindle_names", &SpindleNames, py::arg("machine"), py::arg("errors"));
  m.def(
      "checked_rotary_axes",
      [](const Machine& mc) {
        std::vector<std::string> out;
        for (char a : CheckedRotaryAxes(mc)) out.emplace_back(1, a);
        return out;
      },
      py::arg("machine"));
  m.def(
      "pivot_parameters",
      [](const Machine& mc, const std::string& axis, bool backlash) {
        return PivotParameters(mc, AxisLetter(axis), backlash);
      },
      py::arg("machine"), py::arg("axis"), py::arg("backlash") = true);

  py::class_<SphereCheckValue>(m, "SphereCheckValue")
      .def_readonly("name", &SphereCheckValue::name)
      .def_readonly("value", &SphereCheckValue::value)
      .def_readonly("std", &SphereCheckValue::std);
  py::class_<SphereCheckAxis>(m, "SphereCheckAxis")
      .def_property_readonly("axis", [](const SphereCheckAxis& a) { return std::string(1, a.axis); })
      .def_readonly("pivot", &SphereCheckAxis::pivot)
      .def_readonly("has_backlash", &SphereCheckAxis::has_backlash)
      .def_readonly("backlash", &SphereCheckAxis::backlash);
  py::class_<SphereCheckResult>(m, "SphereCheckResult")
      .def_readonly("fit", &SphereCheckResult::fit)
      .def_readonly("sphere", &SphereCheckResult::sphere)
      .def_readonly("estimate", &SphereCheckResult::estimate)
      .def_readonly("axes", &SphereCheckResult::axes)
      .def_readonly("change", &SphereCheckResult::change)
      .def_readonly("positions", &SphereCheckResult::positions)
      .def_readonly("centres_before", &SphereCheckResult::centres_before)
      .def_readonly("centres_after", &SphereCheckResult::centres_after)
      .def_readonly("dispersion_before", &SphereCheckResult::dispersion_before)
      .def_readonly("dispersion_after", &SphereCheckResult::dispersion_after)
      .def_readonly("condition_number", &SphereCheckResult::condition_number)
      .def_readonly("informed", &SphereCheckResult::informed);
  m.def(
      "sphere_check",
      [](const Dataset& ds, const std::string& sphere, bool calibrated_stylus, int backlash,
         const std::map<std::string, std::pair<double, double>>& previous) {
        SphereCheckOptions o;
        o.sphere = sphere;
        o.calibrated_stylus = calibrated_stylus;
        o.backlash = backlash;
        o.previous = previous;
        py::gil_scoped_release release;
        return EvaluateSphereCheck(ds, o);
      },
      py::arg("dataset"), py::arg("sphere") = "", py::arg("calibrated_stylus") = true, py::arg("backlash") = -1,
      py::arg("previous") = std::map<std::string, std::pair<double, double>>{},
      "The sphere check's evaluation (procedures/sphere_check.h EvaluateSphereCheck).");
  m.def(
      "sphere_check_positions",
      [](const Machine& mc, int n, const std::map<std::string, std::pair<double, double>>& limits) {
        std::vector<std::pair<std::string, std::vector<double>>> out;
        for (auto& [a, v] : SphereCheckPositions(mc, n, limits)) out.emplace_back(std::string(1, a), std::move(v));
        return out;
      },
      py::arg("machine"), py::arg("n"), py::arg("limits") = std::map<std::string, std::pair<double, double>>{},
      "A sphere check's positions per rotary axis (procedures/sphere_check.h SphereCheckPositions).");
  m.attr("sphere_check_max_positions") = kMaxSphereCheckPositions;

  py::class_<RTestGroup>(m, "RTestGroup")
      .def_readonly("name", &RTestGroup::name)
      .def_readonly("observations", &RTestGroup::observations)
      .def_readonly("deviations", &RTestGroup::deviations)
      .def_readonly("ranges", &RTestGroup::ranges);
  py::class_<RTestResult>(m, "RTestResult")
      .def_readonly("tests", &RTestResult::tests)
      .def_readonly("identified", &RTestResult::identified)
      .def_readonly("estimated", &RTestResult::estimated)
      .def_readonly("fit", &RTestResult::fit);
  m.def("rtest_location_errors", &RTestLocationErrors, py::arg("machine"));
  m.def(
      "rtest_axis_roles",
      [](const Machine& mc) {
        const RTestRoles r = RTestAxisRoles(mc);
        py::dict d;
        d["turn"] = std::string(1, r.turn);
        d["tilt"] = std::string(1, r.tilt);
        return d;
      },
      py::arg("machine"));
  m.def(
      "rtest_sequence",
      [](const Machine& mc, const std::string& test, double step, double tilt,
         const std::pair<double, double>& tilt_range) {
        return RTestSequence(mc, test, step, tilt, tilt_range.first, tilt_range.second);
      },
      py::arg("machine"), py::arg("test"), py::arg("step"), py::arg("tilt"), py::arg("tilt_range"));
  m.def(
      "rtest_path_commands",
      [](const Machine& mc, const Eigen::MatrixXd& rotary, const Eigen::VectorXd& start,
         const Eigen::Vector3d& table_ball, const Eigen::Vector3d& tool_ball, bool chain) {
        return RTestPathCommands(mc, rotary, start, table_ball, tool_ball, chain);
      },
      py::arg("machine"), py::arg("rotary"), py::arg("start"), py::arg("table_ball"), py::arg("tool_ball"),
      py::arg("chain"), "An R-test path's axis commands (procedures/rtest.h RTestPathCommands).");
  m.def(
      "rtest",
      [](const Dataset& ds, bool identify, const std::vector<std::string>& estimate) {
        RTestOptions o;
        o.identify = identify;
        o.estimate = estimate;
        py::gil_scoped_release release;
        return EvaluateRTest(ds, o);
      },
      py::arg("dataset"), py::arg("identify") = true, py::arg("estimate") = std::vector<std::string>{},
      "The R-test K tests' evaluation (procedures/rtest.h EvaluateRTest).");

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

  // ---- Probing statistics ---------------------------------------------------------------
  py::class_<PooledStd>(m, "PooledStd")
      .def_readonly("pooled_std", &PooledStd::pooled_std)
      .def_readonly("dof", &PooledStd::dof)
      .def_readonly("group_std", &PooledStd::group_std)
      .def_readonly("group_size", &PooledStd::group_size);
  m.def("pooled_std", &PooledStandardDeviation, py::arg("groups"));
  m.def("window_pooled_std", &WindowPooledStd, py::arg("series"), py::arg("window"));

  py::class_<GridStatistics>(m, "GridStatistics")
      .def_readonly("points", &GridStatistics::points)
      .def_readonly("cycles", &GridStatistics::cycles)
      .def_readonly("window", &GridStatistics::window)
      .def_readonly("mean", &GridStatistics::mean)
      .def_readonly("total_std", &GridStatistics::total_std)
      .def_readonly("total_range", &GridStatistics::total_range)
      .def_readonly("point_pooled_std", &GridStatistics::point_pooled_std)
      .def_readonly("max_pooled_std", &GridStatistics::max_pooled_std)
      .def_readonly("pooled_std", &GridStatistics::pooled_std)
      .def_readonly("pooled_dof", &GridStatistics::pooled_dof)
      .def_readonly("point_means", &GridStatistics::point_means)
      .def_readonly("surface_std", &GridStatistics::surface_std)
      .def_readonly("surface_range", &GridStatistics::surface_range)
      .def_readonly("cycle_means", &GridStatistics::cycle_means)
      .def_readonly("drift_std", &GridStatistics::drift_std)
      .def_readonly("drift_range", &GridStatistics::drift_range)
      .def_readonly("point_std", &GridStatistics::point_std)
      .def_readonly("point_std_pooled", &GridStatistics::point_std_pooled)
      .def_readonly("repeatability", &GridStatistics::repeatability)
      .def_readonly("surface_component", &GridStatistics::surface_component)
      .def_readonly("drift_component", &GridStatistics::drift_component)
      .def("to_json", &GridStatistics::ToJson);
  m.def("analyze_grid", &AnalyzeGrid, py::arg("P"), py::arg("window") = 5);
}
