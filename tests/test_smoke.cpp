#include <gtest/gtest.h>

#include "slimrt/math.h"

TEST(Smoke, BoxExtends) {
  slim::Box3f b;
  EXPECT_TRUE(b.empty());
  b.extend(slim::Vec3f(1, 2, 3));
  EXPECT_FALSE(b.empty());
}
