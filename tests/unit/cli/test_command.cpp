// The typo helper behind "did you mean ...?": optimal string alignment distance and the nearest-name rule.
#include <gtest/gtest.h>

#include "command.hpp"

namespace bsn::services {
namespace {

TEST(EditDistance, CountsEachKindOfEditOnce) {
  EXPECT_EQ(edit_distance("fusion", "fusion"), 0u);
  EXPECT_EQ(edit_distance("fuson", "fusion"), 1u);    // insertion
  EXPECT_EQ(edit_distance("fussion", "fusion"), 1u);  // deletion
  EXPECT_EQ(edit_distance("fasion", "fusion"), 1u);   // substitution
  EXPECT_EQ(edit_distance("ehco", "echo"), 1u);       // neighbours swapped
  EXPECT_EQ(edit_distance("", "sim"), 3u);
  EXPECT_EQ(edit_distance("kitten", "sitting"), 3u);  // the textbook pair
  EXPECT_EQ(edit_distance("ca", "abc"), 3u);          // optimal string alignment: a swapped pair is not edited again
}

TEST(NearestName, SuggestsOnlyWhatLooksLikeATypo) {
  const std::vector<std::string> commands{"sim", "fusion", "echo", "demo", "eval", "calibrate"};
  EXPECT_EQ(nearest_name("fuson", commands), "fusion");
  EXPECT_EQ(nearest_name("calbirate", commands), "calibrate");
  EXPECT_EQ(nearest_name("simm", commands), "sim");
  EXPECT_EQ(nearest_name("xyzzy", commands), "");
  EXPECT_EQ(nearest_name("x", commands), "");  // one letter is no evidence of anything

  const std::vector<std::string> options{"--help", "--best-effort", "--body", "--domain", "-h"};
  EXPECT_EQ(nearest_name("--best-efort", options), "--best-effort");
  EXPECT_EQ(nearest_name("--bdy", options), "--body");
  EXPECT_EQ(nearest_name("--x", options), "");  // dashes are not letters in common
}

}  // namespace
}  // namespace bsn::services
