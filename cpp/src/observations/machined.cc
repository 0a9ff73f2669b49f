#include "fivecal/observations/machined.h"

#include <cmath>
#include <memory>
#include <nlohmann/json.hpp>
#include <stdexcept>

#include "fivecal/model/inverse.h"
#include "fivecal/observations/simulate.h"
#include "fivecal/solve/problem.h"
#include "json_util.h"

namespace fivecal {
namespace {

using namespace json_util;

// The file names the part ("part", kept in Observation::setup); the rest is
// the payload (MachinedData), under these file keys:
const char* kNormal = "normal";
const char* kRefAxes = "reference_axes";    // step: machine axis order, mm / degrees
const char* kRefPoint = "reference_point";  // step
const char* kRefNormal = "reference_normal";  // step
const char* kFields[6] = {"x", "y", "z", "a", "b", "c"};
// A measured deviation beyond this is no machining error but a wrong nominal.
constexpr double kMaxDeviation = 100.0;  // mm

bool IsStep(const Observation& o) { return o.data<MachinedData>().step(); }
std::string Prefix(const Observation& o) { return "machined." + o.setup; }

// A step's reference point or normal, or the message that it has none.
const Eigen::Vector3d& Reference(const std::optional<Eigen::Vector3d>& v, const char* key,
                                 const std::function<std::string()>& w) {
  if (!v) throw std::invalid_argument(w() + "." + key + ": missing (3 numbers)");
  return *v;
}

// A face of observation `o` in internal units: the cut at `axes` (reference
// = false) or at `reference_axes`.
MachinedFace FaceOf(const Machine& m, const Observation& o, bool reference) {
  const MachinedData& d = o.data<MachinedData>();
  MachinedFace f;
  const Eigen::VectorXd& axes = reference ? d.reference_axes : o.axes;
  f.q.resize(m.num_axes());
  AxisValuesToInternal(m, axes.data(), f.q.data());
  // The reference cut was reached the same way as the first (its own approach directions are not recorded).
  f.dir.assign(o.direction.data(), o.direction.data() + o.direction.size());
  f.point = reference ? d.reference_point.value() : d.point;
  f.normal = (reference ? d.reference_normal.value() : d.normal).normalized();
  return f;
}

// Whether the part's datum matters to first order: a face, or a step whose
// two faces differ in point or normal.
bool SeesDatum(const Observation& o) {
  const MachinedData& d = o.data<MachinedData>();
  if (!d.step()) return true;
  return !(d.reference_point.value() - d.point).isZero(1e-9) ||
         !(d.reference_normal.value().normalized() - d.normal.normalized()).isZero(1e-12);
}

Eigen::Vector3d ReadNormal(const json& o, const char* key, const std::string& w) {
  const Eigen::Vector3d n = ReadVector3(o.value(key, json()), w + "." + key);
  // Kept as written (a file round trip changes no bit); normalised where used.
  if (!(n.norm() > 1e-9)) throw std::invalid_argument(w + "." + key + ": zero vector (the face's outward normal)");
  return n;
}

// Every axis of the machine (S may be left out), or with `linear_optional`
// the rotary ones; returns whether every linear axis was given.
bool ReadPose(const Machine& m, const json& axes, const std::string& w, bool linear_optional,
              Eigen::VectorXd* out) {
  if (!axes.is_object()) throw std::invalid_argument(w + ": missing (an object axis letter -> reading)");
  *out = Eigen::VectorXd::Zero(m.num_axes());
  std::vector<bool> given(m.num_axes(), false);
  ReadAxes(m, axes, w, out, &given);
  bool linear = true;
  for (int k = 0; k < m.num_axes(); ++k) {
    if (given[k] || m.axis(k).name == 'S') continue;
    if (m.axis(k).rotary() || !linear_optional)
      throw std::invalid_argument(w + ": missing axis '" + std::string(1, m.axis(k).name) + "' (machine axes " +
                                  m.axis_names() + ")");
    linear = false;
  }
  return linear;
}

// The linear commands that put the nominal tool point on `point` at the
// rotary commands of `pose` (the machining programme of the test).
Eigen::VectorXd CutCommands(const Machine& m, const Eigen::Vector3d& point, Eigen::VectorXd pose) {
  for (int k = 0; k < m.num_axes(); ++k)
    if (!m.axis(k).rotary()) pose[k] = 0;
  const Eigen::MatrixXd target = point.transpose();
  return InverseKinematics(m, Eigen::VectorXd::Zero(m.num_parameters()), target, nullptr, pose)
      .row(0)
      .transpose();
}

class Kind final : public ObservationKind {
 public:
  ObservationType type() const override { return ObservationType::kMachined; }
  const char* name() const override { return "machined"; }
  const char* label() const override { return "machined feature (machining test, part measured on a CMM)"; }
  // A finished face measured on a CMM: the cut's own scatter (tool deflection,
  // surface finish) dominates the CMM's probing.
  double default_sigma() const override { return 0.003; }
  bool analytic() const override { return false; }
  bool plan_finds_linear_axes() const override { return true; }
  // A CMM report of a machined test part, one face per row, columns named
  // after the file keys (the generic reader) with a CMM report's own names.
  KindTable Table() const override {
    KindTable t;
    t.aliases = {"machining", "cmm"};
    t.columns = {TableColumn("point", "point").Required(), TableColumn("normal", "normal").Required(),
                 TableColumn("measured", "measured")
                     .Measured()
                     .Required()
                     .Range(2.0,  // mm: this far from nominal is a unit mistake, not a machining error
                            "deviation {value:.6g} mm: a machined face is not that far from nominal (refused "
                            "beyond ±{limit:g} mm); deviations look like µm: name the column measured_um or "
                            "give --units um")};
    t.expected =
        "point_x point_y point_z normal_x normal_y normal_z measured [part] [feature] [reference_<axis> ...] "
        "[id] [sigma]";
    t.header_aliases = {{"deviation", "measured"}, {"dev", "measured"}, {"ref_", "reference_"}};
    t.directions = {{"normal", "a face normal"}, {"reference_normal", "a face normal"}};
    // The part: a column, else --setup / the sidecar's setup, else P1. The
    // feature: a step when the row has a reference cut, else a face.
    const std::vector<std::string> reference = {kRefAxes, kRefPoint, kRefNormal};
    t.rules = {
        TableRule("default", {"part"}).Option("setup").Value("P1"),
        TableRule("no_char", {"part"}).Chars(".").Message("part '{value}': a part name has no '.'"),
        TableRule("default", {"feature"}).If(kRefAxes, "step").Value("face"),
        TableRule("one_of", {"feature"}).Values({"face", "step"}),
        TableRule("excludes", reference)
            .If("feature")
            .Value("face")
            .Message("a face has no reference cut (leave the cell empty, or say 'step' in the feature column)"),
        TableRule("requires", {kRefAxes})
            .If("feature")
            .Value("step")
            .Message("a step needs the axes of its reference cut: columns reference_<axis> (or ref_<axis>) for "
                     "{axes}"),
        TableRule("size", {"point", kNormal, kRefPoint, kRefNormal}).Size(3),
        TableRule("nonzero", {kNormal, kRefNormal})
            .Message("the face normal {value} is zero (the outward normal of the face, part frame)"),
        // a coordinate this large is µm typed as mm, not a part on a machine
        TableRule("limit", {"point", kRefPoint})
            .Limit(kMaxLinear)
            .Message("{value:.6g} mm is beyond any machine tool; coordinates look like µm: name the column "
                     "{column}_um")};
    return t;
  }

