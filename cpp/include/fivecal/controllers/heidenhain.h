// Heidenhain TNC (TNC 640 / TNC7 / iTNC 530): the kinematics description
// table (docs/controllers.md, "Heidenhain TNC").
//
// Public source: HEIDENHAIN Technical Manual iTNC 530 HSCI, July 2013 (via
// easymanua.ls), p. 722, the format of the description table: rows NR, KEY,
// AXIS, COORD; KEY MachAxis (where an axis takes effect: from that row on,
// the axis moves what the rows before it define relative to what follows;
// the chain starts at the tool reference point), Trans (a translation along
// or a rotation about the axis in AXIS by COORD), ToolAxis (X, Y, Z: the
// tool axis), MachBase (the stationary part of the machine). p. 670 prints a table of
// this kind for a B head and a C table (Trans X, Trans Z, MachAxis B,
// MachAxis Y, MachAxis X, MachBase, MachAxis Z, Trans X, Trans Y, MachAxis C).
//
// The rows fivecal writes (the machine builder chooses the number and order;
// this is fivecal's standard sequence, from the tool reference point to the
// part):
//
//   ToolAxis Z                               the tool axis (fixed)
//   Trans <k>, Trans <j>                     the spindle's tilt (deg)
//   per tool-side axis, spindle first:
//     rotary: Trans X, Y, Z                  from the previous point (tool reference
//                                            point, or the previous pivot) to its pivot
//             Trans <j>, Trans <k>           turn the frame's own axis onto the axis direction
//             MachAxis <L>
//             Trans <k>, Trans <j>           the same turn undone (frames stay machine-parallel)
//     linear: MachAxis <L>                   (Trans <j> 180 ... -180 around it if reversed)
//   Trans X, Y, Z                            from the last point to the machine datum
//   MachBase
//   per table-side axis, from the base outward: as above
//   Trans X, Y, Z                            from the last pivot back to the machine datum:
//                                            the controller's workpiece frame (vendor.h);
//                                            the part's own frame is the preset
//
// with <L> the axis's own letter (A/X about/along x, B/Y y, C/Z z) and
// <j>, <k> the next two in cyclic order (L = C: A, B; L = A: B, C; L = B: C, A).
//
// Reading of the rows (ToolPoints): each row is a transformation of the
// current coordinate system, its values expressed in that system (the
// MANUALplus 620 technical manual, January 2012, p. 749: a coordinate
// system's position is given in the coordinates of the one before it):
// Trans X v moves the next system by +v along
// the current x (p. 670's Trans Z 250.051 from the tool reference point to a
// B pivot above it), Trans A v turns it by +v about the current x (right hand,
// ISO 841's +A). The manual does not give the sense of a MachAxis row after
// MachBase (a table axis): ISO 841 counts a table's motion reversed (the
// tool's motion relative to the part), a builder may count the carriage's.
// The option table-axis-sign states it; the export refuses without it.
#ifndef FIVECAL_CONTROLLERS_HEIDENHAIN_H_
#define FIVECAL_CONTROLLERS_HEIDENHAIN_H_

#include <string>
#include <vector>

#include "fivecal/controllers/vendor.h"

namespace fivecal {
namespace controllers {

// One row of the generated description table.
struct HeidenhainRow {
  std::string key;         // "ToolAxis", "Trans", "MachAxis", "MachBase"
  char axis = 0;           // X Y Z A B C, 0 for MachBase
  bool coord = true;       // has a COORD value (Trans rows)
  bool fixed = false;      // not changed by an export (codes, 180 deg flips)
  bool tool_side = false;  // before MachBase
  std::string role;        // what the row places, for the source text and the docs
};

class HeidenhainVendor final : public RegisteredVendor<HeidenhainVendor> {
 public:
  static constexpr const char* kName = "heidenhain";
  static constexpr const char* kTitle = "Heidenhain TNC 640 / TNC7 / iTNC 530: kinematics description table";
  std::map<std::string, std::string> OptionHelp() const override;
  VendorModel Model(const Machine& m, const VendorOptions& o) const override;
  std::vector<VendorValue> Values(const Machine& m, const VendorOptions& o) const override;
  Eigen::VectorXd Map(const Machine& m, const KinematicsTable& table,
                      const VendorOptions& o) const override;
  KinematicsTable Table(const Machine& m, const Eigen::VectorXd& values,
                        const VendorOptions& o) const override;
  Eigen::MatrixXd ToolPoints(const Machine& m, const Eigen::VectorXd& values, const Eigen::MatrixXd& q,
                             const VendorOptions& o) const override;

  // The rows for `m`, in table order (Values names them "row <NR> <KEY> <AXIS>").
  std::vector<HeidenhainRow> Rows(const Machine& m, const VendorOptions& o) const;
};

// The manual's kinematic transformation for any rows (what ToolPoints
// applies to the rows it writes): the rows in order from the tool reference
// point, the tool tip at tool_length along -ToolAxis; coord per row (Trans
// rows: mm or deg; others ignored); q by axis letter (mm, deg); table_sense
// +1 (iso) or -1 (carriage) for MachAxis rows after MachBase. The tool point
// in the frame after the last row (mm).
Eigen::Vector3d HeidenhainToolPoint(const std::vector<HeidenhainRow>& rows, const Eigen::VectorXd& coord,
                                    const std::map<char, double>& q, double tool_length, char tool_axis,
                                    int table_sense);

}  // namespace controllers
}  // namespace fivecal

#endif  // FIVECAL_CONTROLLERS_HEIDENHAIN_H_
