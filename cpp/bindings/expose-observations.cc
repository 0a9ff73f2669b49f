// Bindings of the observations (fivecal/observations/): Dataset, the
// registered observation kinds, the simulator and its plans, and the
// columnar loader (the caller passes Arrow's buffers as numpy arrays, zero
// copy from pyarrow; this file only checks their shapes and hands raw
// pointers to the core).
#include <algorithm>
#include <limits>
#include <optional>
#include <stdexcept>
#include <string>

#include <pybind11/eigen.h>
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <nlohmann/json.hpp>

#include "fivecal/observations/ball_mount.h"
#include "fivecal/observations/columns.h"
#include "fivecal/observations/dataset.h"
#include "fivecal/observations/dataset_reader.h"
#include "fivecal/observations/nc_geometry.h"
#include "fivecal/observations/registry.h"
#include "fivecal/observations/simulate.h"
#include "fivecal/observations/writer.h"
#include "fivecal/solve/priors.h"

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

// A numpy array owning `v` (moved, not copied): a written block's column.
template <typename T, typename C>
py::array_t<T> Owned(C&& v) {
  auto* p = new C(std::move(v));
  py::capsule free(p, [](void* q) { delete reinterpret_cast<C*>(q); });
  return py::array_t<T>({static_cast<py::ssize_t>(p->size())}, {static_cast<py::ssize_t>(sizeof(T))},
                        reinterpret_cast<const T*>(p->data()), free);
}

}  // namespace

