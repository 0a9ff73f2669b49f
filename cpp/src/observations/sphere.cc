#include "fivecal/observations/sphere.h"

#include <nlohmann/json.hpp>
#include <stdexcept>

#include "fivecal/model/kinematic_model.h"
#include "fivecal/observations/probe_touch.h"
#include "fivecal/solve/analytic_residuals.h"
#include "fivecal/solve/problem.h"
#include "json_util.h"

namespace fivecal {
namespace {

using namespace json_util;

// The spheres probed in `ds`: a scale bar says something only about those.
std::set<std::string> Probed(const Dataset& ds) {
  std::set<std::string> probed;
  for (const Observation& o : ds.observations)
    if (o.type == ObservationType::kSphere) probed.insert(o.data<TouchData>().target);
  return probed;
}

class Kind final : public ProbeTouchKind {
 public:
  ObservationType type() const override { return ObservationType::kSphere; }
  const char* name() const override { return "sphere"; }
  const char* label() const override { return "probe touch on a sphere"; }
  KindReport Report() const override {
    KindReport r;
    r.target_list = "spheres";
    return r;
  }

  void AddArtefactParameters(const Dataset& ds, ParameterTable* t) const override {
    for (const Sphere& s : ds.artefact.spheres) {
      std::vector<int> idx;
      for (const char* c : {"x", "y", "z", "r"}) idx.push_back(t->Add("sphere." + s.id + "." + c));
      t->AddGroup(type(), s.id, idx);
    }
  }
  // sphere.<id>.x|y|z|r
  bool IsParameterName(const std::string& rest) const override {
    const size_t dot = rest.find('.');
    if (dot == std::string::npos || dot != rest.rfind('.') || rest.size() <= 2) return false;
    const std::string tail = rest.substr(rest.size() - 2);
    return tail == ".x" || tail == ".y" || tail == ".z" || tail == ".r";
  }
  std::vector<PriorClass> prior_classes() const override {
    return {{"sphere_center", 1.0, "mm", "sphere.<id>.x|y|z: where a sphere really sits"},
            {"sphere_radius", 0.01, "mm", "sphere.<id>.r: a calibrated sphere's radius error"},
            ProbeClass()};
  }
  // Placement (docs/setup_uncertainty.md): a calibrated sphere's radius is
  // known from its certificate to about a micrometre. Its centre is what the
  // probing finds: the nominal is a start (a rough touch-off, and a machine
  // file's pivot moves the workpiece frame it is given in), no placement
  // unless the dataset declares one (a sphere on a located nest).
  double DefaultPlacement(const std::string& n) const override {
    if (n.rfind("sphere.", 0) != 0) return 0.0;
    return n.size() >= 2 && n.compare(n.size() - 2, 2, ".r") == 0 ? 0.001 : 0.0;
  }
  const char* PriorClassOfName(const std::string& n) const override {
    if (n.rfind("sphere.", 0) != 0) return ProbeTouchKind::PriorClassOfName(n);
    return n.size() >= 2 && n.compare(n.size() - 2, 2, ".r") == 0 ? "sphere_radius" : "sphere_center";
  }

  void AddResidual(ResidualBuilder& b, const Observation& o) const override {
    const Dataset& ds = b.dataset;
    const int si = ds.artefact.SphereIndex(o.data<TouchData>().target);
    const auto& sp = b.table.group(type(), o.data<TouchData>().target);
    const SetupRef c[3] = {b.Ref(sp[0]), b.Ref(sp[1]), b.Ref(sp[2])};
    const SetupRef r = b.Ref(sp[3]);
    const ProbeTrigger trigger = MakeProbeTrigger(b, o);
    b.Add(new SphereResidual(b.context, o, ds.artefact.spheres[si], ds.tip_radius, c, r, trigger), 1);
  }
  std::vector<int> ScaleBarRows(const Dataset& ds) const override {
    const std::set<std::string> probed = Probed(ds);
    std::vector<int> out;
    for (size_t i = 0; i < ds.artefact.scale_bars.size(); ++i)
      if (probed.count(ds.artefact.scale_bars[i].sphere1) && probed.count(ds.artefact.scale_bars[i].sphere2))
        out.push_back(static_cast<int>(i));
    return out;
  }
  void AddArtefactResiduals(ResidualBuilder& b) const override {
    const Dataset& ds = b.dataset;
    const std::set<std::string> probed = Probed(ds);
    for (size_t i = 0; i < ds.artefact.scale_bars.size(); ++i) {
      const ScaleBar& bar = ds.artefact.scale_bars[i];
      // A bar whose balls were not probed in this dataset says nothing about it.
      if (!probed.count(bar.sphere1) || !probed.count(bar.sphere2)) continue;
      b.Start(-1 - static_cast<int>(i), false);
      const auto &p1 = b.table.group(type(), bar.sphere1), &p2 = b.table.group(type(), bar.sphere2);
      const SetupRef d1[3] = {b.Ref(p1[0]), b.Ref(p1[1]), b.Ref(p1[2])};
      const SetupRef d2[3] = {b.Ref(p2[0]), b.Ref(p2[1]), b.Ref(p2[2])};
      const Sphere& s1 = ds.artefact.spheres[ds.artefact.SphereIndex(bar.sphere1)];
      const Sphere& s2 = ds.artefact.spheres[ds.artefact.SphereIndex(bar.sphere2)];
      b.Add(new ScaleBarResidual(b.context, s1, s2, bar.length, d1, d2), 1);
    }
  }

