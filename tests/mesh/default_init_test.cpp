// UninitialisedVector: only value-less construction differs from std::vector's.
#include "mesh/default_init.h"

#include <gtest/gtest.h>

#include <string>

namespace morphmap {
namespace {

TEST(DefaultInit, ConstructionWithAValueIsUnchanged) {
  UninitialisedVector<int> v(5, 7);
  v.resize(8, -2);
  v.push_back(11);
  v.emplace_back(12);
  const std::vector<int> expected = {7, 7, 7, 7, 7, -2, -2, -2, 11, 12};
  EXPECT_EQ(std::vector<int>(v.begin(), v.end()), expected);

  // A class type still runs its default constructor: only trivial types are left unset.
  UninitialisedVector<std::string> s;
  s.resize(3);
  s.emplace_back("x");
  EXPECT_EQ(s[0], "");
  EXPECT_EQ(s[3], "x");
}

TEST(DefaultInit, ResizeKeepsTheElementsAlreadyThere) {
  UninitialisedVector<int> v;
  for (int i = 0; i < 1000; ++i) v.push_back(i);
  v.resize(100000);
  for (int i = 0; i < 1000; ++i) ASSERT_EQ(v[std::size_t(i)], i);
  v.resize(10);
  EXPECT_EQ(v.back(), 9);
}

}  // namespace
}  // namespace morphmap
