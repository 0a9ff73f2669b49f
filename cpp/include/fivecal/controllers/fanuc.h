// FANUC Series 30i/31i/32i: the parameters of tool centre point control for
// 5-axis machining (docs/controllers.md, "FANUC"), and the transformation
// those parameters describe, written from FANUC's public manual apart from
// fivecal's chain code.
//
// Source (the only public one found with the parameter descriptions):
// "FANUC Series 30i-MODEL A, Tool center point control for 5-axis machining,
// Additional manual", A-79348E, Jan. 2004 (cncmanuals.com copy, sheets
// n/88); the MODEL B parameter manual B-64490EN was not found in public
// copies, and the numbers below are those of the MODEL A manual.
//
// Mechanism types (No. 19680, sheet 72/88): 2 tool rotation type (both rotary
// axes turn the tool), 12 table rotation type (both turn the table), 21 mixed
// (first rotation axis the tool's, second the table's). The first rotation
// axis is the master, the second the slave: the offset chains the manual
// gives run from the machine through the first axis to the second (table:
// rotary table position to point A on the first axis, 19703-19705 from A to
// B on the second, sheets 59, 82; tool: 19709-19711 from point D on the tool
// axis to E on the second axis, 19712-19714 from E to F on the first, sheets
// 83-84), so the first axis carries the second.
#ifndef FIVECAL_CONTROLLERS_FANUC_H_
#define FIVECAL_CONTROLLERS_FANUC_H_

#include "fivecal/controllers/vendor.h"

namespace fivecal {
namespace controllers {

class FanucVendor final : public RegisteredVendor<FanucVendor> {
 public:
  static constexpr const char* kName = "fanuc";
  static constexpr const char* kTitle =
      "FANUC Series 30i/31i/32i: tool centre point control for 5-axis machining parameters";
  std::map<std::string, std::string> OptionHelp() const override;
  VendorModel Model(const Machine& m, const VendorOptions& o) const override;
  std::vector<VendorValue> Values(const Machine& m, const VendorOptions& o) const override;
  Eigen::VectorXd Map(const Machine& m, const KinematicsTable& table, const VendorOptions& o) const override;
  KinematicsTable Table(const Machine& m, const Eigen::VectorXd& values, const VendorOptions& o) const override;
  Eigen::MatrixXd ToolPoints(const Machine& m, const Eigen::VectorXd& values, const Eigen::MatrixXd& q,
                             const VendorOptions& o) const override;
};

}  // namespace controllers
}  // namespace fivecal

#endif  // FIVECAL_CONTROLLERS_FANUC_H_