  // variant 0: a touch (a: centre, constant: R + r_tip, idx: x y z r);
  // variant 1: a scale bar (a, n: the two centres, constant: L, idx: the
  // centre offsets of sphere 1 then 2).
  void PrepareAnalytic(const Dataset& ds, const ParameterTable& t, const Observation& o,
                       AnalyticRow* r) const override {
    const int si = ds.artefact.SphereIndex(o.data<TouchData>().target);
    r->a = ds.artefact.spheres[si].center;
    r->constant = ds.artefact.spheres[si].radius + ds.tip_radius;
    for (int c = 0; c < 4; ++c) r->idx[c] = t.group(type(), o.data<TouchData>().target)[c];
    PrepareProbeTrigger(ds, t, o, r);
  }
  void AddArtefactAnalyticRows(const Dataset& ds, const ParameterTable& t, std::vector<AnalyticRow>* rows,
                               std::vector<int>* source) const override {
    const std::set<std::string> probed = Probed(ds);
    for (size_t b = 0; b < ds.artefact.scale_bars.size(); ++b) {
      const ScaleBar& bar = ds.artefact.scale_bars[b];
      if (!probed.count(bar.sphere1) || !probed.count(bar.sphere2)) continue;  // as AddArtefactResiduals
      AnalyticRow r;
      r.kind = this;
      r.variant = 1;
      r.a = ds.artefact.spheres[ds.artefact.SphereIndex(bar.sphere1)].center;
      r.n = ds.artefact.spheres[ds.artefact.SphereIndex(bar.sphere2)].center;
      r.constant = bar.length;
      for (int c = 0; c < 3; ++c) {
        r.idx[c] = t.group(type(), bar.sphere1)[c];
        r.idx[3 + c] = t.group(type(), bar.sphere2)[c];
      }
      rows->push_back(std::move(r));
      source->push_back(-1 - static_cast<int>(b));
    }
  }
  void EvaluateAnalytic(AnalyticEval& e, const AnalyticRow* rows, int count) const override {
    const Eigen::VectorXd& v = e.v;
    if (rows[0].variant == 1) {
      for (const AnalyticRow* r = rows; r != rows + count; ++r) {
        Eigen::Vector3d d = r->a - r->n;
        for (int c = 0; c < 3; ++c) d[c] += v[r->idx[c]] - v[r->idx[3 + c]];
        const double len = d.norm();
        e.residuals[e.row] = len - r->constant;
        if (e.jacobians) {
          const Eigen::Vector3d u = d / len;
          for (int c = 0; c < 3; ++c) {
            e.Put(e.row, r->idx[c], u[c]);
            e.Put(e.row, r->idx[3 + c], -u[c]);
          }
        }
        e.row += 1;
      }
      return;
    }
    Eigen::Matrix3d G;
    for (const AnalyticRow* r = rows; r != rows + count; ++r) {
      Eigen::Vector3d P;
      e.ToolPoint(*r, e.probe_tip(), &P);
      const Eigen::Vector3d c = r->a + Eigen::Vector3d(v[r->idx[0]], v[r->idx[1]], v[r->idx[2]]);
      const Eigen::Vector3d d = P - c;
      const double len = d.norm();
      const Eigen::Vector3d u = d / len;
      Eigen::Vector3d gp;  // dp/du_work at u_work = -u
      const double p = ProbePretravel(e, *r, -u, &gp);
      e.residuals[e.row] = len - r->constant - v[r->idx[3]] + p;
      // d(-u)/dP = -(I - u u^T) / len
      const Eigen::Vector3d grad = u - (gp - u * u.dot(gp)) / len;
      G.row(0) = grad.transpose();
      for (int k = 0; k < 3; ++k) e.Put(e.row, r->idx[k], -grad[k]);
      e.Put(e.row, r->idx[3], -1.0);
      e.Chain(G, 1, nullptr);
      e.row += 1;
    }
  }

  std::vector<const char*> plan_keys() const override {
    return {"type", "target", "axes", "normal", "direction", "id"};
  }

  bool ArtefactLengthReference(const Dataset& ds) const override {
    const std::set<std::string> probed = Probed(ds);
    for (const ScaleBar& b : ds.artefact.scale_bars)
      if (probed.count(b.sphere1) && probed.count(b.sphere2)) return true;
    return false;
  }
  void ReportVector(const ReportContext& c, const Observation& o, const double* r, Eigen::Vector3d* point,
                    Eigen::Vector3d* vector) const override {
    const Dataset& ds = *c.dataset;
    const Eigen::Vector3d P = FittedTipCentre(c, o);
    const auto& sp = c.table->group(type(), o.data<TouchData>().target);
    const Eigen::VectorXd& values = *c.values;
    const Eigen::Vector3d centre = ds.artefact.spheres[ds.artefact.SphereIndex(o.data<TouchData>().target)].center +
                                   Eigen::Vector3d(values[sp[0]], values[sp[1]], values[sp[2]]);
    *point = P;
    *vector = r[0] * (P - centre).normalized();
  }

