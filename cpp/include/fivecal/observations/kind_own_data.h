// The payload of a kind registered from outside the core (a plug-in, the
// test-only stylus3d of tests/cpp/kind_plugin): its numbers by names of the
// kind's choosing (its file keys, say), read, validated and written by the
// kind. A built-in kind has a struct of its own instead (payloads.h).
#ifndef FIVECAL_OBSERVATIONS_KIND_OWN_DATA_H_
#define FIVECAL_OBSERVATIONS_KIND_OWN_DATA_H_

#include <Eigen/Core>
#include <map>
#include <string>

namespace fivecal {

struct KindOwnData {
  static constexpr const char* kName = "KindOwnData";
  std::map<std::string, Eigen::VectorXd> values;
};
inline bool operator==(const KindOwnData& a, const KindOwnData& b) {
  if (a.values.size() != b.values.size()) return false;
  for (auto i = a.values.begin(), j = b.values.begin(); i != a.values.end(); ++i, ++j)
    if (i->first != j->first || i->second.size() != j->second.size() || i->second != j->second) return false;
  return true;
}

}  // namespace fivecal

#endif  // FIVECAL_OBSERVATIONS_KIND_OWN_DATA_H_
