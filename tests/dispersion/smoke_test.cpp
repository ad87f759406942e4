#include <gtest/gtest.h>
#include "support/testing.hpp"
TEST(Smoke, Version) {
  auto r = specbake::testing::run_cli({"--version"});
  EXPECT_EQ(r.exit_code, 0);
  EXPECT_NE(r.out.find("specbake"), std::string::npos);
}
