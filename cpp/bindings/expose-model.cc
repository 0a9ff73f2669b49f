// Bindings of the machine model (fivecal/model/): Machine, forward and
// inverse kinematics.
#include <pybind11/eigen.h>
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include "fivecal/model/inverse.h"
#include "fivecal/model/kinematics.h"
#include "fivecal/model/machine.h"
#include "fivecal/model/machine_kinds.h"
#include "fivecal/model/rotation_forms.h"

namespace py = pybind11;
using namespace fivecal;

namespace {

py::dict AxisDict(const Axis& a) {
  py::dict d;
  d["name"] = std::string(1, a.name);
  d["type"] = a.rotary() ? "rotary" : "linear";
  d["direction"] = std::vector<double>{a.direction.x(), a.direction.y(), a.direction.z()};
  d["point"] = std::vector<double>{a.point.x(), a.point.y(), a.point.z()};
  return d;
}

const Eigen::MatrixXi* OptionalDirs(const std::optional<Eigen::MatrixXi>& d) {
  return d ? &*d : nullptr;
}

}  // namespace

void BindModel(py::module_& m) {
  py::class_<Machine>(m, "Machine")
      .def_static("from_json", &Machine::FromJson, py::arg("text"))
      .def_static("load", &Machine::Load, py::arg("path"))
      .def("to_json", &Machine::ToJson)
      .def_property_readonly("name", &Machine::name)
      .def_property_readonly("topology", &Machine::topology)
      .def_property_readonly("axis_names", &Machine::axis_names)
      .def_property_readonly("axes", [](const Machine& mc) {
        py::list l;
        for (const Axis& a : mc.axes()) l.append(AxisDict(a));
        return l;
      })
      .def_property_readonly("workpiece_chain", [](const Machine& mc) {
        std::string s;
        for (int k : mc.workpiece_chain()) s += mc.axis(k).name;
        return s;
      })
      .def_property_readonly("tool_chain", [](const Machine& mc) {
        std::string s;
        for (int k : mc.tool_chain()) s += mc.axis(k).name;
        return s;
      })
      .def_property_readonly("tip", [](const Machine& mc) { return Eigen::Vector3d(mc.tip()); })
      .def_property_readonly("tool_axis",
                             [](const Machine& mc) { return Eigen::Vector3d(mc.tool_axis()); })
      .def("parameter_names", &Machine::parameter_names)
      .def_property_readonly("num_parameters", &Machine::num_parameters)
      .def("parameter_index", &Machine::RequireParameter, py::arg("name"))
      .def("parameter_kind",
           [](const Machine& mc, const std::string& name) {
             const ParameterInfo& p = mc.parameters()[mc.RequireParameter(name)];
             switch (p.kind) {
               case ParameterKind::kLocation: return "location";
               case ParameterKind::kMotion: return "motion";
               case ParameterKind::kBacklash: return "backlash";
               default: return "tip";
             }
           })
      .def("parameter_is_angular",
           [](const Machine& mc, const std::string& name) {
             const ParameterInfo& p = mc.parameters()[mc.RequireParameter(name)];
             if (p.kind == ParameterKind::kBacklash) return mc.axis(p.axis).rotary();
             return p.angular();
           });

  m.def(
      "tool_poses",
      [](const Machine& mc, const Eigen::VectorXd& theta, const Eigen::Ref<const RowMatrixXd>& axes,
         const std::optional<RowMatrixXi>& dirs, const std::optional<Eigen::Vector3d>& tip,
         bool with_axes) {
        // Written in place into the numpy arrays returned.
        const py::ssize_t n = axes.rows();
        py::array_t<double> p({n, py::ssize_t(3)}), a({with_axes ? n : 0, py::ssize_t(3)});
        double* pp = p.mutable_data();
        double* pa = with_axes ? a.mutable_data() : nullptr;
        {
          py::gil_scoped_release release;
          ToolPosesRowMajor(mc, theta, axes, dirs ? &*dirs : nullptr, pp, pa, tip ? &*tip : nullptr);
        }
        return py::make_tuple(p, with_axes ? py::object(a) : py::object(py::none()));
      },
      py::arg("machine"), py::arg("theta"), py::arg("axes"), py::arg("directions") = py::none(),
      py::arg("tip") = py::none(), py::arg("with_axes") = true,
      "Tool points and tool axes (N x 3 each, workpiece frame) for N poses; axes N x num_axes "
      "in mm / degrees. with_axes=False skips the tool axes (returned as None).");

  m.def(
      "inverse",
      [](const Machine& mc, const Eigen::VectorXd& theta, const Eigen::MatrixXd& points,
         const std::optional<Eigen::MatrixXd>& tool_axes, const Eigen::VectorXd& start,
         const std::optional<Eigen::MatrixXi>& dirs) {
        py::gil_scoped_release release;
        return InverseKinematics(mc, theta, points, tool_axes ? &*tool_axes : nullptr, start,
                                 OptionalDirs(dirs));
      },
      py::arg("machine"), py::arg("theta"), py::arg("points"), py::arg("tool_axes"),
      py::arg("start"), py::arg("directions") = py::none());

  m.def("machine_kinds", []() {
    py::list out;
    for (const MachineKindInfo& k : MachineKinds()) {
      py::dict d;
      d["name"] = k.name;
      d["description"] = k.description;
      d["priors"] = k.priors;
      out.append(d);
    }
    return out;
  }, "The kinds of machine a machine file's \"kind\" names, each with its class priors (docs/identification.md).");

  // Orientations as instruments write them (rotation_forms.h): the importers'
  // one conversion, to fivecal's rotation vectors and back.
  auto form = [](const std::string& f, const std::string& order, const std::string& sequence,
                 const std::string& unit, double tolerance) {
    RotationForm r;
    r.form = f;
    r.order = order;
    r.sequence = sequence;
    r.unit = unit;
    r.tolerance = tolerance;
    return r;
  };
  m.def(
      "rotation_vectors",
      [form](const Eigen::MatrixXd& values, const std::string& f, const std::string& order,
             const std::string& sequence, const std::string& unit, double tolerance) {
        RotationVectors r = ToRotationVectors(values, form(f, order, sequence, unit, tolerance));
        return py::make_tuple(r.vectors, r.problems);
      },
      py::arg("values"), py::arg("form"), py::arg("order") = "wxyz", py::arg("sequence") = "",
      py::arg("unit") = "rad", py::arg("tolerance") = 1e-3,
      "(N x 3 rotation vectors in rad, per row '' or why it is not a rotation) of N rows of a rotation "
      "form: quaternion (order wxyz or xyzw), matrix (r11..r33 row by row), rotation_vector (unit), "
      "euler (sequence, e.g. ZYX intrinsic or zyx extrinsic; unit).");
  m.def(
      "rotations_from_vectors",
      [form](const Eigen::MatrixXd& vectors, const std::string& f, const std::string& order,
             const std::string& sequence, const std::string& unit) {
        return FromRotationVectors(vectors, form(f, order, sequence, unit, 1e-3));
      },
      py::arg("vectors"), py::arg("form"), py::arg("order") = "wxyz", py::arg("sequence") = "",
      py::arg("unit") = "rad", "N x 3 rotation vectors (rad) in a rotation form (as rotation_vectors).");
}
