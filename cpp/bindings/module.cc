// pybind11 module fivecal._core: a thin boundary over the C++ core. Every
// std::invalid_argument thrown by the core reaches Python as ValueError with
// its message intact. One binding file per folder of the core
// (expose-<folder>.cc, as Pinocchio's bindings/python/algorithm/expose-*.cpp).
#include <pybind11/pybind11.h>

#include <exception>
#include <stdexcept>

namespace py = pybind11;

void BindModel(py::module_& m);
void BindObservations(py::module_& m);
void BindNcGeometry(py::module_& m);
void BindSolve(py::module_& m);
void BindUncertainty(py::module_& m);
void BindProcedures(py::module_& m);
void BindDesign(py::module_& m);
void BindControllers(py::module_& m);

PYBIND11_MODULE(_core, m) {
  m.doc() = "fivecal C++ core: machine model, kinematics, identification";
  py::register_exception_translator([](std::exception_ptr p) {
    try {
      if (p) std::rethrow_exception(p);
    } catch (const std::invalid_argument& e) {
      PyErr_SetString(PyExc_ValueError, e.what());
    }
  });

  BindModel(m);
  BindObservations(m);
  BindNcGeometry(m);
  BindSolve(m);
  BindUncertainty(m);
  BindProcedures(m);
  BindDesign(m);
  BindControllers(m);
}
