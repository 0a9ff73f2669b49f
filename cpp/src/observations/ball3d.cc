#include "fivecal/observations/ball3d.h"

#include <cmath>
#include <nlohmann/json.hpp>
#include <stdexcept>

#include "fivecal/observations/simulate.h"
#include "fivecal/solve/analytic_residuals.h"
#include "fivecal/solve/problem.h"
#include "json_util.h"

namespace fivecal {
namespace {

using namespace json_util;

class Kind final : public BallMountKind {
 public:
  ObservationType type() const override { return ObservationType::kBall3d; }
  const char* name() const override { return "ball3d"; }
  const char* label() const override { return "3D ball displacement"; }
  KindReport Report() const override {
    KindReport r;
    r.setup_key = "setup";
    r.setup_heading = "R-test / 3D ball setups";
    r.count_word = "sample";
    r.components = {"dx", "dy", "dz"};
    r.component_label = "R-test / 3D ball";
    r.component_frame = "workpiece (table) frame";
    r.component_caption =
        "R-test / 3D ball: recorded deviation and residual after the fit per component (dx, dy, dz, "
        "workpiece frame) against the rotary angle, one line per setup / indexation group.";
    r.recorded_deviation = "measured";
    r.range_field = "measured";
    r.range = 5.0;  // R-test / 3D ball sensors measure a few mm
    r.range_note = "an R-test / 3D ball sensor measures a few mm";
    r.range_what = "displacements";
    return r;
  }
  // R-test / 3D ball triples: axes and the displacement dx dy dz; the balls
  // from the sidecar unless columns give them.
  KindTable Table() const override {
    KindTable t;
    t.aliases = {"rtest", "r-test"};
    t.row_aliases = {"rtest", "r-test"};
    t.layout = "mount";
    t.columns = MountColumns();
    const char* names[3] = {"dx", "dy", "dz"};
    for (int i = 0; i < 3; ++i)
      t.columns.push_back(TableColumn(names[i], "measured", i).Measured().Required().Range(
          Report().range,
          "{value:.6g} mm is beyond an R-test / 3D ball sensor's range (a few mm, refused beyond {limit:g} mm); "
          "displacements look like µm: name the column {column}_um or give --units um"));
    t.expected = "dx_um dy_um dz_um [id]";
    t.options = {"tool_ball", "table_ball"};
    return t;
  }
  int rows() const override { return 3; }
  // R-test / CapBall displacement sensors.
  double default_sigma() const override { return 0.001; }

  std::vector<const char*> json_keys() const override {
    return {"type", "setup", "axes", "direction", "measured", "tool_ball", "table_ball", "sigma", "id"};
  }
  void Read(const json& o, const std::string& w, const Dataset&, Observation* ob) const override {
    ReadMount(o, w, ob);
    static const json absent;  // by reference: o.value(key, json()) copies the array
    auto it = o.find("measured");
    ob->data<BallMountData>().measured = ReadVector3(it == o.end() ? absent : *it, w + ".measured");
  }
  enum Slot { kMeasured = kFlatOwn };
  const std::vector<FlatKey>& flat_keys() const override {
    static const std::vector<FlatKey> keys = [] {
      std::vector<FlatKey> k = MountFlatKeys();
      k.push_back({"measured", FlatKey::kVector});
      return k;
    }();
    return keys;
  }
  bool ReadFlat(const FlatObservation& f, const Artefact&, Observation* ob) const override {
    if (!f.has(kMeasured)) return false;
    ob->data<BallMountData>().measured = f.vector(kMeasured);
    return ReadFlatMount(f, ob);
  }
  bool WriteFlat(const Observation& o, FlatObservation* f) const override {
    f->set_vector(kMeasured, o.data<BallMountData>().measured);
    WriteFlatMount(o, f);
    return true;
  }

