// Concurrency: queries from 8 threads on one scene give bit-identical answers
// to one thread, for every configuration; two scenes built at the same time (from two threads,
// each build itself parallel with TBB) equal scenes built one after the other. Scene::intersect
// and occluded are const and documented thread-safe. Run under ThreadSanitizer too:
//   cmake --preset tsan && cmake --build --preset tsan
//   build-tsan/slimrt_tests --gtest_filter='RobustConcurrency*'
#include <gtest/gtest.h>
#include <tbb/global_control.h>

#include <cstring>
#include <string>
#include <thread>
#include <vector>

#include "test_util.h"

using namespace slim;
using namespace slim::test;

namespace {

#if defined(__SANITIZE_THREAD__)
constexpr int kRays = 1000;  // TSan runs about 10x slower
// Debian's libtbb is not built with TSan: the synchronisation inside it is invisible, and the
// task bookkeeping of TBB's inlined templates then shows up as races. Under TSan, TBB runs every
// task on the thread that calls it, so the threads that do race-check are our own std::threads
// (the queries and the two concurrent builds below).
const tbb::global_control kSerialTbb(tbb::global_control::max_allowed_parallelism, 1);
#else
constexpr int kRays = 10000;
#endif
constexpr int kThreads = 8;

// A closed torus and a random soup together: both traversal directions, many leaf kinds.
std::vector<PolyMesh> test_meshes() {
  std::vector<PolyMesh> m;
  m.push_back(make_torus(48));
  m.push_back(random_soup(3000, 21, 0.2f));
  for (Vec3f& p : m[1].positions) p = p * 3.0f - Vec3f(1.5f);
  return m;
}

std::vector<Ray> test_rays(const Box3f& box) {
  Rng rng(99);
  std::vector<Ray> rays;
  for (int i = 0; i < kRays; ++i) rays.push_back(random_ray(rng, box));
  return rays;
}

bool same_hit(const Hit& a, const Hit& b) {
  return std::memcmp(&a.t, &b.t, 4) == 0 && std::memcmp(&a.u, &b.u, 4) == 0 &&
         std::memcmp(&a.v, &b.v, 4) == 0 && a.Ng == b.Ng && a.geomID == b.geomID &&
         a.primID == b.primID && a.kind == b.kind;
}

struct Answers {
  std::vector<Hit> hits;
  std::vector<char> occluded;
};

Answers one_thread(const Scene& s, const std::vector<Ray>& rays) {
  Answers a;
  for (const Ray& r : rays) {
    a.hits.push_back(s.intersect(r));
    a.occluded.push_back(s.occluded(r));
  }
  return a;
}

}  // namespace

TEST(RobustConcurrency, EightThreadsQueryOneSceneLikeOneThread) {
  const std::vector<PolyMesh> meshes = test_meshes();
  for (const std::string& c : all_config_names()) {
    SCOPED_TRACE(c);
    Scene s;
    try {
      s = Scene::build(meshes, BuildOptions::from_config(c));
    } catch (const NotApplicable&) {
      continue;
    } catch (const Error& e) {
      ADD_FAILURE() << e.what();
      continue;
    }
    const std::vector<Ray> rays = test_rays(s.bounds());
    const Answers ref = one_thread(s, rays);
    // Each thread traces every ray, starting at a different offset, so that the same nodes and
    // leaves are read by several threads at the same moment.
    std::vector<uint64_t> mismatches(kThreads, 0);
    std::vector<std::thread> pool;
    for (int k = 0; k < kThreads; ++k)
      pool.emplace_back([&, k] {
        for (size_t j = 0; j < rays.size(); ++j) {
          const size_t i = (j + k * rays.size() / kThreads) % rays.size();
          const Hit h = s.intersect(rays[i]);
          const bool o = s.occluded(rays[i]);
          mismatches[k] += !same_hit(h, ref.hits[i]) || o != bool(ref.occluded[i]);
        }
      });
    for (std::thread& t : pool) t.join();
    for (int k = 0; k < kThreads; ++k) EXPECT_EQ(mismatches[k], 0u) << "thread " << k;
  }
}

// Two builds at the same time, from two threads (each build parallel inside with TBB): the same
// configuration twice, and two different ones; every scene answers like one built alone.
TEST(RobustConcurrency, TwoScenesBuiltAtOnce) {
  const std::vector<PolyMesh> meshes = test_meshes();
  const std::vector<std::string> names = all_config_names();
  // Pairs (i, i) and (i, i + 1) over a spread of configurations.
  std::vector<std::pair<std::string, std::string>> pairs;
  for (size_t i = 0; i < names.size(); i += 3) {
    pairs.push_back({names[i], names[i]});
    pairs.push_back({names[i], names[(i + 1) % names.size()]});
  }
  for (const auto& [a, b] : pairs) {
    SCOPED_TRACE(a + " and " + b);
    Scene sa, sb;
    std::string ea, eb;  // build errors; "n/a" for a configuration that does not apply
    auto build = [&](const std::string& name, Scene& out, std::string& err) {
      try {
        out = Scene::build(meshes, BuildOptions::from_config(name));
      } catch (const NotApplicable&) {
        err = "n/a";
      } catch (const Error& e) {
        err = e.what();
      }
    };
    std::thread ta([&, name = a] { build(name, sa, ea); });
    std::thread tb([&, name = b] { build(name, sb, eb); });
    ta.join();
    tb.join();
    for (auto [name, scene, err] : {std::tuple{a, &sa, ea}, std::tuple{b, &sb, eb}}) {
      if (!err.empty()) {
        EXPECT_EQ(err, "n/a") << name;
        continue;
      }
      std::string why;
      EXPECT_TRUE(scene->validate(&why)) << name << ": " << why;
      const Scene alone = Scene::build(meshes, BuildOptions::from_config(name));
      EXPECT_EQ(scene->memory().total(), alone.memory().total()) << name;
      const std::vector<Ray> rays = test_rays(alone.bounds());
      uint64_t mismatches = 0;
      for (const Ray& r : rays) mismatches += !same_hit(scene->intersect(r), alone.intersect(r));
      EXPECT_EQ(mismatches, 0u) << name;
    }
  }
}
