#include "fivecal/observations/cylinder.h"

#include <nlohmann/json.hpp>
#include <stdexcept>

#include "fivecal/model/kinematic_model.h"
#include "fivecal/observations/probe_touch.h"
#include "fivecal/solve/analytic_residuals.h"
#include "fivecal/solve/problem.h"
#include "json_util.h"

namespace fivecal {

void CylinderFrame(const Eigen::Vector3d& a, Eigen::Vector3d* x, Eigen::Vector3d* y) {
  Eigen::Vector3d v = Eigen::Vector3d::UnitX() - a * a.x();
  if (v.norm() < 0.1) v = Eigen::Vector3d::UnitY() - a * a.y();
  *x = v.normalized();
  *y = a.cross(*x);
}

namespace {

using namespace json_util;

const char* kFields[5] = {"r", "x", "y", "rx", "ry"};

// The true (or estimated) axis line of cylinder `c` with setup values
// (r, x, y, rx, ry): its point, unit direction and radius.
struct Axis {
  Eigen::Vector3d c, a;
  double R;
};
Axis AxisOf(const Cylinder& cyl, const double* v) {
  Eigen::Vector3d x, y;
  CylinderFrame(cyl.axis, &x, &y);
  Axis out;
  out.c = cyl.point + v[1] * x + v[2] * y;
  out.a = (cyl.axis + v[4] * x - v[3] * y).normalized();
  out.R = cyl.radius + v[0];
  return out;
}
// The radial vector of P from the axis line.
Eigen::Vector3d Radial(const Axis& ax, const Eigen::Vector3d& P) {
  const Eigen::Vector3d w = P - ax.c;
  return w - ax.a * w.dot(ax.a);
}

class Kind final : public ProbeTouchKind {
 public:
  ObservationType type() const override { return ObservationType::kCylinder; }
  const char* name() const override { return "cylinder"; }
  const char* label() const override { return "probe touch on a cylinder"; }
  KindReport Report() const override {
    KindReport r;
    r.target_list = "cylinders";
    return r;
  }

  void AddArtefactParameters(const Dataset& ds, ParameterTable* t) const override {
    for (const Cylinder& c : ds.artefact.cylinders) {
      std::vector<int> idx;
      for (const char* f : kFields) idx.push_back(t->Add("cylinder." + c.id + "." + f));
      t->AddGroup(type(), c.id, idx);
    }
  }
  // cylinder.<id>.r|x|y|rx|ry
  bool IsParameterName(const std::string& rest) const override {
    const size_t dot = rest.find('.');
    if (dot == std::string::npos || dot == 0 || dot != rest.rfind('.')) return false;
    const std::string tail = rest.substr(dot + 1);
    for (const char* f : kFields)
      if (tail == f) return true;
    return false;
  }
  std::vector<PriorClass> prior_classes() const override {
    return {{"cylinder_radius", 1.0, "mm", "cylinder.<id>.r: radius error of an uncalibrated cylinder section"},
            {"cylinder_axis", 1.0, "mm", "cylinder.<id>.x|y: where a cylinder's axis line really is"},
            {"cylinder_tilt", 1e-3, "rad", "cylinder.<id>.rx|ry: tilt of a cylinder's axis: 1 mrad"},
            ProbeClass()};
  }
  const char* PriorClassOfName(const std::string& n) const override {
    if (n.rfind("cylinder.", 0) != 0) return ProbeTouchKind::PriorClassOfName(n);
    const std::string tail = n.substr(n.rfind('.') + 1);
    if (tail == "r") return "cylinder_radius";
    return tail == "rx" || tail == "ry" ? "cylinder_tilt" : "cylinder_axis";
  }

