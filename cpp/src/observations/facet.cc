#include "fivecal/observations/facet.h"

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

class Kind final : public ProbeTouchKind {
 public:
  ObservationType type() const override { return ObservationType::kFacet; }
  const char* name() const override { return "facet"; }
  const char* label() const override { return "probe touch on a facet"; }
  KindReport Report() const override {
    KindReport r;
    r.target_list = "facets";
    return r;
  }

  void AddArtefactParameters(const Dataset& ds, ParameterTable* t) const override {
    for (const Facet& f : ds.artefact.facets) t->AddGroup(type(), f.id, {t->Add("facet." + f.id)});
  }
  bool IsParameterName(const std::string& rest) const override { return rest.find('.') == std::string::npos; }
  std::vector<PriorClass> prior_classes() const override {
    return {{"facet", 1.0, "mm", "facet.<id>: offset of a facet from its nominal plane"}, ProbeClass()};
  }
  const char* PriorClassOfName(const std::string& n) const override {
    return n.rfind("facet.", 0) == 0 ? "facet" : ProbeTouchKind::PriorClassOfName(n);
  }

  void AddResidual(ResidualBuilder& b, const Observation& o) const override {
    const Dataset& ds = b.dataset;
    const int fi = ds.artefact.FacetIndex(o.data<TouchData>().target);
    const SetupRef off = b.Ref(b.table.group(type(), o.data<TouchData>().target)[0]);
    const ProbeTrigger trigger = MakeProbeTrigger(b, o);
    b.Add(new FacetResidual(b.context, o, ds.artefact.facets[fi], ds.tip_radius, off, trigger), 1);
  }
  void PrepareAnalytic(const Dataset& ds, const ParameterTable& t, const Observation& o,
                       AnalyticRow* r) const override {
    const Facet& f = ds.artefact.facets[ds.artefact.FacetIndex(o.data<TouchData>().target)];
    r->a = f.point;
    r->n = f.normal;
    r->constant = ds.tip_radius;
    r->idx[0] = t.group(type(), o.data<TouchData>().target)[0];
    PrepareProbeTrigger(ds, t, o, r);
  }
  void EvaluateAnalytic(AnalyticEval& e, const AnalyticRow* rows, int count) const override {
    Eigen::Matrix3d G;
    for (const AnalyticRow* r = rows; r != rows + count; ++r) {
      Eigen::Vector3d P;
      e.ToolPoint(*r, e.probe_tip(), &P);
      e.residuals[e.row] = r->n.dot(P - r->a) - r->constant - e.v[r->idx[0]] + ProbePretravel(e, *r, -r->n, nullptr);
      G.row(0) = r->n.transpose();
      e.Put(e.row, r->idx[0], -1.0);
      e.Chain(G, 1, nullptr);
      e.row += 1;
    }
  }

  void ReportVector(const ReportContext& c, const Observation& o, const double* r, Eigen::Vector3d* point,
                    Eigen::Vector3d* vector) const override {
    const Dataset& ds = *c.dataset;
    *point = FittedTipCentre(c, o);
    *vector = r[0] * ds.artefact.facets[ds.artefact.FacetIndex(o.data<TouchData>().target)].normal;
  }

 protected:
  int TargetIndex(const Artefact& a, const std::string& id) const override { return a.FacetIndex(id); }
  bool PlannedContact(const Dataset& ds, const json& e, const std::string& w, Eigen::Vector3d* point,
                      Eigen::Vector3d* normal) const override {
    const Facet& f = ds.artefact.facets[RequireTarget(ds, e.value("target", std::string()), w)];
    *point = ReadVector3(e.value("point", json()), w + ".point");
    *normal = f.normal.normalized();
    return true;
  }
  int DefaultTargetParameters() const override { return 1; }  // facet.<id>
  void PlannedTouch(const json& e, const std::string& w, const PlanTruth& t, const Observation& ob,
                    Eigen::Vector3d* n_out, Eigen::Vector3d* c, Gap* gap) const override {
    const Dataset& ds = *t.dataset;
    const double r = ds.tip_radius;
    const int fi = RequireTarget(ds, ob.data<TouchData>().target, w);
    const Facet& f = ds.artefact.facets[fi];
    const Eigen::Vector3d n = f.normal;
    Eigen::Vector3d p = e.contains("point") ? ReadVector3(e["point"], w + ".point") : f.point;
    p -= n * n.dot(p - f.point);  // onto the nominal plane
    *c = p + r * n;
    const Eigen::Vector3d a_true = f.point + t.setup("facet." + f.id) * n;
    *gap = [=](const Eigen::Vector3d& P) { return n.dot(P - a_true) - r; };
    *n_out = n;
  }
  void RecordedTouch(const RecordedContext& rec, const Observation& o, const Eigen::Vector3d&,
                     const std::string&, Eigen::Vector3d* n_out, Gap* gap) const override {
    const Dataset& ds = *rec.dataset;
    const Facet& f = ds.artefact.facets[ds.artefact.FacetIndex(o.data<TouchData>().target)];
    const Eigen::Vector3d n = f.normal;
    const double off = rec.values[rec.table->group(type(), o.data<TouchData>().target)[0]];
    *gap = [=](const Eigen::Vector3d& P) { return n.dot(P - f.point) - off; };
    *n_out = n;
  }

  // NC programs (defined at the end of this file).
  ProbeCrossing CrossProbeLine(const Dataset& ds, const std::string& target, const Eigen::Vector3d& p,
                               const Eigen::Vector3d& d) const override;
};

}  // namespace

const ObservationKind& FacetKind() {
  static const Kind kind;
  return kind;
}

}  // namespace fivecal

// ---- What an NC program needs (io/nc_programs.py) ----------------------------------

namespace fivecal {
namespace {

// The stylus centre meets the facet's plane moved out by the stylus radius:
// n.(p + s d - (a + r n)) = 0, coming from outside (n.d < 0).
ProbeCrossing Kind::CrossProbeLine(const Dataset& ds, const std::string& target, const Eigen::Vector3d& p,
                                   const Eigen::Vector3d& d) const {
  const Facet& f = ds.artefact.facets[RequireTarget(ds, target, "target")];
  ProbeCrossing c;
  c.normal = f.normal.normalized();
  const Eigen::Vector3d q0 = f.point + ds.tip_radius * c.normal;
  const double h0 = c.normal.dot(p - q0), dn = c.normal.dot(d);
  c.inside = h0 <= 0;
  c.s = dn < 0 ? -h0 / dn : std::numeric_limits<double>::infinity();
  return c;
}

}  // namespace
}  // namespace fivecal
