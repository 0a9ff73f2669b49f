// A test-only observation kind, defined and registered in this file alone:
// nothing in the core, the bindings or the other tests names it. It follows
// docs/adding_an_observation_kind.md step by step. Linked into
// fivecal_kind_plugin_tests (test_kind_plugin.cc: load, Jacobian, simulate,
// identify, report pieces) and into a test-only build of the Python module
// (build/dev/kind_plugin/fivecal/_core*.so: tests/python/test_kind_plugin.py
// runs it through the Python load, identify and report).
#include "stylus3d.h"

#include <cmath>
#include <nlohmann/json.hpp>
#include <string>

#include "fivecal/observations/registry.h"
#include "fivecal/observations/residuals.h"
#include "fivecal/observations/simulate.h"
#include "fivecal/solve/priors.h"
#include "fivecal/solve/problem.h"

namespace fivecal {
namespace {

using nlohmann::json;

// ---- step 1: its data ----------------------------------------------------------------------------------
// A kind outside the core has no struct among the core's payloads: its
// observations carry the generic KindOwnData (ObservationKind::NewPayload's
// default), its numbers under names of its choosing, here its file key.
const Eigen::VectorXd& Measured(const Observation& o) { return o.data<KindOwnData>().values.at("measured"); }
Eigen::VectorXd& Measured(Observation* o) { return o->data<KindOwnData>().values["measured"]; }

// ---- step 2: the residual ---------------------------------------------------------------------------
// "stylus3d" (a made-up instrument): the 3D position of a stylus on the
// spindle, read in the workpiece frame by a fixture on the table. The
// stylus sits at the machine's tool tip plus an offset d per mounting
// (stylus3d.<setup>.x|y|z, F at the zero pose):
//
//     r = P(theta, q, tip + d) - measured          (3 rows, mm, workpiece frame)
//
//   P  the tool point in the workpiece frame (ToolInWorkpiece, kinematics.h);
//   dr/dd = dP/dtip, dr/dtheta = dP/dtheta: the automatic derivatives of
//   this functor give both (analytic() is false: no hand-written batch).
class Stylus3dResidual {
 public:
  Stylus3dResidual(std::shared_ptr<const ResidualContext> ctx, const Observation& o, const SetupRef d[3])
      : access_(ctx), pose_(*ctx->machine, o), tip_(ctx->machine->tip()), measured_(Measured(o)) {
    for (int c = 0; c < 3; ++c) d_[c] = d[c];
  }

  template <typename T>
  bool operator()(T const* const* p, T* residual) const {
    std::vector<T> theta;
    access_.Theta(p, &theta);
    Vec3<T> tip;
    for (int c = 0; c < 3; ++c) tip[c] = T(tip_[c]) + access_.Setup(p, d_[c]);
    Vec3<T> P;
    ToolInWorkpiece<T>(access_.machine(), theta.data(), pose_.q.data(), pose_.dir.data(), tip, &P);
    for (int c = 0; c < 3; ++c) residual[c] = P[c] - T(measured_[c]);
    return true;
  }

 private:
  const ParameterAccess access_;
  const PoseData pose_;
  const Eigen::Vector3d tip_, measured_;
  SetupRef d_[3];
};

const char* const kXYZ[3] = {"x", "y", "z"};

std::string Prefix(const Observation& o) { return "stylus3d." + o.setup; }

Eigen::Vector3d ReadXYZ(const json& o, const std::string& key, const std::string& w) {
  const json& v = o.contains(key) ? o[key] : json();
  if (!v.is_array() || v.size() != 3) throw std::invalid_argument(w + "." + key + ": expected [x, y, z] (mm)");
  Eigen::Vector3d out;
  for (int c = 0; c < 3; ++c) {
    if (!v[c].is_number() || !std::isfinite(v[c].get<double>()))
      throw std::invalid_argument(w + "." + key + "[" + std::to_string(c) + "]: expected a finite number (mm)");
    out[c] = v[c].get<double>();
  }
  return out;
}

// ---- step 3: the kind ---------------------------------------------------------------------------------
class Stylus3dKind final : public ObservationKind {
 public:
  explicit Stylus3dKind(ObservationType t) : type_(t) {}

  // who it is
  ObservationType type() const override { return type_; }
  const char* name() const override { return "stylus3d"; }
  const char* label() const override { return "3D stylus position (test-only kind)"; }
  int rows() const override { return 3; }
  double default_sigma() const override { return 0.002; }
  bool analytic() const override { return false; }
  bool LengthReference() const override { return true; }

