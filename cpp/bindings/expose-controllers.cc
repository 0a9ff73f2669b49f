// Bindings of the controller models (fivecal/controllers/): LinuxCNC's
// xyzac-trt / xyzbc-trt kinematics, the mapping of a fivecal machine onto
// them and the pin values that best absorb identified errors. Pins cross the
// boundary as dicts keyed by LinuxCNC's pin names ("x-rot-point", ...).
#include <pybind11/eigen.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <algorithm>
#include <map>
#include <optional>
#include <string>

#include "fivecal/controllers/absorb.h"
#include "fivecal/controllers/compensate.h"
#include "fivecal/controllers/kinematics_table.h"
#include "fivecal/controllers/linuxcnc_5axis.h"
#include "fivecal/controllers/linuxcnc_trt.h"
#include "fivecal/controllers/vendor.h"
#include "fivecal/controllers/verify.h"
#include "fivecal/model/machine.h"

namespace py = pybind11;
using namespace fivecal;
using namespace fivecal::controllers;

namespace {

TrtPins PinsFromMap(TrtKins kins, const std::map<std::string, double>& d) {
  TrtPins p;
  const std::vector<std::string> names = TrtPinNames(kins);
  for (const auto& [k, v] : d) {
    if (std::find(names.begin(), names.end(), k) == names.end())
      throw std::invalid_argument("pins: '" + k + "' is not a pin of " + TrtKinsName(kins) +
                                  "-kins");
    RequireBounded(v, kMaxLinear, "pins." + k);
    TrtPin(p, k) = v;
  }
  return p;
}

std::map<std::string, double> PinsToMap(TrtKins kins, const TrtPins& p) {
  std::map<std::string, double> d;
  for (const std::string& n : TrtPinNames(kins)) d[n] = TrtPin(p, n);
  return d;
}

py::dict TrtFitDict(TrtKins kins, const TrtFit& fit) {
  py::dict d;
  d["pins"] = PinsToMap(kins, fit.pins);
  d["solved"] = fit.solved;
  d["workpiece_shift"] = Eigen::Vector3d(fit.workpiece_shift);
  d["workpiece_shift_held"] = Eigen::Vector3d(fit.workpiece_shift_held);
  d["residual"] = fit.residual;
  d["residual_held"] = fit.residual_held;
  d["rms"] = fit.rms;
  d["max"] = fit.max;
  d["rms_held"] = fit.rms_held;
  d["max_held"] = fit.max_held;
  return d;
}

py::list VendorValueList(const std::vector<VendorValue>& values) {
  py::list l;
  for (const VendorValue& v : values) {
    py::dict d;
    d["name"] = v.name;
    d["unit"] = v.unit;
    d["source"] = v.source;
    d["fixed"] = v.fixed;
    d["motion"] = v.motion;
    l.append(d);
  }
  return l;
}

py::list ParameterList(const std::vector<ControllerParameter>& params) {
  py::list l;
  for (const ControllerParameter& p : params) {
    py::dict d;
    d["label"] = p.label;
    d["unit"] = p.unit;
    d["column"] = p.column;
    l.append(d);
  }
  return l;
}

// What every absorption hands to Python (controller_absorb, vendor_export).
py::dict AbsorptionDict(const Absorption& ab) {
  py::dict d;
  d["model"] = ControllerModelName(ab.model);
  d["parameters"] = ParameterList(ab.parameters);
  d["values"] = ab.values;
  d["held"] = ab.held;
  d["theta"] = ab.theta;
  d["workpiece_shift"] = Eigen::Vector3d(ab.workpiece_shift);
  d["residual"] = ab.residual;
  d["residual_old"] = ab.residual_old;
  d["rms"] = ab.rms;
  d["max"] = ab.max;
  d["rms_old"] = ab.rms_old;
  d["max_old"] = ab.max_old;
  return d;
}

}  // namespace

