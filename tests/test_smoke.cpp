#include <gtest/gtest.h>

#include <string>

#include "slimrt/analysis.h"
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

// The format's own build figures are a measurement hook of slimrt/analysis.h beside the typed
// SceneStats: none for an empty scene, in the builder's order for a built one, found by name.
TEST(Smoke, BuildFiguresComeFromTheAnalysisHeader) {
  const slim::Scene empty;
  EXPECT_TRUE(slim::stat_details(empty).empty());
  EXPECT_FALSE(slim::stat_detail(empty, "leaf_count").has_value());

  const slim::Scene scene =
      slim::Scene::build(slim::load("terrain:16"), slim::BuildOptions::from_config("bvh8-tri4v"));
  EXPECT_EQ(scene.stats().triangles, 2u * 16 * 16);
  const slim::StatDetails& d = slim::stat_details(scene);
  ASSERT_FALSE(d.empty());
  for (const auto& [name, value] : d) EXPECT_EQ(slim::stat_detail(scene, name), value) << name;
  EXPECT_GT(slim::stat_detail(scene, "leaf_count").value_or(0), 0);
  EXPECT_FALSE(slim::stat_detail(scene, "no_such_figure").has_value());
}
