// Orientations as instruments write them, to and from fivecal's one form.
//
// fivecal keeps every measured or nominal orientation of an observation as a
// rotation vector (axis times angle, rad, angle in [0, pi]); cameras, motion
// capture and trackers write quaternions (w x y z or x y z w), rotation
// matrices (r11 ... r33, row by row), rotation vectors (rad or deg) or Euler
// angles in a named sequence. The importers convert here, once.
//
// Euler sequences: three axis letters, no two neighbours equal ("ZYX",
// "XYZ", "ZXZ"). Upper case = intrinsic (each turn about the axis as already
// turned): "ZYX" with angles (a1, a2, a3) is R = Rz(a1) Ry(a2) Rx(a3).
// Lower case = extrinsic (about the fixed axes, in the order given): "xyz"
// with (a1, a2, a3) is R = Rz(a3) Ry(a2) Rx(a1). fivecal's own
// instrument_angles a b c are "ZYX" with angles (c, b, a).
#ifndef FIVECAL_ROTATION_FORMS_H_
#define FIVECAL_ROTATION_FORMS_H_

#include <string>
#include <vector>

#include <Eigen/Core>

namespace fivecal {

struct RotationForm {
  std::string form = "rotation_vector";  // quaternion | matrix | rotation_vector | euler
  std::string order = "wxyz";            // quaternion: wxyz or xyzw
  std::string sequence;                  // euler: e.g. ZYX (intrinsic) or zyx (extrinsic)
  std::string unit = "rad";              // rotation_vector, euler: rad or deg
  // A quaternion whose norm differs from 1, or a matrix whose R^T R differs
  // from I (largest entry), by more than this is not a rotation: refused.
  // Within it, the value is normalised (a written file keeps ~6 digits).
  double tolerance = 1e-3;
};

// Number of values per row of a form (4, 9, 3, 3). Throws std::invalid_argument
// naming the bad field of `f` (form, order, sequence, unit, tolerance).
int RotationFormWidth(const RotationForm& f);

struct RotationVectors {
  Eigen::MatrixXd vectors;            // N x 3, rad
  std::vector<std::string> problems;  // per row: "" or why the row is not a rotation
};

// values: N x RotationFormWidth(f). A row that is not a rotation (a
// non-unit quaternion, a matrix that is not orthonormal or is a reflection, a
// non-finite value) gets a zero vector and its reason in `problems`, so that
// the caller can name its file and line.
RotationVectors ToRotationVectors(const Eigen::MatrixXd& values, const RotationForm& f);

// The inverse: N x 3 rotation vectors (rad) to N x width values of form `f`
// (a quaternion with w >= 0; Euler angles in Eigen's ranges).
Eigen::MatrixXd FromRotationVectors(const Eigen::MatrixXd& vectors, const RotationForm& f);

}  // namespace fivecal

#endif  // FIVECAL_ROTATION_FORMS_H_