 protected:
  int TargetIndex(const Artefact& a, const std::string& id) const override { return a.SphereIndex(id); }
  bool PlannedContact(const Dataset& ds, const json& e, const std::string& w, Eigen::Vector3d* point,
                      Eigen::Vector3d* normal) const override {
    const Sphere& s = ds.artefact.spheres[RequireTarget(ds, e.value("target", std::string()), w)];
    *normal = UnitDirection(ReadVector3(e.value("normal", json()), w + ".normal"), w + ".normal");
    *point = s.center + s.radius * *normal;
    return true;
  }
  // The centre; the radius only on request (a calibrated sphere's is known).
  int DefaultTargetParameters() const override { return 3; }
  void PlannedTouch(const json& e, const std::string& w, const PlanTruth& t, const Observation& ob,
                    Eigen::Vector3d* n_out, Eigen::Vector3d* c, Gap* gap) const override {
    const Dataset& ds = *t.dataset;
    const double r = ds.tip_radius;
    const int si = RequireTarget(ds, ob.data<TouchData>().target, w);
    const Sphere& s = ds.artefact.spheres[si];
    if (!e.contains("normal")) throw std::invalid_argument(w + ".normal: missing (touch direction from the centre)");
    const Eigen::Vector3d n = UnitDirection(ReadVector3(e["normal"], w + ".normal"), w + ".normal");
    *c = s.center + (s.radius + r) * n;
    const std::string id = s.id;
    const Eigen::Vector3d c_true = s.center + Eigen::Vector3d(t.setup("sphere." + id + ".x"),
                                                              t.setup("sphere." + id + ".y"),
                                                              t.setup("sphere." + id + ".z"));
    const double R_true = s.radius + t.setup("sphere." + id + ".r");
    *gap = [=](const Eigen::Vector3d& P) { return (P - c_true).norm() - (R_true + r); };
    *n_out = n;
  }
  void RecordedTouch(const RecordedContext& rec, const Observation& o, const Eigen::Vector3d& P0,
                     const std::string& w, Eigen::Vector3d* n_out, Gap* gap) const override {
    const Dataset& ds = *rec.dataset;
    const int si = ds.artefact.SphereIndex(o.data<TouchData>().target);
    const Sphere& sp = ds.artefact.spheres[si];
    Eigen::Vector3d n = P0 - sp.center;
    if (n.norm() < 1e-9) throw std::invalid_argument(w + ": touch at the sphere centre");
    n.normalize();
    const auto& ix = rec.table->group(type(), o.data<TouchData>().target);
    const Eigen::Vector3d c = sp.center + Eigen::Vector3d(rec.values[ix[0]], rec.values[ix[1]], rec.values[ix[2]]);
    *gap = [=](const Eigen::Vector3d& P) { return (P - c).norm(); };
    *n_out = n;
  }

  // NC programs (defined at the end of this file).
  ProbeCrossing CrossProbeLine(const Dataset& ds, const std::string& target, const Eigen::Vector3d& p,
                               const Eigen::Vector3d& d) const override;
  // The sphere cycle; its spheres are the balls the moves keep out of.
  const char* nc_program() const override { return "sphere"; }
  std::vector<ClearanceBall> ClearanceBalls(const Dataset& ds) const override;
};

}  // namespace

const ObservationKind& SphereKind() {
  static const Kind kind;
  return kind;
}

}  // namespace fivecal

// ---- What an NC program needs (io/nc_programs.py) ----------------------------------

namespace fivecal {
namespace {

std::vector<ClearanceBall> Kind::ClearanceBalls(const Dataset& ds) const {
  std::vector<ClearanceBall> out;
  for (const Sphere& s : ds.artefact.spheres) out.push_back({s.id, s.center, s.radius});
  return out;
}

// The stylus centre meets the sphere grown by the stylus radius:
// |p + s d - c| = R + r, the first root coming from outside.
ProbeCrossing Kind::CrossProbeLine(const Dataset& ds, const std::string& target, const Eigen::Vector3d& p,
                                   const Eigen::Vector3d& d) const {
  const Sphere& sp = ds.artefact.spheres[RequireTarget(ds, target, "target")];
  const double rr = sp.radius + ds.tip_radius;
  const Eigen::Vector3d w = p - sp.center;
  const double a = d.dot(d), b = (2 * d).dot(w), cc = w.dot(w) - rr * rr;
  const double disc = b * b - 4 * a * cc;
  ProbeCrossing c;
  c.inside = cc <= 0;
  c.s = disc >= 0 ? (-b - std::sqrt(disc)) / (2 * a) : std::numeric_limits<double>::infinity();
  const Eigen::Vector3d q = std::isfinite(c.s) ? Eigen::Vector3d(p + c.s * d) : p;
  c.normal = (q - sp.center) / (q - sp.center).norm();
  return c;
}

}  // namespace
}  // namespace fivecal