  // The nest (table ball) position always comes with ball3d data: a nest
  // placed to a millimetre, left fixed, turns into location errors of
  // hundreds of microradians (a fit without it is a mistake, not a choice).
  void DefaultSetup(const Dataset&, const ParameterTable& t, const Observation& o,
                    std::set<int>* out) const override {
    const auto& mt = t.group(type(), o.setup);
    for (int c = 4; c < 7; ++c) out->insert(mt[c]);
  }
  const char* PriorClassOfName(const std::string& n) const override {
    return n.rfind("ball3d.", 0) == 0 ? "mount" : nullptr;
  }
  // Placement (docs/setup_uncertainty.md): the R-test nest is clamped where
  // the spindle probe or an edge finder put it, and its readings are zeroed
  // on a master ball or at a reference pose (about 50 um either way); the
  // spindle ball sits on the spindle axis to a few um, at the tool length of
  // a presetter (about 20 um).
  double DefaultPlacement(const std::string& n) const override {
    if (!PriorClassOfName(n)) return 0.0;
    if (n.find(".table.") != std::string::npos) return 0.050;
    return n.compare(n.size() - 2, 2, ".z") == 0 ? 0.020 : 0.005;
  }

  void EvaluateAnalytic(AnalyticEval& e, const AnalyticRow* rows, int count) const override {
    const Eigen::VectorXd& v = e.v;
    const Eigen::Matrix3d G = Eigen::Matrix3d::Identity();
    for (const AnalyticRow* r = rows; r != rows + count; ++r) {
      Eigen::Vector3d tip, target = r->a;
      for (int c = 0; c < 3; ++c) {
        tip[c] = r->tool_ball[c] + v[r->idx[1 + c]];
        target[c] += v[r->idx[4 + c]];
      }
      Eigen::Vector3d P;
      e.ToolPoint(*r, tip, &P);
      const Eigen::Vector3d d = P - target - r->measured;
      for (int k = 0; k < 3; ++k) {
        e.residuals[e.row + k] = d[k];
        e.Put(e.row + k, r->idx[4 + k], -1.0);
      }
      e.Chain(G, 3, r->idx + 1);
      e.row += 3;
    }
  }

  bool has_length() const override { return false; }
  void SetSample(const Eigen::MatrixXd& values, int r, double, Observation* o) const override {
    Eigen::Vector3d& measured = o->data<BallMountData>().measured;
    measured = values.row(r).transpose();
    for (int c = 0; c < 3; ++c) RequireFinite(measured[c], "ball samples: measured[" + std::to_string(r) + "]");
  }

  std::vector<const char*> plan_keys() const override {
    return {"type", "setup", "axes", "tool_ball", "table_ball", "direction", "id"};
  }
  void AddInputs(SimulationPlan* plan, int i, const PlanSlot*, const RecordedContext*) const override {
    for (int c = 0; c < 3; ++c) AddPlanInput(plan, i, c, -1.0, NoiseLevel(plan->noise));
  }
  void ApplyInput(const SimulationPlan& plan, int i, int c, double x, Observation* o) const override {
    o->data<BallMountData>().measured[c] = plan.base.observations[i].data<BallMountData>().measured[c] + x;
  }

 protected:
  void ValidateOwn(const Observation& o, const std::function<std::string()>& w) const override {
    for (int c = 0; c < 3; ++c)
      if (!(std::abs(o.data<BallMountData>().measured[c]) <= kMaxLinear))
        RequireBounded(o.data<BallMountData>().measured[c], kMaxLinear, w() + ".measured[" + std::to_string(c) + "]");
  }
  void WriteOwn(const Observation& o, json* jo) const override { (*jo)["measured"] = Array3(o.data<BallMountData>().measured); }
  void AddFunctor(ResidualBuilder& b, const Observation& o, const MountRefs& refs) const override {
    b.Add(new Ball3dResidual(b.context, o, refs), 3);
  }
  void SimulateReading(const json&, const std::string&, const PlanTruth&, const std::string&,
                       const Eigen::Vector3d& d, Observation* ob) const override {
    ob->data<BallMountData>().measured = d;
  }
  Eigen::Vector3d ReportRows(const double* r, const Eigen::Vector3d&) const override {
    return Eigen::Vector3d(r[0], r[1], r[2]);
  }
  // EvaluateAnalytic's residual inverted (to rounding): P = table + measured + r.
  bool PointFromRows(const double* r, const BallMountData& d, const Eigen::Vector3d& table_ball,
                     Eigen::Vector3d* point) const override {
    *point = table_ball + d.measured + Eigen::Vector3d(r[0], r[1], r[2]);
    return true;
  }
  // NC programs: an R-test path with a dwell per sample (nc_programs.rtest_program).
  const char* nc_program() const override { return "rtest"; }
};

}  // namespace

const ObservationKind& Ball3dKind() {
  static const Kind kind;
  return kind;
}

}  // namespace fivecal
