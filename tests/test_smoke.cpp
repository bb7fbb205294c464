#include <gtest/gtest.h>

#include <string>

#include "slimrt/math.h"
#include "slimrt/scene.h"

TEST(Smoke, BoxExtends) {
  slim::Box3f b;
  EXPECT_TRUE(b.empty());
  b.extend(slim::Vec3f(1, 2, 3));
  EXPECT_FALSE(b.empty());
}

// The suite runs on the machine that built it, so the CPU has the compiled set: the check passes
// (it would throw naming the missing extensions), and simd_isa() names the path CMake chose.
TEST(Smoke, CpuHasTheCompiledInstructionSet) {
  EXPECT_NO_THROW(slim::check_cpu_isa());
  const std::string isa = slim::simd_isa();
  EXPECT_TRUE(isa == "avx2" || isa == "avx512" || isa == "scalar") << isa;
#if defined(SLIM_ISA_AVX512)
  EXPECT_EQ(isa, "avx512");
#elif defined(SLIM_ISA_AVX2)
  EXPECT_EQ(isa, "avx2");
#else
  EXPECT_EQ(isa, "scalar");
#endif
}
