// A machine as a neutral kinematics table (docs/controllers.md): per axis
// its chain (workpiece: carries the part, tool: carries the spindle; each
// listed from the foundation outward), unit direction and, for a rotary
// axis, the point of its line nearest the nominal pivot, all in the machine
// frame at the zero pose, with the location errors and tip offsets of theta
// (error motions are not in a table); the tool tip and tool axis at the zero
// pose; where the part frame sits at the zero pose (part_origin,
// part_rotation: moved by the table axes' location errors).
//
// TableToolPoints is the kinematics such a table describes, written apart
// from fivecal's chain code (kinematics.h) so that a table's values can be
// checked against the tool points they must reproduce: each axis a screw
// about its line, tool = S_tool(q) tip, part = S_workpiece(q), the point in
// the part frame. Sign convention: a positive linear command moves its
// carriage by +direction, a positive rotary command turns its carriage
// right-handed about +direction.
#ifndef FIVECAL_CONTROLLERS_KINEMATICS_TABLE_H_
#define FIVECAL_CONTROLLERS_KINEMATICS_TABLE_H_

#include <Eigen/Core>
#include <string>
#include <vector>

#include "fivecal/model/machine.h"

namespace fivecal {
namespace controllers {

struct TableAxis {
  char axis = 'X';
  bool tool_chain = false;  // false: the workpiece chain
  bool rotary = false;
  Eigen::Vector3d direction = Eigen::Vector3d::UnitX();
  Eigen::Vector3d point = Eigen::Vector3d::Zero();  // rotary axes: on the line, nearest the nominal pivot
};

struct KinematicsTable {
  std::vector<TableAxis> axes;  // the workpiece chain, then the tool chain (the spindle left out)
  Eigen::Vector3d tool_tip = Eigen::Vector3d::Zero();
  Eigen::Vector3d tool_axis = Eigen::Vector3d::UnitZ();
  Eigen::Vector3d part_origin = Eigen::Vector3d::Zero();
  Eigen::Matrix3d part_rotation = Eigen::Matrix3d::Identity();
};

// theta: the machine's full parameter vector (location errors and tip offsets are used).
KinematicsTable MakeKinematicsTable(const Machine& m, const Eigen::VectorXd& theta);

// Tool points (N x 3, mm, part frame) for commands q (N x table.axes.size(),
// one column per table row, mm / degrees).
Eigen::MatrixXd TableToolPoints(const KinematicsTable& table, const Eigen::MatrixXd& q);

}  // namespace controllers
}  // namespace fivecal

#endif  // FIVECAL_CONTROLLERS_KINEMATICS_TABLE_H_
