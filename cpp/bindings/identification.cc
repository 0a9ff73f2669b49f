// Bindings of the identification engine (Problem, Solve, Result).
#include <pybind11/eigen.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

namespace py = pybind11;

void BindIdentification(py::module_& m) { (void)m; }
