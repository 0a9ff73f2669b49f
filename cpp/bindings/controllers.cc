// Bindings of the controller models (fivecal/controllers/): LinuxCNC's
// xyzac-trt / xyzbc-trt kinematics, the mapping of a fivecal machine onto
// them and the pin values that best absorb identified errors. Pins cross the
// boundary as dicts keyed by LinuxCNC's pin names ("x-rot-point", ...).
#include <pybind11/eigen.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <algorithm>
#include <map>
#include <string>

#include "fivecal/controllers/linuxcnc_trt.h"
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
      },
      py::arg("machine"), py::arg("kins"), py::arg("theta"), py::arg("poses"),
      py::arg("held") = std::map<std::string, double>{},
      "Pins that best absorb the errors theta over the poses (N x num_axes, mm / degrees): "
      "dict pins, solved, workpiece_shift(_held) (3, mm), residual / residual_held (N x 3 mm), rms, max, rms_held, max_held.");
}