void BindObservations(py::module_& m) {
  py::class_<Dataset>(m, "Dataset")
      .def_static("from_json", &Dataset::FromJson, py::arg("text"),
                  py::arg("require_observations") = true)
      .def("to_json", &Dataset::ToJson)
      // write: called with the file's bytes piece by piece (an exception it
      // raises stops the write and propagates).
      .def(
          "write_json",
          [](const Dataset& d, const py::object& write, size_t chunk_bytes) {
            WriteDatasetJson(d, [&](const char* p, size_t n) { write(py::bytes(p, n)); }, chunk_bytes);
          },
          py::arg("write"), py::arg("chunk_bytes") = size_t{1} << 20)
      .def("head", &DatasetHead)
      .def("subset", &Dataset::Subset, py::arg("indices"))
      .def_static(
          "balls",
          [](const Machine& m, const std::string& type, const std::string& setup,
             const Eigen::MatrixXd& axes, const std::optional<Eigen::MatrixXi>& dirs,
             const Eigen::Vector3d& tool_ball, const Eigen::Vector3d& table_ball, double length,
             const Eigen::MatrixXd& values, const std::optional<Eigen::MatrixXd>& sigma) {
            Dataset d(m);
            const ObservationKind* kind = FindKind(type);
            if (!kind || !dynamic_cast<const BallMountKind*>(kind)) {
              std::string names;
              for (const ObservationKind* k : ObservationKinds())
                if (dynamic_cast<const BallMountKind*>(k)) names += (names.empty() ? "'" : " or '") + std::string(k->name()) + "'";
              throw std::invalid_argument("ball samples: type must be " + names);
            }
            const ObservationType t = kind->type();
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
              // The samples are one column block (AppendBallSamples).
              if (n > 0) {
                TraceBlock& b = d.blocks.back();
                b.sigma.assign(static_cast<size_t>(rows), std::vector<double>(static_cast<size_t>(n)));
                for (Eigen::Index k = 0; k < rows; ++k)
                  for (Eigen::Index r = 0; r < n; ++r)
                    b.sigma[k][r] = (*sigma)(r, sigma->cols() == rows ? k : 0);
              }
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
          // include_blocks=false: the per-object observations only (the
          // blocks then through block_columns(), without a copy).
          [](const Dataset& d, bool include_blocks) {
            // Column-block rows too (dataset.h TraceBlock), in order.
            const Eigen::Index n = static_cast<Eigen::Index>(include_blocks ? d.size() : d.observations.size());
            const int na = d.machine().num_axes();
            using RowMajor = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;
            RowMajor axes(n, na);
            Eigen::VectorXi type(n), target(n);
            std::vector<int> ball;
            d.ForEachRow([&](size_t row, const Observation& o) {
              if (row >= static_cast<size_t>(n)) return;
              const Eigen::Index i = static_cast<Eigen::Index>(row);
              axes.row(i) = o.axes.transpose();
              type[i] = static_cast<int>(o.type);
              const ObservationKind& kind = KindOf(o);
              target[i] = kind.ArtefactTarget(d, o);
              if (dynamic_cast<const BallMountKind*>(&kind)) ball.push_back(static_cast<int>(i));
            });
            const Eigen::Index k = static_cast<Eigen::Index>(ball.size());
            const double nan = std::numeric_limits<double>::quiet_NaN();
            Eigen::VectorXd reading = Eigen::VectorXd::Constant(k, nan), length = reading;
            RowMajor measured = RowMajor::Constant(k, 3, nan), tool(k, 3), table(k, 3);
            Observation scratch;
            for (Eigen::Index j = 0; j < k; ++j) {
              const Observation& o = d.Row(static_cast<size_t>(ball[j]), &scratch);
              const BallMountData& b = o.data<BallMountData>();
              if (static_cast<const BallMountKind&>(KindOf(o)).has_length()) {
                reading[j] = b.reading;
                length[j] = b.length;
              } else {
                measured.row(j) = b.measured.transpose();
              }
              tool.row(j) = b.tool_ball.transpose();
              table.row(j) = b.table_ball.transpose();
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
          },
          py::arg("include_blocks") = true)
      .def(
          "block_columns",
          // Each column block as numpy views of its columns (read-only, no
          // copy; they keep the dataset alive): "type", "setup", "first" (the
          // dataset index of its first row), "rows", "axes" (axis letter ->
          // values, file units), "directions" (the same, int8; empty when no
          // row has one), "values" (the kind's per-row values by file column:
          // reading, measured_x ...), "sigma" (per residual row: one value or
          // one per row, NaN = default; empty: the default) and "shared" (the
          // kind's JSON fields every row shares, as a file writes them).
          [](py::object self) {
            const Dataset& d = self.cast<const Dataset&>();
            auto view = [&](const auto& v) {
              using T = typename std::decay_t<decltype(v)>::value_type;
              py::array_t<T> a({static_cast<py::ssize_t>(v.size())}, {static_cast<py::ssize_t>(sizeof(T))}, v.data(),
                               self);
              py::detail::array_proxy(a.ptr())->flags &= ~py::detail::npy_api::NPY_ARRAY_WRITEABLE_;
              return a;
            };
            py::list out;
            size_t first = d.observations.size();
            Observation row;
            for (const TraceBlock& b : d.blocks) {
              const ObservationKind& kind = KindOf(b.type);
              py::dict blk;
              blk["type"] = ObservationTypeName(b.type);
              blk["setup"] = b.setup;
              blk["first"] = first;
              blk["rows"] = b.size();
              py::dict axes, dirs, values;
              for (size_t k = 0; k < b.axes.size(); ++k) {
                const std::string a(1, d.machine().axis(static_cast<int>(k)).name);
                axes[a.c_str()] = view(b.axes[k]);
                if (!b.direction.empty()) dirs[a.c_str()] = view(b.direction[k]);
              }
              for (size_t v = 0; v < b.values.size(); ++v)
                values[kind.block_value_name(static_cast<int>(v)).c_str()] = view(b.values[v]);
              py::list sigma;
              for (const auto& c : b.sigma) sigma.append(view(c));
              blk["axes"] = axes;
              blk["directions"] = dirs;
              blk["values"] = values;
              blk["sigma"] = sigma;
              nlohmann::json j = nlohmann::json::object();
              if (b.size()) {
                d.FillRow(b, 0, &row);
                kind.Write(row, &j);
              }
              blk["shared"] = py::module_::import("json").attr("loads")(j.dump());
              out.append(blk);
              first += b.size();
            }
            return out;
          })
      .def_property_readonly("machine", &Dataset::machine)
      .def_readonly("tip_radius", &Dataset::tip_radius)
      .def_property_readonly("num_observations",
                             [](const Dataset& d) { return d.size(); })
      // How many observations are held as column blocks (dataset.h
      // TraceBlock) rather than one object each.
      .def_property_readonly("num_block_rows", [](const Dataset& d) { return d.block_rows(); })
      .def_property_readonly("num_blocks", [](const Dataset& d) { return d.blocks.size(); })
      .def("pack_traces", &Dataset::PackTraces, py::arg("min_rows") = 0)
      .def("expanded", &Dataset::Expanded)
      .def_property_readonly("observation_types", [](const Dataset& d) {
        std::vector<std::string> t;
        t.reserve(d.size());
        for (const auto& o : d.observations) t.push_back(ObservationTypeName(o.type));
        for (const TraceBlock& b : d.blocks) t.insert(t.end(), b.size(), ObservationTypeName(b.type));
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
      d["probe_touch"] = k->probe_touch();
      d["length_reference"] = k->LengthReference();
      // Samples of a tool ball and a table ball on one mounting: Dataset.balls
      // and the "ball" rows of Dataset.columns.
      d["ball_mount"] = dynamic_cast<const BallMountKind*>(k) != nullptr;
      d["instrument_key"] = k->instrument_key() ? py::object(py::str(k->instrument_key())) : py::object(py::none());
      // What reports, plots and plausibility checks show of the kind
      // (KindReport, kind.h): Python names no kind, it reads these.
      const KindReport r = k->Report();
      auto str = [](const char* c) { return c ? py::object(py::str(c)) : py::object(py::none()); };
      py::dict rep;
      rep["target_list"] = str(r.target_list);
      rep["setup_key"] = str(r.setup_key);
      rep["setup_heading"] = str(r.setup_heading);
      rep["count_word"] = str(r.count_word);
      rep["indexed"] = r.indexed;
      rep["components"] = r.components;
      rep["component_label"] = str(r.component_label);
      rep["component_frame"] = str(r.component_frame);
      rep["component_caption"] = str(r.component_caption);
      rep["recorded_deviation"] = str(r.recorded_deviation);
      rep["range_field"] = str(r.range_field);
      rep["range"] = r.range;
      rep["range_note"] = str(r.range_note);
      rep["range_what"] = str(r.range_what);
      rep["figures"] = str(r.figures);
      d["report"] = rep;
      // Its instrument table (KindTable, kind.h): fivecal import reads a
      // table of any kind through these and names no kind.
      const KindTable tb = k->Table();
      py::dict tab;
      tab["name"] = tb.name.empty() ? std::string(k->name()) : tb.name;
      tab["aliases"] = tb.aliases;
      tab["row_aliases"] = tb.row_aliases;
      tab["layout"] = tb.layout;
      py::list cols;
      for (const TableColumn& c : tb.columns) {
        py::dict cd;
        cd["name"] = c.name;
        cd["field"] = c.field;
        cd["index"] = c.index < 0 ? py::object(py::none()) : py::object(py::int_(c.index));
        cd["quantity"] = c.quantity;
        cd["measured"] = c.measured;
        cd["required"] = c.required;
        cd["alias"] = c.alias.empty() ? py::object(py::none()) : py::object(py::str(c.alias));
        cd["sidecar"] = c.sidecar.empty() ? py::object(py::none()) : py::object(py::str(c.sidecar));
        cd["missing"] = c.missing;
        cd["range"] = c.range;
        cd["range_message"] = c.range_message;
        cols.append(cd);
      }
      tab["columns"] = cols;
      tab["expected"] = tb.expected;
      tab["options"] = tb.options;
      py::dict ha;
      for (const auto& [from, to] : tb.header_aliases) ha[py::str(from)] = to;
      tab["header_aliases"] = ha;
      py::dict dirs;
      for (const auto& [key, what] : tb.directions) dirs[py::str(key)] = what;
      tab["directions"] = dirs;
      py::list rules;
      for (const TableRule& r : tb.rules) {
        py::dict rd;
        rd["rule"] = r.rule;
        rd["keys"] = r.keys;
        rd["values"] = r.values;
        rd["value"] = r.value;
        rd["option"] = r.option;
        rd["if_key"] = r.if_key;
        rd["then"] = r.then;
        rd["chars"] = r.chars;
        rd["size"] = r.size;
        rd["limit"] = r.limit;
        rd["message"] = r.message;
        rules.append(rd);
      }
      tab["rules"] = rules;
      d["table"] = tab;
      out.append(d);
    }
    return out;
  });

  // A planned touch's contact point and outward normal, from its kind; None
  // for an entry of a kind that touches no surface.
  m.def("planned_contact", [](const Dataset& d, const std::string& entry) -> py::object {
    Eigen::Vector3d p, n;
    if (!PlannedContact(d, entry, &p, &n)) return py::none();
    return py::make_tuple(p, n);
  }, py::arg("dataset"), py::arg("entry_json"));
  m.def("noise_classes", &NoiseClasses);
  // class -> "mm" | "rad": which simulator noise levels are in rad.
  m.def("noise_class_units", [] {
    std::map<std::string, std::string> out;
    for (const std::string& c : NoiseClasses()) out[c] = NoiseClassUnit(c);
    return out;
  });

  m.def("simulate", &Simulate, py::arg("spec_json"), py::call_guard<py::gil_scoped_release>());
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

  // ---- Simulation plans ---------------------------------------------------------
  py::class_<SimulationPlan>(m, "SimulationPlan")
      .def_static("from_spec", &BuildSimulationPlan, py::arg("spec_json"),
                  py::call_guard<py::gil_scoped_release>())
      .def_static(
          "from_dataset",
          // noise: one sigma (mm) per noise class (fivecal._core.noise_classes()).
          [](const Dataset& ds, const std::map<std::string, double>& values,
             const std::map<std::string, double>& noise) {
            NoiseLevels n;
            n.level = noise;
            py::gil_scoped_release release;
            return PlanFromDataset(ds, values, n);
          },
          py::arg("dataset"), py::arg("values"), py::arg("noise"))
      .def_readonly("base", &SimulationPlan::base)
      .def_readonly("seed", &SimulationPlan::seed)
      .def_readonly("values", &SimulationPlan::values)
      .def_readonly("sensitivity", &SimulationPlan::sensitivity)
      .def_readonly("input_sigma", &SimulationPlan::input_sigma)
      .def_readonly("input_observation", &SimulationPlan::input_observation)
      .def_readonly("input_component", &SimulationPlan::input_component)
      .def_property_readonly("num_inputs", &SimulationPlan::num_inputs)
      .def("add_noise", &AddNoise, py::arg("seed"), py::call_guard<py::gil_scoped_release>())
      .def("apply_input_deviations", &ApplyInputDeviations, py::arg("deviation"),
           py::call_guard<py::gil_scoped_release>());

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

  // A JSON dataset file piece by piece (fivecal convert): `streamable` false
  // means load it whole (the reference messages); next(rows) gives the next
  // piece as a Dataset, None at the end (or when it turns out not
  // streamable: check `streamable` again).
  py::class_<DatasetFileReader>(m, "DatasetFileReader")
      .def(py::init<const std::string&, size_t>(), py::arg("path"), py::arg("buffer_bytes") = size_t{1} << 22,
           py::call_guard<py::gil_scoped_release>())
      .def_property_readonly("streamable", &DatasetFileReader::streamable)
      .def_property_readonly("observations_read", &DatasetFileReader::observations_read)
      .def_property_readonly("head", &DatasetFileReader::head_json)
      .def(
          "next",
          [](DatasetFileReader& r, size_t rows) {
            if (rows < 1) throw std::invalid_argument("rows: expected a positive number of observations per piece");
            return r.Next(rows);
          },
          py::call_guard<py::gil_scoped_release>(),
          py::arg("rows"));

  // The JSON text of a dataset written piece by piece (DatasetJsonWriter):
  // write(bytes) receives it.
  py::class_<DatasetJsonWriter>(m, "DatasetJsonWriter")
      .def(py::init([](const Dataset& head, const py::object& write, size_t chunk_bytes) {
             return std::make_unique<DatasetJsonWriter>(
                 head, [write](const char* p, size_t n) { write(py::bytes(p, n)); }, chunk_bytes);
           }),
           py::arg("head"), py::arg("write"), py::arg("chunk_bytes") = size_t{1} << 20)
      .def("add", py::overload_cast<const Dataset&>(&DatasetJsonWriter::Add), py::arg("piece"))
      .def("finish", &DatasetJsonWriter::Finish);

  py::class_<ColumnWriter>(m, "ColumnWriter")
      .def(py::init<const Dataset&>(), py::arg("dataset"), py::keep_alive<1, 2>(),
           py::call_guard<py::gil_scoped_release>())
      // A writer of pieces: scan(piece) each (True when the columns
      // changed), then write(begin, end, piece).
      .def(py::init<>())
      .def("scan", &ColumnWriter::Scan, py::arg("piece"), py::arg("offset") = 0,
           py::call_guard<py::gil_scoped_release>())
      .def_property_readonly("rows", &ColumnWriter::rows)
      .def_property_readonly("columns",
                             [](const ColumnWriter& w) {
                               py::list out;
                               for (const ColumnWriter::Spec& s : w.columns())
                                 out.append(py::make_tuple(s.name, s.type == ColumnWriter::Type::kString ? "string"
                                                                   : s.type == ColumnWriter::Type::kInt8 ? "int8"
                                                                                                         : "float64"));
                               return out;
                             })
      .def(
          "write",
          // Per column, in `columns` order: float64 (values, valid), int8
          // (values, valid) or string (int32 offsets, uint8 bytes, valid);
          // valid is a bool array, or None when every row holds a value.
          [](const ColumnWriter& w, int64_t begin, int64_t end, const Dataset* piece) {
            std::vector<ColumnWriter::Block> blocks;
            {
              py::gil_scoped_release release;
              blocks = piece ? w.Write(*piece, begin, end) : w.Write(begin, end);
            }
            py::list out;
            for (size_t c = 0; c < blocks.size(); ++c) {
              ColumnWriter::Block& b = blocks[c];
              py::object valid = b.valid.empty() ? py::object(py::none()) : py::object(Owned<bool>(std::move(b.valid)));
              switch (w.columns()[c].type) {
                case ColumnWriter::Type::kFloat64:
                  out.append(py::make_tuple(Owned<double>(std::move(b.numbers)), valid));
                  break;
                case ColumnWriter::Type::kInt8:
                  out.append(py::make_tuple(Owned<int8_t>(std::move(b.small)), valid));
                  break;
                case ColumnWriter::Type::kString:
                  out.append(py::make_tuple(Owned<int32_t>(std::move(b.offsets)), Owned<uint8_t>(std::move(b.text)), valid));
                  break;
              }
            }
            return out;
          },
          py::arg("begin"), py::arg("end"), py::arg("piece") = nullptr);
}

// What the NC program writers ask of a plan's kinds (observations/
// nc_geometry.h): io/nc_programs.py and io/plan_readings.py name no kind.
void BindNcGeometry(py::module_& m) {
  // Per kind: the program family its plan entries run in (None: no program
  // writes them) and whether it is a probe touch.
  m.def("nc_kinds", [] {
    py::list out;
    for (const ObservationKind* k : ObservationKinds()) {
      py::dict d;
      d["name"] = k->name();
      const char* p = NcProgram(*k);
      d["program"] = p ? py::object(py::str(p)) : py::object(py::none());
      d["touch"] = dynamic_cast<const ProbeTouchKind*>(k) != nullptr;
      d["target_list"] = k->Report().target_list ? py::object(py::str(k->Report().target_list))
                                                 : py::object(py::none());
      out.append(d);
    }
    return out;
  });
  // Per plan entry: (contact point, outward normal, clearance radius) of a
  // probe touch, None for an entry of another kind.
  m.def(
      "planned_touch_contacts",
      [](const Dataset& d, const std::string& plan_json) {
        py::list out;
        for (const auto& c : PlannedTouchContacts(d, plan_json))
          out.append(c ? py::object(py::make_tuple(c->point, c->normal, c->clearance)) : py::object(py::none()));
        return out;
      },
      py::arg("dataset"), py::arg("plan_json"));
  // (id, centre, radius) of every ball the moves keep out of.
  m.def("clearance_balls", [](const Dataset& d) {
    py::list out;
    for (const ClearanceBall& b : ArtefactClearanceBalls(d)) out.append(py::make_tuple(b.id, b.centre, b.radius));
    return out;
  }, py::arg("dataset"));
  // (inside, s, normal): where the stylus centre on p + s d first reaches
  // the target's surface.
  m.def(
      "probe_line_crossing",
      [](const Dataset& d, const std::string& type, const std::string& target, const Eigen::Vector3d& p,
         const Eigen::Vector3d& dir) {
        const ProbeCrossing c = CrossProbeLine(d, type, target, p, dir);
        return py::make_tuple(c.inside, c.s, c.normal);
      },
      py::arg("dataset"), py::arg("type"), py::arg("target"), py::arg("p"), py::arg("d"));
}