  std::vector<const char*> json_keys() const override {
    return {"type", "part", "feature", "axes", "direction", "point", "normal", "measured", "reference_axes",
            "reference_point", "reference_normal", "sigma", "id"};
  }
  void Read(const json& o, const std::string& w, const Dataset& ds, Observation* ob) const override {
    ReadOwn(ds.machine(), o, w, false, ob);
    ob->data<MachinedData>().measured = ReadBounded(o, "measured", w, kMaxDeviation);
  }
  ObservationPayload NewPayload() const override { return MachinedData{}; }
  void Validate(const Dataset& ds, const Observation& o, const std::function<std::string()>& w) const override {
    if (o.setup.empty() || o.setup.find('.') != std::string::npos)
      throw std::invalid_argument(w() + ".part: the part id must be a non-empty name without '.'");
    const MachinedData& d = o.data<MachinedData>();
    if (d.feature != "face" && d.feature != "step")
      throw std::invalid_argument(w() + ".feature: " + Quote(d.feature) + " is neither \"face\" nor \"step\"");
    if (!(std::abs(d.measured) <= kMaxDeviation)) RequireBounded(d.measured, kMaxDeviation, w() + ".measured");
    auto vec = [&](const Eigen::Vector3d& v, const char* field, bool unit) {
      for (int c = 0; c < 3; ++c)
        if (!(std::abs(v[c]) <= kMaxLinear)) RequireBounded(v[c], kMaxLinear, w() + "." + field);
      if (unit && !(v.norm() > 1e-9)) throw std::invalid_argument(w() + "." + field + ": zero vector");
    };
    vec(d.point, "point", false);
    vec(d.normal, kNormal, true);
    const bool step = d.step();
    const bool has[3] = {d.reference_axes.size() > 0, d.reference_point.has_value(), d.reference_normal.has_value()};
    const char* keys[3] = {kRefAxes, kRefPoint, kRefNormal};
    for (int k = 0; k < 3; ++k)
      if (!step && has[k]) throw std::invalid_argument(w() + "." + keys[k] + ": only a step has a reference cut");
    if (!step) return;
    const Machine& m = ds.machine();
    const Eigen::VectorXd& ref = d.reference_axes;
    if (ref.size() != m.num_axes())
      throw std::invalid_argument(w() + "." + kRefAxes + ": missing (" + std::to_string(m.num_axes()) + " numbers)");
    for (int k = 0; k < m.num_axes(); ++k)
      RequireBounded(ref[k], m.axis(k).rotary() ? kMaxRotaryDeg : kMaxLinear,
                     w() + "." + kRefAxes + "." + std::string(1, m.axis(k).name));
    vec(Reference(d.reference_point, kRefPoint, w), kRefPoint, false);
    vec(Reference(d.reference_normal, kRefNormal, w), kRefNormal, true);
  }
  void Write(const Observation& o, json* jo) const override {
    // The generic writer put the part under "setup".
    jo->erase("setup");
    const MachinedData& d = o.data<MachinedData>();
    (*jo)["part"] = o.setup;
    (*jo)["feature"] = d.feature;
    (*jo)["point"] = Array3(d.point);
    (*jo)["normal"] = Array3(d.normal);
    (*jo)["measured"] = d.measured;
    if (!d.step()) return;
    (*jo)["reference_point"] = Array3(d.reference_point.value());
    (*jo)["reference_normal"] = Array3(d.reference_normal.value());
  }
  void WriteOnMachine(const Machine& m, const Observation& o, json* jo) const override {
    if (!IsStep(o)) return;
    json ax = json::object();
    const Eigen::VectorXd& ref = o.data<MachinedData>().reference_axes;
    for (int k = 0; k < m.num_axes(); ++k) ax[std::string(1, m.axis(k).name)] = ref[k];
    (*jo)[kRefAxes] = ax;
  }

