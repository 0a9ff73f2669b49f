// Loads a machine definition and identified error values, computes where the
// erroneous machine puts the tool for a nominal command, and the compensated
// command that puts it where the nominal one was meant to be; lists the
// observation kinds the core fits (the headers that need nlohmann_json).
//
//   compensate MACHINE.json ERRORS.json
// ERRORS.json: {"EX0C": 0.01, ...} or a fivecal result file (mm, rad).
#include <fivecal/model/inverse.h>
#include <fivecal/model/kinematics.h>
#include <fivecal/observations/registry.h>

#include <fstream>
#include <iostream>
#include <sstream>

int main(int argc, char** argv) {
  if (argc != 3) {
    std::cerr << "usage: compensate MACHINE.json ERRORS.json\n";
    return 2;
  }
  try {
    const fivecal::Machine m = fivecal::Machine::Load(argv[1]);
    std::ifstream in(argv[2]);
    std::stringstream text;
    text << in.rdbuf();
    fivecal::ErrorModel errors = fivecal::ErrorModel::FromJson(m, text.str());
    // A result file also carries the probe stylus offsets tip.x|y|z: they describe the
    // measuring probe, not the cutting tool, so compensation does not apply them.
    for (const char* n : {"tip.x", "tip.y", "tip.z"})
      if (m.ParameterIndex(n) >= 0) errors.Set(n, 0.0);
    const Eigen::VectorXd nominal = Eigen::VectorXd::Zero(m.num_parameters());

    // A nominal command: every linear axis at 50 mm, every rotary axis at 30 deg.
    Eigen::MatrixXd cmd(1, m.num_axes());
    for (int k = 0; k < m.num_axes(); ++k) cmd(0, k) = m.axis(k).rotary() ? 30.0 : 50.0;
    Eigen::MatrixXd target, target_axis, real;
    fivecal::ToolPoses(m, nominal, cmd, nullptr, &target, &target_axis);
    real = fivecal::ToolPoints(m, errors.values(), cmd);
    const Eigen::MatrixXd comp = fivecal::InverseKinematics(m, errors.values(), target, &target_axis,
                                                            cmd.row(0).transpose());
    const Eigen::MatrixXd after = fivecal::ToolPoints(m, errors.values(), comp);

    std::cout << "machine " << m.name() << " (" << m.topology() << "), axes " << m.axis_names() << "\n"
              << "observation kinds    " << fivecal::KindList() << "\n"
              << "nominal command      " << cmd << "\n"
              << "tool error (mm)      " << (real - target) << "\n"
              << "compensated command  " << comp << "\n"
              << "remaining error (mm) " << (after - target) << "\n";
    return (after - target).norm() < 1e-6 ? 0 : 1;
  } catch (const std::invalid_argument& e) {
    std::cerr << "compensate: " << e.what() << "\n";
    return 2;
  }
}
