#include "fivecal/model/rotation_forms.h"

#include <cctype>
#include <cmath>
#include <cstdio>
#include <stdexcept>

#include <Eigen/Geometry>
#include <Eigen/SVD>

namespace fivecal {
namespace {

constexpr double kPi = 3.14159265358979323846;

std::string Lower(std::string s) {
  for (char& c : s) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return s;
}

double UnitFactor(const RotationForm& f) {
  const std::string u = Lower(f.unit);
  if (u == "rad" || u.empty()) return 1.0;
  if (u == "deg" || u == "degree" || u == "degrees") return kPi / 180.0;
  throw std::invalid_argument("rotation.unit: '" + f.unit + "' is not an angle unit (rad or deg)");
}

// The sequence as intrinsic axis indices (extrinsic ones reversed, with a
// flag saying the angles are to be reversed too).
void Sequence(const RotationForm& f, int axes[3], bool* extrinsic) {
  const std::string& s = f.sequence;
  const bool upper = s.size() == 3 && std::isupper(static_cast<unsigned char>(s[0]));
  bool ok = s.size() == 3;
  for (size_t i = 0; ok && i < 3; ++i) {
    const char c = s[i];
    ok = (upper ? std::string("XYZ") : std::string("xyz")).find(c) != std::string::npos;
  }
  for (size_t i = 0; ok && i < 2; ++i) ok = std::tolower(s[i]) != std::tolower(s[i + 1]);
  if (!ok)
    throw std::invalid_argument("rotation.sequence: '" + s +
                                "' is not an Euler sequence: three axis letters, no two neighbours equal, all "
                                "upper case (intrinsic, e.g. ZYX) or all lower case (extrinsic, e.g. xyz)");
  *extrinsic = !upper;
  for (int i = 0; i < 3; ++i) {
    const int a = std::tolower(s[*extrinsic ? 2 - i : i]) - 'x';
    axes[i] = a;
  }
}

std::string Fmt(const Eigen::VectorXd& v) {
  std::string out;
  char buf[32];
  for (int i = 0; i < v.size(); ++i) {
    std::snprintf(buf, sizeof buf, "%s%.6g", i ? ", " : "", v[i]);
    out += buf;
  }
  return out;
}

}  // namespace

int RotationFormWidth(const RotationForm& f) {
  if (!(f.tolerance > 0) || !(f.tolerance < 0.5))
    throw std::invalid_argument("rotation.tolerance: expected a number in (0, 0.5), got " +
                                std::to_string(f.tolerance));
  if (f.form == "quaternion") {
    const std::string o = Lower(f.order);
    if (o != "wxyz" && o != "xyzw")
      throw std::invalid_argument("rotation.order: '" + f.order +
                                  "' is not a quaternion order (wxyz: scalar first, xyzw: scalar last)");
    return 4;
  }
  if (f.form == "matrix") return 9;
  if (f.form == "rotation_vector") {
    UnitFactor(f);
    return 3;
  }
  if (f.form == "euler") {
    UnitFactor(f);
    int axes[3];
    bool ext;
    Sequence(f, axes, &ext);
    return 3;
  }
  throw std::invalid_argument("rotation.form: '" + f.form +
                              "' is not a rotation form (quaternion, matrix, rotation_vector, euler)");
}

RotationVectors ToRotationVectors(const Eigen::MatrixXd& values, const RotationForm& f) {
  const int width = RotationFormWidth(f);
  if (values.cols() != width)
    throw std::invalid_argument("rotation: a " + f.form + " has " + std::to_string(width) + " values per row, got " +
                                std::to_string(values.cols()));
  RotationVectors out;
  out.vectors = Eigen::MatrixXd::Zero(values.rows(), 3);
  out.problems.assign(values.rows(), "");
  for (Eigen::Index i = 0; i < values.rows(); ++i) {
    const Eigen::VectorXd row = values.row(i).transpose();
    if (!row.allFinite()) {
      out.problems[i] = f.form + " " + Fmt(row) + " is not finite";
      continue;
    }
    Eigen::Matrix3d R;
    if (f.form == "quaternion") {
      const bool wfirst = Lower(f.order) == "wxyz";
      const double w = wfirst ? row[0] : row[3];
      const Eigen::Vector3d xyz = wfirst ? Eigen::Vector3d(row.segment<3>(1)) : Eigen::Vector3d(row.head<3>());
      const double n = std::sqrt(w * w + xyz.squaredNorm());
      if (!(std::abs(n - 1.0) <= f.tolerance)) {
        char buf[160];
        std::snprintf(buf, sizeof buf, " has norm %.6g, not 1 (tolerance %g): not a rotation", n, f.tolerance);
        out.problems[i] = "quaternion (" + Lower(f.order) + ") " + Fmt(row) + buf;
        continue;
      }
      // AngleAxis of a unit quaternion: angle in [0, pi], q and -q alike.
      const Eigen::AngleAxisd aa(Eigen::Quaterniond(w / n, xyz[0] / n, xyz[1] / n, xyz[2] / n));
      out.vectors.row(i) = (aa.angle() * aa.axis()).transpose();
      continue;
    }
    if (f.form == "rotation_vector") {
      out.vectors.row(i) = row.transpose() * UnitFactor(f);
      continue;
    }
    if (f.form == "matrix") {
      for (int r = 0; r < 3; ++r)
        for (int c = 0; c < 3; ++c) R(r, c) = row[3 * r + c];
      const double off = (R.transpose() * R - Eigen::Matrix3d::Identity()).cwiseAbs().maxCoeff();
      const double det = R.determinant();
      if (!(off <= f.tolerance) || !(det > 0)) {
        char buf[200];
        std::snprintf(buf, sizeof buf,
                      " is not a rotation: R^T R differs from I by %.3g (tolerance %g), det %.6g%s", off,
                      f.tolerance, det, det < 0 ? " (a reflection)" : "");
        out.problems[i] = "matrix (r11 ... r33, row by row) " + Fmt(row) + buf;
        continue;
      }
      // The nearest rotation (polar factor): a written matrix keeps few digits.
      Eigen::JacobiSVD<Eigen::Matrix3d> svd(R, Eigen::ComputeFullU | Eigen::ComputeFullV);
      R = svd.matrixU() * svd.matrixV().transpose();
    } else {  // euler
      int axes[3];
      bool ext;
      Sequence(f, axes, &ext);
      const double k = UnitFactor(f);
      R.setIdentity();
      for (int j = 0; j < 3; ++j)
        R = R * Eigen::AngleAxisd(row[ext ? 2 - j : j] * k, Eigen::Vector3d::Unit(axes[j])).toRotationMatrix();
    }
    const Eigen::AngleAxisd aa(R);
    out.vectors.row(i) = (aa.angle() * aa.axis()).transpose();
  }
  return out;
}

Eigen::MatrixXd FromRotationVectors(const Eigen::MatrixXd& vectors, const RotationForm& f) {
  const int width = RotationFormWidth(f);
  if (vectors.cols() != 3)
    throw std::invalid_argument("rotation vectors: expected 3 values per row, got " + std::to_string(vectors.cols()));
  Eigen::MatrixXd out(vectors.rows(), width);
  for (Eigen::Index i = 0; i < vectors.rows(); ++i) {
    const Eigen::Vector3d v = vectors.row(i).transpose();
    if (!v.allFinite())
      throw std::invalid_argument("rotation vectors[" + std::to_string(i) + "]: not finite");
    const double angle = v.norm();
    const Eigen::AngleAxisd aa(angle, angle > 0 ? Eigen::Vector3d(v / angle) : Eigen::Vector3d::UnitZ());
    if (f.form == "rotation_vector") {
      out.row(i) = v.transpose() / UnitFactor(f);
    } else if (f.form == "quaternion") {
      Eigen::Quaterniond q(aa);
      if (q.w() < 0) q.coeffs() = -q.coeffs();
      out.row(i) = Lower(f.order) == "wxyz" ? Eigen::RowVector4d(q.w(), q.x(), q.y(), q.z())
                                            : Eigen::RowVector4d(q.x(), q.y(), q.z(), q.w());
    } else if (f.form == "matrix") {
      const Eigen::Matrix3d R = aa.toRotationMatrix();
      for (int r = 0; r < 3; ++r)
        for (int c = 0; c < 3; ++c) out(i, 3 * r + c) = R(r, c);
    } else {
      int axes[3];
      bool ext;
      Sequence(f, axes, &ext);
      const Eigen::Vector3d a = aa.toRotationMatrix().eulerAngles(axes[0], axes[1], axes[2]) / UnitFactor(f);
      out.row(i) = ext ? Eigen::RowVector3d(a[2], a[1], a[0]) : Eigen::RowVector3d(a[0], a[1], a[2]);
    }
  }
  return out;
}

}  // namespace fivecal