  void AddResidual(ResidualBuilder& b, const Observation& o) const override {
    const Dataset& ds = b.dataset;
    const auto& g = b.table.group(type(), o.data<TouchData>().target);
    const SetupRef s[5] = {b.Ref(g[0]), b.Ref(g[1]), b.Ref(g[2]), b.Ref(g[3]), b.Ref(g[4])};
    const ProbeTrigger trigger = MakeProbeTrigger(b, o);
    b.Add(new CylinderResidual(b.context, o, ds.artefact.cylinders[ds.artefact.CylinderIndex(o.data<TouchData>().target)],
                               ds.tip_radius, s, trigger),
          1);
  }
  // a: the nominal axis point, n: the nominal axis, constant: R,
  // measured: (side s, tip radius, 0), idx: r x y rx ry.
  void PrepareAnalytic(const Dataset& ds, const ParameterTable& t, const Observation& o,
                       AnalyticRow* r) const override {
    const Cylinder& c = ds.artefact.cylinders[ds.artefact.CylinderIndex(o.data<TouchData>().target)];
    r->a = c.point;
    r->n = c.axis;
    r->constant = c.radius;
    r->measured = Eigen::Vector3d(c.inside ? -1.0 : 1.0, ds.tip_radius, 0.0);
    for (int k = 0; k < 5; ++k) r->idx[k] = t.group(type(), o.data<TouchData>().target)[k];
    PrepareProbeTrigger(ds, t, o, r);
  }
  void EvaluateAnalytic(AnalyticEval& e, const AnalyticRow* rows, int count) const override {
    const Eigen::VectorXd& v = e.v;
    Eigen::Matrix3d Gm;
    for (const AnalyticRow* r = rows; r != rows + count; ++r) {
      Eigen::Vector3d P;
      e.ToolPoint(*r, e.probe_tip(), &P);
      Eigen::Vector3d x, y;
      CylinderFrame(r->n, &x, &y);
      const double sx = v[r->idx[1]], sy = v[r->idx[2]], rx = v[r->idx[3]], ry = v[r->idx[4]];
      const Eigen::Vector3d c = r->a + sx * x + sy * y;
      const Eigen::Vector3d vv = r->n + ry * x - rx * y;
      const double vn = vv.norm();
      const Eigen::Vector3d a = vv / vn;
      const Eigen::Vector3d w = P - c;
      const double wa = w.dot(a);
      const Eigen::Vector3d d = w - a * wa;
      const double rho = d.norm();
      const Eigen::Vector3d eu = d / rho;
      const double s = r->measured[0];
      Eigen::Vector3d g;
      const double p = ProbePretravel(e, *r, -s * eu, &g);
      e.residuals[e.row] = s * (rho - (r->constant + v[r->idx[0]])) - r->measured[1] + p;
      if (e.jacobians) {
        // D g with D = (I - e e^T - a a^T) / rho
        const Eigen::Vector3d Dg = (g - eu * eu.dot(g) - a * a.dot(g)) / rho;
        const Eigen::Vector3d G = s * (eu - Dg);
        Gm.row(0) = G.transpose();
        e.Put(e.row, r->idx[0], -s);
        e.Put(e.row, r->idx[1], -G.dot(x));
        e.Put(e.row, r->idx[2], -G.dot(y));
        const Eigen::Vector3d da =
            s * (-wa * eu + wa * (g - eu * eu.dot(g)) / rho + a.dot(g) * w / rho);
        const Eigen::Vector3d proj = (da - a * a.dot(da)) / vn;  // (I - a a^T) da / |v|
        e.Put(e.row, r->idx[3], -proj.dot(y));
        e.Put(e.row, r->idx[4], proj.dot(x));
        e.Chain(Gm, 1, nullptr);
      }
      e.row += 1;
    }
  }

  void ReportVector(const ReportContext& c, const Observation& o, const double* r, Eigen::Vector3d* point,
                    Eigen::Vector3d* vector) const override {
    const Dataset& ds = *c.dataset;
    const Eigen::Vector3d P = FittedTipCentre(c, o);
    const Cylinder& cyl = ds.artefact.cylinders[ds.artefact.CylinderIndex(o.data<TouchData>().target)];
    double sv[5];
    const auto& g = c.table->group(type(), o.data<TouchData>().target);
    for (int k = 0; k < 5; ++k) sv[k] = (*c.values)[g[k]];
    const Eigen::Vector3d radial = Radial(AxisOf(cyl, sv), P);
    *point = P;
    *vector = r[0] * (cyl.inside ? -1.0 : 1.0) * radial.normalized();
  }