  // ---- setup: the part's datum in the workpiece frame ----
  void AddObservationParameters(const Observation& o, ParameterTable* t) const override {
    if (t->has_group(type(), o.setup)) return;
    std::vector<int> idx;
    for (const char* f : kFields) idx.push_back(t->Add(Prefix(o) + "." + f));
    t->AddGroup(type(), o.setup, idx);
  }
  // Where the CMM's datum sits on the machine is never known to the
  // micrometre: estimated whenever a feature sees it (a face; a step between
  // faces of different points or normals). A step of one point and normal,
  // Zhang & Zhang's own kind of measurement, does not need it.
  void DefaultSetup(const Dataset&, const ParameterTable& t, const Observation& o,
                    std::set<int>* out) const override {
    if (!SeesDatum(o)) return;
    for (int i : t.group(type(), o.setup)) out->insert(i);
  }
  bool IsParameterName(const std::string& rest) const override {
    const size_t dot = rest.find('.');
    if (dot == std::string::npos || dot == 0 || rest.find('.', dot + 1) != std::string::npos) return false;
    const std::string f = rest.substr(dot + 1);
    for (const char* k : kFields)
      if (f == k) return true;
    return false;
  }
  std::vector<PriorClass> prior_classes() const override {
    return {{"part_position", 1.0, "mm",
             "machined.<part>.x|y|z: where a machined test part's measuring datum sits on the table"},
            {"part_angle", 1e-3, "rad", "machined.<part>.a|b|c: how that datum is turned (1 mm over 1 m)"}};
  }
  // Placement (docs/setup_uncertainty.md): a test part is clamped by eye and
  // its CMM datum is the CMM's own alignment, so where that datum sits on the
  // machine is known to about a millimetre and a milliradian: the plausible
  // size. The row keeps an error confounded with the datum from being fitted
  // as if the datum were exact; the data find the datum.
  double DefaultPlacement(const std::string& n) const override {
    const char* c = PriorClassOfName(n);
    if (!c) return 0.0;
    return std::string(c) == "part_angle" ? 1e-3 : 1.0;
  }
  const char* PriorClassOfName(const std::string& n) const override {
    if (n.rfind("machined.", 0) != 0) return nullptr;
    const std::string f = n.substr(n.rfind('.') + 1);
    return (f == "a" || f == "b" || f == "c") ? "part_angle" : "part_position";
  }

