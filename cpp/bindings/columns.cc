// Binding of the columnar loader (observations/columns.h): the caller passes
// Arrow's buffers as numpy arrays (zero copy from pyarrow); this file only
// checks their shapes and hands raw pointers to the core.
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <stdexcept>
#include <string>

#include "fivecal/observations/columns.h"
#include "fivecal/solve/analytic_residuals.h"

namespace py = pybind11;
using namespace fivecal;

namespace {

std::string Shape(const py::array& a) {
  std::string s = "(";
  for (py::ssize_t d = 0; d < a.ndim(); ++d) s += (d ? ", " : "") + std::to_string(a.shape(d));
  return s + (a.ndim() == 1 ? ",)" : ")");
}

// A 1-D array of T with `n` entries (n < 0: any length), or nullptr for None.
template <typename T>
const T* Buffer(py::handle obj, int64_t n, const std::string& what, py::list* keep) {
  if (obj.is_none()) return nullptr;
  auto a = py::array_t<T, py::array::c_style>::ensure(obj);
  if (!a) throw std::invalid_argument(what + ": expected an array of " + py::str(py::dtype::of<T>()).cast<std::string>());
  if (a.ndim() != 1 || (n >= 0 && a.shape(0) != n))
    throw std::invalid_argument(what + ": expected shape (" + std::to_string(n) + ",), got " + Shape(a));
  keep->append(a);
  return a.data();
}

}  // namespace

void BindColumns(py::module_& m) {
  py::class_<ColumnLoader>(m, "ColumnLoader")
      .def(py::init<Dataset, int64_t, int64_t>(), py::arg("head"), py::arg("rows"), py::arg("first_row") = 0)
      .def(
          "add",
          // numbers: name -> (float64 values, bool validity or None);
          // strings: name -> (int64 offsets (rows + 1), uint8 bytes, validity or None);
          // positions: int64 dataset index of each row, or None (after the previous batch).
          [](ColumnLoader& l, const std::string& kind, int64_t rows, const py::dict& numbers,
             const py::dict& strings, const py::object& positions) {
            ColumnBatch b;
            b.kind = kind;
            b.rows = rows;
            py::list keep;  // the arrays converted here live until Add returns
            for (auto item : numbers) {
              const std::string name = py::str(item.first);
              const auto t = item.second.cast<py::tuple>();
              const std::string w = kind + ": column " + name;
              if (t.size() != 2) throw std::invalid_argument(w + ": expected (values, valid)");
              NumberColumn c;
              c.name = name;
              c.values = Buffer<double>(t[0], rows, w, &keep);
              if (!c.values) throw std::invalid_argument(w + ": no values");
              c.valid = reinterpret_cast<const uint8_t*>(Buffer<bool>(t[1], rows, w + " (validity)", &keep));
              b.numbers.push_back(c);
            }
            for (auto item : strings) {
              const std::string name = py::str(item.first);
              const auto t = item.second.cast<py::tuple>();
              const std::string w = kind + ": column " + name;
              if (t.size() != 3) throw std::invalid_argument(w + ": expected (offsets, data, valid)");
              StringColumn c;
              c.name = name;
              c.offsets = Buffer<int64_t>(t[0], rows + 1, w + " (offsets)", &keep);
              const auto data = py::array_t<uint8_t, py::array::c_style>::ensure(t[1]);
              if (!c.offsets || !data || data.ndim() != 1) throw std::invalid_argument(w + ": expected offsets and bytes");
              keep.append(data);
              c.data = reinterpret_cast<const char*>(data.data());
              if (c.offsets[0] < 0 || c.offsets[rows] > data.shape(0))
                throw std::invalid_argument(w + ": offsets outside the bytes");
              for (int64_t r = 0; r < rows; ++r)
                if (c.offsets[r + 1] < c.offsets[r]) throw std::invalid_argument(w + ": offsets not increasing");
              c.valid = reinterpret_cast<const uint8_t*>(Buffer<bool>(t[2], rows, w + " (validity)", &keep));
              b.strings.push_back(c);
            }
            b.positions = Buffer<int64_t>(positions, rows, kind + ": positions", &keep);
            py::gil_scoped_release release;
            l.Add(b);
          },
          py::arg("kind"), py::arg("rows"), py::arg("numbers"), py::arg("strings"), py::arg("positions") = py::none())
      .def("finish", &ColumnLoader::Finish, py::arg("whole") = true);
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