void BindControllers(py::module_& m) {
  m.def(
      "trt_pin_names", [](const std::string& kins) { return TrtPinNames(ParseTrtKins(kins)); },
      py::arg("kins"), "HAL input pin names of LinuxCNC's <kins>-kins module.");

  m.def(
      "trt_forward",
      [](const std::string& kins_name, const std::map<std::string, double>& pins,
         const Eigen::MatrixXd& joints) {
        const TrtKins kins = ParseTrtKins(kins_name);
        if (joints.cols() != 5)
          throw std::invalid_argument("joints: expected N x 5 (X Y Z tilt C), got " +
                                      std::to_string(joints.cols()) + " columns");
        const TrtPins p = PinsFromMap(kins, pins);
        Eigen::MatrixXd w(joints.rows(), 3);
        for (int i = 0; i < joints.rows(); ++i)
          w.row(i) = TrtForward(kins, p, joints.row(i).transpose()).transpose();
        return w;
      },
      py::arg("kins"), py::arg("pins"), py::arg("joints"),
      "LinuxCNC's forward kinematics: joints N x 5 (mm, degrees) -> world N x 3 (mm).");

  m.def(
      "trt_inverse",
      [](const std::string& kins_name, const std::map<std::string, double>& pins,
         const Eigen::MatrixXd& world) {
        const TrtKins kins = ParseTrtKins(kins_name);
        if (world.cols() != 5)
          throw std::invalid_argument("world: expected N x 5 (X Y Z tilt C), got " +
                                      std::to_string(world.cols()) + " columns");
        const TrtPins p = PinsFromMap(kins, pins);
        Eigen::MatrixXd j = world;
        for (int i = 0; i < world.rows(); ++i)
          j.row(i).head<3>() =
              TrtInverse(kins, p, world.row(i).head<3>().transpose(), world(i, 3), world(i, 4))
                  .transpose();
        return j;
      },
      py::arg("kins"), py::arg("pins"), py::arg("world"),
      "LinuxCNC's inverse kinematics: world N x 5 (X Y Z mm, tilt C degrees) -> joints N x 5.");

  m.def(
      "trt_match",
      [](const Machine& mc, const std::string& kins_name) {
        const TrtMapping map = MatchTrt(mc, ParseTrtKins(kins_name));
        py::dict d;
        std::string axes;
        std::vector<double> sign;
        for (int k = 0; k < 5; ++k) {
          axes += mc.axis(map.axis[k]).name;
          sign.push_back(map.sign[k]);
        }
        d["axes"] = axes;
        d["sign"] = sign;
        d["origin"] = Eigen::Vector3d(map.origin);
        return d;
      },
      py::arg("machine"), py::arg("kins"),
      "How the machine's axes drive LinuxCNC's joints X Y Z tilt C: the fivecal axis letters, "
      "joint = sign * command, and world = workpiece point - origin. Raises ValueError when "
      "the machine does not fit the kinematics.");

  m.def(
      "trt_joints",
      [](const Machine& mc, const std::string& kins_name, const Eigen::MatrixXd& commands) {
        const TrtKins kins = ParseTrtKins(kins_name);
        return TrtJoints(mc, MatchTrt(mc, kins), commands);
      },
      py::arg("machine"), py::arg("kins"), py::arg("commands"));

  m.def(
      "trt_commands",
      [](const Machine& mc, const std::string& kins_name, const Eigen::MatrixXd& joints) {
        const TrtKins kins = ParseTrtKins(kins_name);
        return TrtCommands(mc, MatchTrt(mc, kins), joints);
      },
      py::arg("machine"), py::arg("kins"), py::arg("joints"));

  m.def(
      "trt_fit",
      [](const Machine& mc, const std::string& kins_name, const Eigen::VectorXd& theta,
         const Eigen::MatrixXd& poses, const std::map<std::string, double>& held) {
        const TrtKins kins = ParseTrtKins(kins_name);
        TrtFit fit;
        {
          py::gil_scoped_release release;
          fit = FitTrtPins(mc, kins, theta, poses, PinsFromMap(kins, held));
        }
        return TrtFitDict(kins, fit);
      },
      py::arg("machine"), py::arg("kins"), py::arg("theta"), py::arg("poses"),
      py::arg("held") = std::map<std::string, double>{},
      "Pins that best absorb the errors theta over the poses (N x num_axes, mm / degrees): "
      "dict pins, solved, workpiece_shift(_held) (3, mm), residual / residual_held (N x 3 mm), rms, max, rms_held, max_held.");

  m.def("controller_models", &ControllerModelNames,
        "Names of the controller models the absorber knows (generic pivots, LinuxCNC trt, 5axiskins).");

  m.def(
      "controller_parameters",
      [](const Machine& mc, const std::string& model, bool directions, bool tool_length) {
        return ParameterList(ControllerParameters(mc, ParseControllerModel(model), directions, tool_length));
      },
      py::arg("machine"), py::arg("model"), py::arg("directions") = false, py::arg("tool_length") = true,
      "The model's parameters on the machine: list of dicts label, unit, column (d theta per unit). "
      "Raises ValueError when the machine's topology does not fit the model.");

  m.def(
      "controller_absorb",
      [](const Machine& mc, const std::string& model_name, const Eigen::VectorXd& theta,
         const Eigen::MatrixXd& poses, bool directions, bool tool_length,
         const std::map<std::string, double>& held_pins) {
        const ControllerModel model = ParseControllerModel(model_name);
        AbsorbOptions o;
        o.directions = directions;
        o.tool_length = tool_length;
        const bool trt = model == ControllerModel::kXyzacTrt || model == ControllerModel::kXyzbcTrt;
        const TrtKins kins = model == ControllerModel::kXyzbcTrt ? TrtKins::kXyzbc : TrtKins::kXyzac;
        if (!held_pins.empty()) {
          if (!trt)
            throw std::invalid_argument("held_pins: only the LinuxCNC trt models have pins (model " +
                                        model_name + ")");
          o.held_pins = PinsFromMap(kins, held_pins);
        }
        Absorption ab;
        {
          py::gil_scoped_release release;
          ab = Absorb(mc, model, theta, poses, o);
        }
        py::dict d = AbsorptionDict(ab);
        d["trt"] = ab.trt ? py::object(TrtFitDict(kins, *ab.trt)) : py::object(py::none());
        return d;
      },
      py::arg("machine"), py::arg("model"), py::arg("theta"), py::arg("poses"),
      py::arg("directions") = false, py::arg("tool_length") = true,
      py::arg("held_pins") = std::map<std::string, double>{},
      "Least-squares absorption of the errors theta by the controller model over the poses (N x "
      "num_axes, mm / degrees): dict model, parameters, values, held, theta, workpiece_shift, "
      "residual, residual_old (N x 3 mm), rms, max, rms_old, max_old, and for the LinuxCNC trt "
      "models trt (the pins fit, as trt_fit; held_pins: the pins it holds).");

  m.def(
      "fiveaxis_match",
      [](const Machine& mc) {
        const FiveAxisMapping map = MatchFiveAxis(mc);
        py::dict sign;
        for (int k = 0; k < 5; ++k) sign[py::str(std::string(1, "XYZBC"[k]))] = map.sign[k];
        py::dict d;
        d["sign"] = sign;
        d["pivot_length"] = map.pivot_length;
        d["origin"] = Eigen::Vector3d(map.origin);
        return d;
      },
      py::arg("machine"),
      "How the machine drives 5axiskins's joints X Y Z B C: sign (joint = sign * command), "
      "pivot_length (mm) and origin (world = workpiece point - origin). ValueError says why a "
      "machine does not fit.");
  m.def("fiveaxis_forward", &FiveAxisForward, py::arg("pivot_length"), py::arg("joints"),
        "5axiskins.c forward kinematics: joints N x 5 (X Y Z B C, mm / degrees) -> world N x 3.");
  m.def("fiveaxis_inverse", &FiveAxisInverse, py::arg("pivot_length"), py::arg("world"),
        "5axiskins.c inverse kinematics: world N x 5 (X Y Z B C) -> joints N x 5.");
  m.def(
      "fiveaxis_joints",
      [](const Machine& mc, const Eigen::MatrixXd& commands) {
        return FiveAxisJoints(mc, MatchFiveAxis(mc), commands);
      },
      py::arg("machine"), py::arg("commands"), "5axiskins joints N x 5 for fivecal commands.");

  m.def(
      "compensate_commands",
      [](const Machine& mc, const Eigen::VectorXd& theta, const Eigen::MatrixXd& points,
         const std::optional<Eigen::MatrixXd>& tool_axes, const Eigen::MatrixXd& nominal,
         const std::optional<Eigen::MatrixXi>& dirs, bool orientation, double max_rotary_correction) {
        CompensatedCommands c;
        {
          py::gil_scoped_release release;
          c = CompensateCommands(mc, theta, points, tool_axes ? &*tool_axes : nullptr, nominal,
                                 dirs ? &*dirs : nullptr, orientation, max_rotary_correction);
        }
        return py::make_tuple(c.commands, c.oriented);
      },
      py::arg("machine"), py::arg("theta"), py::arg("points"), py::arg("tool_axes"), py::arg("nominal"),
      py::arg("directions") = py::none(), py::arg("orientation") = true,
      py::arg("max_rotary_correction") = 0.1,
      "Compensated commands for N poses, each seeded at its nominal commands: (N x num_axes "
      "commands, N oriented flags). ValueError 'pose i: ...' for a target that cannot be reached.");

  m.def(
      "kinematics_table",
      [](const Machine& mc, const Eigen::VectorXd& theta) {
        const KinematicsTable t = MakeKinematicsTable(mc, theta);
        py::list rows;
        for (const TableAxis& a : t.axes) {
          py::dict r;
          r["axis"] = std::string(1, a.axis);
          r["chain"] = a.tool_chain ? "tool" : "workpiece";
          r["type"] = a.rotary ? "rotary" : "linear";
          r["direction"] = Eigen::Vector3d(a.direction);
          if (a.rotary) r["point"] = Eigen::Vector3d(a.point);
          rows.append(r);
        }
        py::dict d;
        d["axes"] = rows;
        d["tool_tip"] = Eigen::Vector3d(t.tool_tip);
        d["tool_axis"] = Eigen::Vector3d(t.tool_axis);
        d["part_origin"] = Eigen::Vector3d(t.part_origin);
        d["part_rotation"] = Eigen::Matrix3d(t.part_rotation);
        return d;
      },
      py::arg("machine"), py::arg("theta"),
      "The machine (location errors and tip offsets of theta) as a neutral kinematics table: dict "
      "axes (axis, chain, type, direction, point for a rotary axis), tool_tip, tool_axis, "
      "part_origin, part_rotation; machine frame at the zero pose, mm.");

  m.def(
      "table_tool_points",
      [](const std::vector<std::string>& names, const std::vector<std::string>& chains,
         const std::vector<std::string>& types,
         const Eigen::MatrixXd& directions, const Eigen::MatrixXd& points, const Eigen::Vector3d& tool_tip,
         const Eigen::Vector3d& part_origin, const Eigen::Matrix3d& part_rotation, const Eigen::MatrixXd& q) {
        const size_t n = chains.size();
        if (names.size() != n || types.size() != n || size_t(directions.rows()) != n || size_t(points.rows()) != n ||
            directions.cols() != 3 || points.cols() != 3)
          throw std::invalid_argument("table.axes: names, chains, types, directions and points (N x 3) disagree");
        KinematicsTable t;
        for (size_t k = 0; k < n; ++k) {
          if (chains[k] != "tool" && chains[k] != "workpiece")
            throw std::invalid_argument("table.axes[" + std::to_string(k) + "].chain: '" + chains[k] +
                                        "' (expected workpiece or tool)");
          if (types[k] != "rotary" && types[k] != "linear")
            throw std::invalid_argument("table.axes[" + std::to_string(k) + "].type: '" + types[k] +
                                        "' (expected linear or rotary)");
          TableAxis a;
          if (names[k].size() != 1)
            throw std::invalid_argument("table.axes[" + std::to_string(k) + "].axis: '" + names[k] +
                                        "' (expected one axis letter)");
          a.axis = names[k][0];
          a.tool_chain = chains[k] == "tool";
          a.rotary = types[k] == "rotary";
          a.direction = directions.row(Eigen::Index(k)).transpose();
          a.point = points.row(Eigen::Index(k)).transpose();
          t.axes.push_back(a);
        }
        t.tool_tip = tool_tip;
        t.part_origin = part_origin;
        t.part_rotation = part_rotation;
        return TableToolPoints(t, q);
      },
      py::arg("names"), py::arg("chains"), py::arg("types"), py::arg("directions"), py::arg("points"), py::arg("tool_tip"),
      py::arg("part_origin"), py::arg("part_rotation"), py::arg("axes"),
      "Tool points (N x 3, part frame) that a kinematics table describes for commands axes (N x "
      "rows, mm / degrees): each axis a screw about its line.");

  // ---- controller vendors (vendor.h): one export path for every vendor ----
  m.def(
      "vendor_names",
      [] {
        std::vector<std::string> out;
        for (const ControllerVendor* v : ControllerVendors()) out.push_back(v->Name());
        return out;
      },
      "Names of the registered controller vendors.");

  m.def(
      "vendor_info",
      [](const std::string& vendor) {
        const ControllerVendor& v = FindVendor(vendor);
        py::dict d;
        d["name"] = v.Name();
        d["title"] = v.Title();
        d["options"] = v.OptionHelp();
        return d;
      },
      py::arg("vendor"), "A vendor's title and the convention options it reads (key -> help).");

  m.def(
      "vendor_values",
      [](const std::string& vendor, const Machine& mc, const Eigen::VectorXd& theta, const VendorOptions& o) {
        const ControllerVendor& v = FindVendor(vendor);
        if (theta.size() != mc.num_parameters())
          throw std::invalid_argument("theta: expected " + std::to_string(mc.num_parameters()) + " values, got " +
                                      std::to_string(theta.size()));
        py::dict d;
        d["values"] = VendorValueList(v.Values(mc, o));
        d["model"] = ControllerModelName(v.Model(mc, o).model);
        d["map"] = Eigen::VectorXd(v.Map(mc, MakeKinematicsTable(mc, theta), o));
        return d;
      },
      py::arg("vendor"), py::arg("machine"), py::arg("theta"), py::arg("options") = VendorOptions{},
      "The vendor's values (names, units, sources) for the machine and their numbers for the errors theta.");

  m.def(
      "vendor_tool_points",
      [](const std::string& vendor, const Machine& mc, const Eigen::VectorXd& values, const Eigen::MatrixXd& q,
         const VendorOptions& o) {
        const ControllerVendor& v = FindVendor(vendor);
        const size_t nv = v.Values(mc, o).size();
        if (size_t(values.size()) != nv)
          throw std::invalid_argument("values: expected " + std::to_string(nv) + " (" + vendor +
                                      "'s values), got " + std::to_string(values.size()));
        if (q.cols() != mc.num_axes())
          throw std::invalid_argument("axes: expected " + std::to_string(mc.num_axes()) + " columns, got " +
                                      std::to_string(q.cols()));
        if (!values.allFinite() || !q.allFinite()) throw std::invalid_argument("values / axes: not all finite");
        return Eigen::MatrixXd(v.ToolPoints(mc, values, q, o));
      },
      py::arg("vendor"), py::arg("machine"), py::arg("values"), py::arg("axes"),
      py::arg("options") = VendorOptions{},
      "The controller's own kinematics: tool points (N x 3, mm) for its values and the commands (N x axes).");

  m.def(
      "vendor_export",
      [](const std::string& vendor, const Machine& mc, const Eigen::VectorXd& theta, const Eigen::MatrixXd& cov,
         const Eigen::MatrixXd& poses, const VendorOptions& o, const Eigen::VectorXd& old_values) {
        const ControllerVendor& v = FindVendor(vendor);
        VendorExport ex;
        Eigen::MatrixXd absorbed_cov;
        {
          py::gil_scoped_release release;
          ex = ExportToVendor(mc, v, theta, cov, poses, o, old_values);
          absorbed_cov = AbsorbedCovariance(ex, cov);
        }
        const Absorption& ab = ex.absorption;
        py::dict a = AbsorptionDict(ab);
        a["trt"] = py::none();
        py::dict d;
        d["vendor"] = ex.vendor;
        d["title"] = v.Title();
        d["directions"] = ex.model.directions;
        d["tool_length"] = ex.model.tool_length;
        d["absorption"] = a;
        d["values"] = VendorValueList(ex.values);
        d["old"] = ex.old_values;
        d["new"] = ex.new_values;
        d["change"] = ex.change;
        d["covariance"] = ex.covariance;
        d["covariance_index"] = ex.covariance_index;
        d["sigma"] = ex.sigma;
        d["old_minus_nominal"] = ex.old_minus_nominal;
        d["round_trip"] = ex.round_trip;
        d["round_trip_max"] = ex.round_trip_max;
        d["absorbed_covariance"] = absorbed_cov;
        return d;
      },
      py::arg("vendor"), py::arg("machine"), py::arg("theta"), py::arg("covariance"), py::arg("poses"),
      py::arg("options") = VendorOptions{}, py::arg("old_values") = Eigen::VectorXd(),
      "One export path for every vendor: absorb theta into the vendor's model over the poses, the "
      "vendor's values old / new / change with the change's covariance, and the round trip through "
      "the vendor's own kinematics.");

  m.def(
      "vendor_to_theta",
      [](const std::string& vendor, const Machine& mc, const Eigen::VectorXd& values, const Eigen::MatrixXd& poses,
         const VendorOptions& o) {
        const Absorption ab = VendorToTheta(mc, FindVendor(vendor), values, poses, o);
        py::dict d;
        d["theta"] = ab.theta;
        d["workpiece_shift"] = Eigen::Vector3d(ab.workpiece_shift);
        d["rms"] = ab.rms;
        d["max"] = ab.max;
        d["held"] = ab.held;
        return d;
      },
      py::arg("vendor"), py::arg("machine"), py::arg("values"), py::arg("poses"),
      py::arg("options") = VendorOptions{},
      "The fivecal errors of the model a controller runs with these values (its own tool points "
      "absorbed into its model over the poses); rms / max: what that model cannot represent.");

  // Verify after loading (verify.h): the estimates cross as (names, values,
  // covariance) triples; the answer as a dict the Python layer reports.
  m.def(
      "verify_change",
      [](const Machine& mc, const std::vector<std::string>& previous_names, const Eigen::VectorXd& previous,
         const Eigen::MatrixXd& previous_cov, const std::vector<std::string>& change_names,
         const Eigen::VectorXd& change, const Eigen::MatrixXd& change_cov, const std::vector<std::string>& now_names,
         const Eigen::VectorXd& now, const Eigen::MatrixXd& now_cov, double k, bool change_covariance) {
        VerifyOptions o;
        o.k = k;
        o.change_covariance = change_covariance;
        const ChangeVerification v = VerifyChange(mc, {previous_names, previous, previous_cov},
                                                  {change_names, change, change_cov}, {now_names, now, now_cov}, o);
        const auto hyp = [](const Hypothesis& h) {
          py::dict d;
          d["cause"] = ChangeCauseText(h.cause);
          d["text"] = h.Text();
          d["component"] = h.component;
          d["chi2"] = h.chi2;
          return d;
        };
        const auto outcome = [&](const ChangeOutcome& oc) {
          py::dict d;
          d["verdict"] = ChangeVerdictName(oc.verdict);
          py::list causes, unresolved;
          for (const Hypothesis& h : oc.causes) causes.append(hyp(h));
          for (const Hypothesis& h : oc.unresolved) unresolved.append(hyp(h));
          d["causes"] = causes;
          d["unresolved"] = unresolved;
          d["message"] = oc.message;
          return d;
        };
        py::list rows, hyps;
        for (const ParameterChange& r : v.parameters) {
          py::dict d;
          d["name"] = r.name;
          d["previous"] = r.previous;
          d["previous_std"] = r.previous_std;
          d["expected"] = r.expected;
          d["expected_std"] = r.expected_std;
          d["now"] = r.now;
          d["now_std"] = r.now_std;
          d["predicted"] = r.predicted;
          d["predicted_std"] = r.predicted_std;
          d["observed"] = r.observed;
          d["observed_std"] = r.observed_std;
          d["z"] = r.z;
          d["as_predicted"] = r.as_predicted;
          d["ratio"] = r.ratio;
          d["ratio_std"] = r.ratio_std;
          d["outcome"] = outcome(r.outcome);
          rows.append(d);
        }
        for (const Hypothesis& h : v.hypotheses) hyps.append(hyp(h));
        py::dict d;
        d["parameters"] = rows;
        d["not_compared"] = v.not_compared;
        d["hypotheses"] = hyps;
        d["chi2_limit"] = v.chi2_limit;
        d["ratio"] = v.ratio;
        d["ratio_std"] = v.ratio_std;
        d["k"] = v.k;
        d["outcome"] = outcome(v.outcome);
        d["took_effect"] = v.took_effect();
        return d;
      },
      py::arg("machine"), py::arg("previous_names"), py::arg("previous"), py::arg("previous_covariance"),
      py::arg("change_names"), py::arg("change"), py::arg("change_covariance"), py::arg("now_names"),
      py::arg("now"), py::arg("now_covariance"), py::arg("k") = 3.0, py::arg("change_covariance") = false,
      "Did a loaded change take effect as predicted (controllers/verify.h)? Names are put under the "
      "check's names; dict parameters (per row previous, expected, now, predicted, observed with std, z, "
      "as_predicted, ratio, ratio_std, outcome), not_compared, hypotheses (cause, text, component, chi2), "
      "chi2_limit, ratio, ratio_std, k, outcome (verdict, causes, unresolved, message), took_effect.");
}