  void AddResidual(ResidualBuilder& b, const Observation& o) const override {
    const auto& g = b.table.group(type(), o.setup);
    PartRefs refs;
    for (int c = 0; c < 3; ++c) {
      refs.position[c] = b.Ref(g[c]);
      refs.angle[c] = b.Ref(g[3 + c]);
    }
    const Machine& m = b.dataset.machine();
    std::shared_ptr<const MachinedFace> reference;
    if (IsStep(o)) reference = std::make_shared<const MachinedFace>(FaceOf(m, o, true));
    b.Add(new MachinedResidual(b.context, FaceOf(m, o, false), reference, o.data<MachinedData>().measured, refs), 1);
  }

  // ---- simulation: the plan gives the rotary axes of each cut; the linear
  // ones follow from the nominal point (the test's programme) unless given ----
  std::vector<const char*> plan_keys() const override {
    return {"type", "part", "feature", "axes", "direction", "point", "normal", "reference_axes",
            "reference_point", "reference_normal", "id"};
  }
  void SimulateEntry(const json& e, const std::string& w, const PlanTruth& t, Observation* ob,
                     PlanSlot*) const override {
    const Machine& m = t.dataset->machine();
    ReadOwn(m, e, w, true, ob);
    MachinedData& md = ob->data<MachinedData>();
    Eigen::VectorXd given;
    if (!ReadPose(m, e.at("axes"), w + ".axes", true, &given)) ob->axes = CutCommands(m, md.point, ob->axes);
    if (md.step() && !ReadPose(m, e.at(kRefAxes), w + "." + kRefAxes, true, &given))
      md.reference_axes = CutCommands(m, md.reference_point.value(), md.reference_axes);
    const std::string pre = Prefix(*ob) + ".";
    Eigen::Vector3d d;
    for (int c = 0; c < 3; ++c) d[c] = t.setup(pre + kFields[c]);
    const Eigen::Matrix3d R = RotZYX(t.setup(pre + "a"), t.setup(pre + "b"), t.setup(pre + "c"));
    double u = MachinedDeviation<double>(m, t.theta.data(), FaceOf(m, *ob, false), d, R);
    if (IsStep(*ob)) u -= MachinedDeviation<double>(m, t.theta.data(), FaceOf(m, *ob, true), d, R);
    md.measured = u;
  }
  void AddInputs(SimulationPlan* plan, int i, const PlanSlot*, const RecordedContext*) const override {
    AddPlanInput(plan, i, 0, -1.0, NoiseLevel(plan->noise));
  }
  void ApplyInput(const SimulationPlan& plan, int i, int, double x, Observation* o) const override {
    o->data<MachinedData>().measured = plan.base.observations[i].data<MachinedData>().measured + x;
  }

