#include "fivecal/solve/analytic_residuals.h"

#include <set>

#include "fivecal/model/kinematic_model.h"
#include "fivecal/model/kinematics.h"

namespace fivecal {

AnalyticResiduals::AnalyticResiduals(const Dataset& ds, const ParameterTable& table,
                                     const Eigen::VectorXd& values, const std::vector<int>& estimated)
    : ds_(ds), values_(values), estimated_(estimated) {
  block_of_.assign(table.size(), -1);
  for (size_t b = 0; b < estimated_.size(); ++b) {
    block_of_[estimated_[b]] = static_cast<int>(b);
    mutable_parameter_block_sizes()->push_back(1);
  }
  const Machine& m = ds.machine();
  int num_rows = 0;
  std::set<std::string> probed;
  for (size_t i = 0; i < ds.observations.size(); ++i) {
    const Observation& o = ds.observations[i];
    Row r;
    r.type = o.type;
    r.q.resize(m.num_axes());
    AxisValuesToInternal(m, o.axes.data(), r.q.data());
    r.dir.assign(o.direction.data(), o.direction.data() + o.direction.size());
    int n = 1;
    switch (o.type) {
      case ObservationType::kFacet: {
        const int fi = ds.artefact.FacetIndex(o.target);
        r.a = ds.artefact.facets[fi].point;
        r.n = ds.artefact.facets[fi].normal;
        r.constant = ds.tip_radius;
        r.idx[0] = table.facet(fi);
        break;
      }
      case ObservationType::kSphere: {
        const int si = ds.artefact.SphereIndex(o.target);
        r.a = ds.artefact.spheres[si].center;
        r.constant = ds.artefact.spheres[si].radius + ds.tip_radius;
        for (int c = 0; c < 4; ++c) r.idx[c] = table.sphere(si)[c];
        probed.insert(o.target);
        break;
      }
      case ObservationType::kDbb:
      case ObservationType::kBall3d: {
        const auto& mt = table.mount(o.type, o.setup);
        for (int c = 0; c < 7; ++c) r.idx[c] = mt[c];
        r.a = o.table_ball;
        r.tool_ball = o.tool_ball;
        r.measured = o.measured;
        r.constant = o.length + o.reading;
        if (o.type == ObservationType::kBall3d) n = 3;
        break;
      }
    }
    rows_.push_back(std::move(r));
    for (int k = 0; k < n; ++k) row_source_.push_back(static_cast<int>(i));
    num_rows += n;
  }
  for (size_t b = 0; b < ds.artefact.scale_bars.size(); ++b) {
    const ScaleBar& bar = ds.artefact.scale_bars[b];
    if (!probed.count(bar.sphere1) || !probed.count(bar.sphere2)) continue;  // as Problem
    const int s1 = ds.artefact.SphereIndex(bar.sphere1), s2 = ds.artefact.SphereIndex(bar.sphere2);
    Row r;
    r.bar = true;
    r.a = ds.artefact.spheres[s1].center;
    r.n = ds.artefact.spheres[s2].center;
    r.constant = bar.length;
    for (int c = 0; c < 3; ++c) {
      r.idx[c] = table.sphere(s1)[c];
      r.idx[3 + c] = table.sphere(s2)[c];
    }
    rows_.push_back(std::move(r));
    row_source_.push_back(-1 - static_cast<int>(b));
    ++num_rows;
  }
  set_num_residuals(num_rows);
}

bool AnalyticResiduals::Evaluate(double const* const* parameters, double* residuals,
                                 double** jacobians) const {
  const Machine& m = ds_.machine();
  const int np = m.num_parameters(), nb = static_cast<int>(estimated_.size());
  Eigen::VectorXd v = values_;
  for (int b = 0; b < nb; ++b) v[estimated_[b]] = parameters[b][0];
  KinematicModel model(m, v.data());
  if (jacobians) model.RestrictJacobian(estimated_);
  const int nr = num_residuals();
  if (jacobians)
    for (int b = 0; b < nb; ++b)
      if (jacobians[b]) std::fill(jacobians[b], jacobians[b] + nr, 0.0);
  // Machine blocks (b, theta index), split by whether they are the probe tip.
  std::vector<std::pair<int, int>> machine_blocks;
  for (int b = 0; b < nb; ++b)
    if (estimated_[b] < np) machine_blocks.emplace_back(b, estimated_[b]);
  const int tip0 = m.tip_index();
  auto put = [&](int row, int index, double value) {
    if (!jacobians || index < 0) return;
    const int b = block_of_[index];
    if (b >= 0 && jacobians[b]) jacobians[b][row] += value;
  };

  Eigen::Matrix<double, 3, Eigen::Dynamic> J(3, np);
  int row = 0;
  for (const Row& r : rows_) {
    if (r.bar) {
      Eigen::Vector3d d = r.a - r.n;
      for (int c = 0; c < 3; ++c) d[c] += v[r.idx[c]] - v[r.idx[3 + c]];
      const double len = d.norm();
      residuals[row] = len - r.constant;
      if (jacobians) {
        const Eigen::Vector3d u = d / len;
        for (int c = 0; c < 3; ++c) {
          put(row, r.idx[c], u[c]);
          put(row, r.idx[3 + c], -u[c]);
        }
      }
      ++row;
      continue;
    }
    const bool ball = r.type == ObservationType::kDbb || r.type == ObservationType::kBall3d;
    Eigen::Vector3d tip = model.tip();
    Eigen::Vector3d target = r.a;
    if (ball) {
      for (int c = 0; c < 3; ++c) {
        tip[c] = r.tool_ball[c] + v[r.idx[1 + c]];
        target[c] += v[r.idx[4 + c]];
      }
    }
    Eigen::Vector3d P;
    if (jacobians) model.ToolPointJacobian(r.q.data(), r.dir.data(), tip, &P, J.data());
    else P = model.ToolPoint(r.q.data(), r.dir.data(), tip);

    // Residual rows as g_k^T P + ..., with g_k the gradient of row k in P.
    Eigen::Matrix3d G;  // rows: gradients in P of this observation's residual rows
    int n = 1;
    switch (r.type) {
      case ObservationType::kFacet:
        residuals[row] = r.n.dot(P - r.a) - r.constant - v[r.idx[0]];
        G.row(0) = r.n.transpose();
        put(row, r.idx[0], -1.0);
        break;
      case ObservationType::kSphere: {
        const Eigen::Vector3d c = r.a + Eigen::Vector3d(v[r.idx[0]], v[r.idx[1]], v[r.idx[2]]);
        const Eigen::Vector3d d = P - c;
        const double len = d.norm();
        residuals[row] = len - r.constant - v[r.idx[3]];
        const Eigen::Vector3d u = d / len;
        G.row(0) = u.transpose();
        for (int k = 0; k < 3; ++k) put(row, r.idx[k], -u[k]);
        put(row, r.idx[3], -1.0);
        break;
      }
      case ObservationType::kDbb: {
        const Eigen::Vector3d d = P - target;
        const double len = d.norm();
        residuals[row] = len - r.constant - v[r.idx[0]];
        const Eigen::Vector3d u = d / len;
        G.row(0) = u.transpose();
        put(row, r.idx[0], -1.0);
        for (int k = 0; k < 3; ++k) put(row, r.idx[4 + k], -u[k]);
        break;
      }
      case ObservationType::kBall3d: {
        n = 3;
        const Eigen::Vector3d d = P - target - r.measured;
        for (int k = 0; k < 3; ++k) {
          residuals[row + k] = d[k];
          put(row + k, r.idx[4 + k], -1.0);
        }
        G.setIdentity();
        break;
      }
    }
    if (jacobians) {
      for (int k = 0; k < n; ++k) {
        const Eigen::RowVector3d g = G.row(k);
        for (const auto& [b, idx] : machine_blocks) {
          if (!jacobians[b]) continue;
          const bool is_tip = idx >= tip0 && idx < tip0 + 3;
          if (ball && is_tip) continue;  // the probe tip does not carry the ball
          jacobians[b][row + k] += g.dot(J.col(idx));
        }
        if (ball)  // the tool ball's offsets act like a tip: dP/dtip
          for (int c = 0; c < 3; ++c) put(row + k, r.idx[1 + c], g.dot(J.col(tip0 + c)));
      }
    }
    row += n;
  }
  return true;
}

}  // namespace fivecal