  // its file fields
  std::vector<const char*> json_keys() const override {
    return {"type", "setup", "axes", "direction", "measured", "sigma", "id"};
  }
  void Read(const json& o, const std::string& w, const Dataset&, Observation* ob) const override {
    ob->setup = o.value("setup", std::string());
    Measured(ob) = ReadXYZ(o, "measured", w);
  }
  void Validate(const Dataset&, const Observation& o, const std::function<std::string()>& w) const override {
    if (o.setup.find('.') != std::string::npos) throw std::invalid_argument(w() + ".setup: no '.' in an id");
    const auto& own = o.data<KindOwnData>().values;
    const auto m = own.find("measured");
    if (m == own.end() || m->second.size() != 3) throw std::invalid_argument(w() + ".measured: missing ([x, y, z] mm)");
    if (!m->second.allFinite()) throw std::invalid_argument(w() + ".measured: not finite");
  }
  void Write(const Observation& o, json* out) const override {
    if (!o.setup.empty()) (*out)["setup"] = o.setup;
    const Eigen::VectorXd& m = Measured(o);
    (*out)["measured"] = {m[0], m[1], m[2]};
  }
  // its instrument table: read by the generic reader (a column per file key);
  // the rules each row must meet are its own, applied by the importer, which
  // names no kind's key
  KindTable Table() const override {
    KindTable t;
    t.rules = {TableRule("default", {"setup"}).Value("M1"),
               TableRule("no_char", {"setup"}).Chars(".").Message("mounting '{value}': a mounting id has no '.'"),
               // the fixture's reach: a position beyond it is µm typed as mm
               TableRule("limit", {"measured"})
                   .Limit(2000.0)
                   .Message("{value:.6g} mm is beyond the fixture's reach; name the column {column}_um")};
    return t;
  }

  // its setup parameters: the stylus offset of each mounting, estimated by default
  void AddObservationParameters(const Observation& o, ParameterTable* t) const override {
    if (t->has_group(type(), o.setup)) return;
    std::vector<int> idx;
    for (const char* c : kXYZ) idx.push_back(t->Add(Prefix(o) + "." + c));
    t->AddGroup(type(), o.setup, idx);
  }
  void DefaultSetup(const Dataset&, const ParameterTable& t, const Observation& o,
                    std::set<int>* out) const override {
    for (int i : t.group(type(), o.setup)) out->insert(i);
  }
  bool IsParameterName(const std::string& rest) const override {
    const size_t d = rest.find('.');
    if (d == std::string::npos || rest.find('.', d + 1) != std::string::npos) return false;
    const std::string f = rest.substr(d + 1);
    return f == "x" || f == "y" || f == "z";
  }
  std::vector<PriorClass> prior_classes() const override {
    return {{"stylus3d_offset", 1.0, "mm", "stylus3d.<setup>.x|y|z: where the stylus sits on the tool"}};
  }
  const char* PriorClassOfName(const std::string& n) const override {
    return n.rfind("stylus3d.", 0) == 0 ? "stylus3d_offset" : nullptr;
  }

  // its residual
  void AddResidual(ResidualBuilder& b, const Observation& o) const override {
    const auto& g = b.table.group(type(), o.setup);
    const SetupRef d[3] = {b.Ref(g[0]), b.Ref(g[1]), b.Ref(g[2])};
    b.Add(new Stylus3dResidual(b.context, o, d), 3);
  }

  // its simulation
  std::vector<const char*> plan_keys() const override { return {"type", "setup", "axes", "direction", "id"}; }
  void SimulateEntry(const json& e, const std::string&, const PlanTruth& t, Observation* ob,
                     PlanSlot*) const override {
    ob->setup = e.value("setup", std::string());
    const Machine& m = t.dataset->machine();
    Eigen::Vector3d tip = m.tip();
    for (int c = 0; c < 3; ++c) tip[c] += t.setup(Prefix(*ob) + "." + kXYZ[c]);
    const PoseData pose(m, *ob);
    Eigen::Vector3d P;
    ToolInWorkpiece<double>(m, t.theta.data(), pose.q.data(), pose.dir.data(), tip, &P);
    Measured(ob) = P;
  }
  void AddInputs(SimulationPlan* plan, int i, const PlanSlot*, const RecordedContext*) const override {
    for (int c = 0; c < 3; ++c) AddPlanInput(plan, i, c, -1.0, NoiseLevel(plan->noise));
  }
  void ApplyInput(const SimulationPlan& plan, int i, int c, double x, Observation* o) const override {
    Measured(o)[c] = Measured(plan.base.observations[i])[c] + x;
  }

  // its report: the residual is already a vector in the workpiece frame
  void ReportVector(const ReportContext& c, const Observation& o, const double* r, Eigen::Vector3d* point,
                    Eigen::Vector3d* vector) const override {
    *point = Measured(o);
    (void)c;
    *vector = Eigen::Vector3d(r[0], r[1], r[2]);
  }
  KindReport Report() const override {
    KindReport k;
    k.setup_key = "setup";
    k.setup_heading = "stylus mountings";
    k.components = {"x", "y", "z"};
    k.component_label = "3D stylus";
    k.component_frame = "workpiece (table) frame";
    k.component_caption = "3D stylus: deviation and residual per component.";
    k.recorded_deviation = nullptr;
    return k;
  }

 private:
  const ObservationType type_;
};

}  // namespace

// ---- step 4: register it (from this file alone) -------------------------------------------------------
const ObservationKind& TheStylus3dKind() {
  static const Stylus3dKind kind(UnusedObservationType());
  return kind;
}
std::unique_ptr<ObservationKind> MakeStylus3dKind(ObservationType t) { return std::make_unique<Stylus3dKind>(t); }
const bool kStylus3dRegistered = RegisterObservationKind(TheStylus3dKind());

}  // namespace fivecal