  // ---- report: the deviation along the face's normal, at the cut's tool point ----
  void ReportVector(const ReportContext& c, const Observation& o, const double* r, Eigen::Vector3d* point,
                    Eigen::Vector3d* vector) const override {
    const Machine& m = c.dataset->machine();
    const Eigen::VectorXd theta = c.values->head(m.num_parameters());
    const MachinedFace f = FaceOf(m, o, false);
    *point = ToolAtCommand(m, theta, o.axes, f.dir, m.tip());
    *vector = r[0] * f.normal;
  }

 private:
  // part, feature, point, normal and (a step) the reference cut; `plan`: the
  // axes of the reference cut may leave the linear axes to the simulator.
  static void ReadOwn(const Machine& m, const json& o, const std::string& w, bool plan, Observation* ob) {
    if (!o.contains("part") || !o["part"].is_string())
      throw std::invalid_argument(w + ".part: missing (the test part's name, a string such as \"P1\")");
    ob->setup = o["part"].get<std::string>();
    if (ob->setup.empty() || ob->setup.find('.') != std::string::npos)
      throw std::invalid_argument(w + ".part: " + Quote(ob->setup) + " must be a non-empty name without '.'");
    if (!o.contains("feature") || !o["feature"].is_string())
      throw std::invalid_argument(w + ".feature: missing (\"face\" or \"step\")");
    MachinedData& d = ob->data<MachinedData>();
    d.feature = o["feature"].get<std::string>();
    if (d.feature != "face" && d.feature != "step")
      throw std::invalid_argument(w + ".feature: " + Quote(d.feature) + " is neither \"face\" nor \"step\"" +
                                  DidYouMean(d.feature, {"face", "step"}));
    d.point = ReadVector3(o.value("point", json()), w + ".point");
    d.normal = ReadNormal(o, kNormal, w);
    if (!d.step()) {
      for (const char* key : {kRefAxes, kRefPoint, kRefNormal})
        if (o.contains(key)) throw std::invalid_argument(w + "." + key + ": only a step has a reference cut");
      return;
    }
    if (!o.contains(kRefAxes))
      throw std::invalid_argument(w + "." + kRefAxes + ": missing (the axes of the step's other cut)");
    Eigen::VectorXd ref;
    ReadPose(m, o[kRefAxes], w + "." + kRefAxes, plan, &ref);
    d.reference_axes = ref;
    d.reference_point = o.contains(kRefPoint) ? ReadVector3(o[kRefPoint], w + "." + kRefPoint) : d.point;
    d.reference_normal = o.contains(kRefNormal) ? ReadNormal(o, kRefNormal, w) : d.normal;
  }
};

}  // namespace

const ObservationKind& MachinedKind() {
  static const Kind kind;
  return kind;
}

}  // namespace fivecal
