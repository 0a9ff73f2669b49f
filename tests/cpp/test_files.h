// Reading the test data files (tests/data, examples) shared by the gtests.
#ifndef FIVECAL_TESTS_TEST_FILES_H_
#define FIVECAL_TESTS_TEST_FILES_H_

#include <gtest/gtest.h>

#include <fstream>
#include <sstream>
#include <string>

namespace fivecal {

// The whole file; a missing file fails the test that reads it (and returns "").
inline std::string ReadFile(const std::string& path) {
  std::ifstream f(path);
  EXPECT_TRUE(f.good()) << path;
  std::stringstream ss;
  ss << f.rdbuf();
  return ss.str();
}

}  // namespace fivecal

#endif  // FIVECAL_TESTS_TEST_FILES_H_