 protected:
  int TargetIndex(const Artefact& a, const std::string& id) const override { return a.CylinderIndex(id); }
  bool PlannedContact(const Dataset& ds, const json& e, const std::string& w, Eigen::Vector3d* point,
                      Eigen::Vector3d* normal) const override {
    const Cylinder& c = ds.artefact.cylinders[RequireTarget(ds, e.value("target", std::string()), w)];
    *point = ReadVector3(e.value("point", json()), w + ".point");
    const Eigen::Vector3d a = c.axis.normalized(), d = *point - c.point, radial = d - a * a.dot(d);
    if (radial.norm() == 0) throw std::invalid_argument(w + ".point: on the cylinder's axis");
    *normal = radial.normalized() * (c.inside ? -1.0 : 1.0);
    return true;
  }
  // The radius and where the axis line is (r, x, y); its tilt only on
  // request (a short section hardly shows it).
  int DefaultTargetParameters() const override { return 3; }
  void PlannedTouch(const json& e, const std::string& w, const PlanTruth& t, const Observation& ob,
                    Eigen::Vector3d* n_out, Eigen::Vector3d* c_out, Gap* gap) const override {
    const Dataset& ds = *t.dataset;
    const double r = ds.tip_radius;
    const int ci = RequireTarget(ds, ob.data<TouchData>().target, w);
    const Cylinder& cyl = ds.artefact.cylinders[ci];
    if (!e.contains("point"))
      throw std::invalid_argument(w + ".point: missing (where to touch the cylinder, workpiece frame)");
    const Eigen::Vector3d p = ReadVector3(e["point"], w + ".point");
    const double zero[5] = {0, 0, 0, 0, 0};
    const Eigen::Vector3d radial = Radial(AxisOf(cyl, zero), p);
    if (radial.norm() < 1e-6) throw std::invalid_argument(w + ".point: on the cylinder's axis");
    const Eigen::Vector3d u = radial.normalized();
    const double s = cyl.inside ? -1.0 : 1.0;
    // Onto the nominal surface, the tip centre one tip radius off it.
    const Eigen::Vector3d q = p - radial + cyl.radius * u;
    *n_out = s * u;
    *c_out = q + r * s * u;
    double tv[5];
    for (int k = 0; k < 5; ++k) tv[k] = t.setup("cylinder." + cyl.id + "." + kFields[k]);
    const Axis truth = AxisOf(cyl, tv);
    *gap = [=](const Eigen::Vector3d& P) { return s * (Radial(truth, P).norm() - truth.R) - r; };
  }
  void RecordedTouch(const RecordedContext& rec, const Observation& o, const Eigen::Vector3d& P0,
                     const std::string& w, Eigen::Vector3d* n_out, Gap* gap) const override {
    const Dataset& ds = *rec.dataset;
    const Cylinder& cyl = ds.artefact.cylinders[ds.artefact.CylinderIndex(o.data<TouchData>().target)];
    const double zero[5] = {0, 0, 0, 0, 0};
    const Eigen::Vector3d radial = Radial(AxisOf(cyl, zero), P0);
    if (radial.norm() < 1e-9) throw std::invalid_argument(w + ": touch on the cylinder's axis");
    const double s = cyl.inside ? -1.0 : 1.0;
    *n_out = s * radial.normalized();
    double sv[5];
    const auto& g = rec.table->group(type(), o.data<TouchData>().target);
    for (int k = 0; k < 5; ++k) sv[k] = rec.values[g[k]];
    const Axis est = AxisOf(cyl, sv);
    *gap = [=](const Eigen::Vector3d& P) { return s * Radial(est, P).norm(); };
  }

  // NC programs (defined at the end of this file).
  ProbeCrossing CrossProbeLine(const Dataset& ds, const std::string& target, const Eigen::Vector3d& p,
                               const Eigen::Vector3d& d) const override;
};

}  // namespace

const ObservationKind& CylinderKind() {
  static const Kind kind;
  return kind;
}

}  // namespace fivecal

// ---- What an NC program needs (io/nc_programs.py) ----------------------------------

namespace fivecal {
namespace {

// The stylus centre meets the nominal cylinder moved out by the stylus
// radius (radius R + r outside a boss, R - r in a bore): the line's radial
// part w + s v (across the axis) reaches that radius, the first root from
// outside a boss, the outward one from inside a bore.
ProbeCrossing Kind::CrossProbeLine(const Dataset& ds, const std::string& target, const Eigen::Vector3d& p,
                                   const Eigen::Vector3d& d) const {
  const Cylinder& cyl = ds.artefact.cylinders[RequireTarget(ds, target, "target")];
  const double zero[5] = {0, 0, 0, 0, 0};
  const Axis ax = AxisOf(cyl, zero);
  const double side = cyl.inside ? -1.0 : 1.0;
  const double rr = ax.R + side * ds.tip_radius;
  const Eigen::Vector3d w = Radial(ax, p), v = d - ax.a * d.dot(ax.a);
  const double a = v.dot(v), b = 2 * v.dot(w), cc = w.dot(w) - rr * rr;
  const double disc = b * b - 4 * a * cc;
  ProbeCrossing c;
  c.inside = side * cc <= 0;
  c.s = a > 0 && disc >= 0 ? (-b - side * std::sqrt(disc)) / (2 * a) : std::numeric_limits<double>::infinity();
  if (c.s < 0) c.s = std::numeric_limits<double>::infinity();  // a boss behind the line's start
  const Eigen::Vector3d q = std::isfinite(c.s) ? Eigen::Vector3d(p + c.s * d) : p;
  const Eigen::Vector3d radial = Radial(ax, q);
  c.normal = side * radial / radial.norm();
  return c;
}

}  // namespace
}  // namespace fivecal
