// Build progress and cancellation (BuildOptions::progress, slimrt/scene.h): every phase reports a
// done that only grows and ends at its total, the calls never overlap, a false return cancels
// with slim::Cancelled, and a scene built with a callback equals one built without.
#include <gtest/gtest.h>

#include <atomic>
#include <map>
#include <mutex>
#include <string>
#include <vector>

#include "slimrt/scene.h"
#include "test_util.h"

namespace {

using slim::BuildOptions;
using slim::BuildProgress;
using slim::PolyMesh;
using slim::Scene;

// Every call of the callback, in order, and whether two ever overlapped.
struct Recorder {
  std::vector<BuildProgress> calls;
  std::atomic<int> inside{0};
  bool overlapped = false;
  std::mutex mutex;  // only to publish `calls` to the test thread (the calls are serialized)

  slim::BuildProgressFn fn() {
    return [this](const BuildProgress& p) {
      if (inside.fetch_add(1) != 0) overlapped = true;
      {
        std::lock_guard<std::mutex> lock(mutex);
        calls.push_back(p);
      }
      inside.fetch_sub(1);
      return true;
    };
  }
};

// The phases in the order they ran (a phase starts when its name changes).
std::vector<std::string> phases_of(const std::vector<BuildProgress>& calls) {
  std::vector<std::string> out;
  for (const BuildProgress& p : calls)
    if (out.empty() || out.back() != p.phase) out.push_back(p.phase);
  return out;
}

// Within each run of a phase: done never decreases, never exceeds total, total stays the same,
// the last report has done == total, and no more than ~100 reports (+ start and end) are made.
void expect_monotone(const std::vector<BuildProgress>& calls, const std::string& what) {
  ASSERT_FALSE(calls.empty()) << what;
  size_t begin = 0;
  for (size_t i = 1; i <= calls.size(); ++i) {
    if (i < calls.size() && calls[i].phase == calls[begin].phase) continue;
    const std::string phase = calls[begin].phase;
    for (size_t k = begin; k < i; ++k) {
      EXPECT_EQ(calls[k].total, calls[begin].total) << what << " " << phase;
      EXPECT_LE(calls[k].done, calls[k].total) << what << " " << phase;
      if (k > begin) {
        EXPECT_GE(calls[k].done, calls[k - 1].done) << what << " " << phase;
      }
    }
    EXPECT_EQ(calls[i - 1].done, calls[i - 1].total) << what << " " << phase << " ends below 100%";
    EXPECT_LE(i - begin, 103u) << what << " " << phase << ": too many reports";
    begin = i;
  }
}

PolyMesh terrain() { return slim::make_terrain(96); }  // 18432 triangles

TEST(BuildProgress, EveryPhaseIsMonotoneAndEndsAtTotal) {
  const PolyMesh mesh = terrain();
  for (const char* config : {"bvh8-tri4v", "qbvh8-tri4i", "clbvh-compact", "bvh8-pairs",
                             "lossy-grid", "lossy-grid-shared", "cluster-lossless", "costa-PFV"}) {
    for (int threads : {1, 0}) {
      SCOPED_TRACE(std::string(config) + " threads " + std::to_string(threads));
      Recorder rec;
      BuildOptions opt = BuildOptions::from_config(config);
      opt.threads = threads;
      opt.progress = rec.fn();
      Scene s = Scene::build(mesh, opt);
      EXPECT_FALSE(rec.overlapped);
      expect_monotone(rec.calls, config);
      EXPECT_EQ(phases_of(rec.calls), (std::vector<std::string>{"prepare", "bvh2", "collapse"}));
      // The BVH phases count the primitives the BVH is built over, twice.
      for (const BuildProgress& p : rec.calls)
        if (p.phase != "prepare") {
          EXPECT_EQ(p.total, 2 * s.stats().primitives) << p.phase;
        }
      // Over many primitives (the triangle formats' 18432, not the grids' few hundred
      // sub-grids) the BVH phases also report in between, not only at their start and end.
      std::map<std::string, int> count;
      for (const BuildProgress& p : rec.calls) count[p.phase]++;
      if (s.stats().primitives >= 16384) {
        EXPECT_GT(count["bvh2"], 10);
        EXPECT_GE(count["collapse"], 3);  // start, measured, written
      }
      // The scene keeps no reference to the callback.
      EXPECT_FALSE(s.options().progress);
    }
  }
}

TEST(BuildProgress, GridLeftoversHaveTheirOwnPhases) {
  const std::vector<PolyMesh> meshes = {terrain(), slim::test::random_soup(500, 7)};
  Recorder rec;
  BuildOptions opt = BuildOptions::from_config("lossy-grid");
  opt.grid_leftovers = slim::GridLeftovers::Triangles;
  opt.progress = rec.fn();
  Scene s = Scene::build(meshes, opt);
  expect_monotone(rec.calls, "lossy-grid + soup");
  EXPECT_EQ(phases_of(rec.calls),
            (std::vector<std::string>{"prepare", "bvh2", "collapse", "bvh2 leftovers",
                                      "collapse leftovers"}));
  EXPECT_EQ(rec.calls.back().total, 2 * 500u);
}

// The callback changes nothing in the result.
TEST(BuildProgress, SameSceneWithAndWithoutCallback) {
  const PolyMesh mesh = terrain();
  for (const char* config : {"bvh8-tri4v", "clbvh-compact", "costa-PFV"}) {
    BuildOptions opt = BuildOptions::from_config(config);
    opt.threads = 1;
    Scene a = Scene::build(mesh, opt);
    int calls = 0;
    opt.progress = [&](const BuildProgress&) { return ++calls > 0; };
    Scene b = Scene::build(mesh, opt);
    EXPECT_GT(calls, 0);
    EXPECT_EQ(a.memory().total(), b.memory().total()) << config;
    const slim::StatDetails &da = stat_details(a), &db = stat_details(b);
    ASSERT_EQ(da.size(), db.size());
    for (size_t i = 0; i < da.size(); ++i) {
      const std::string& key = da[i].first;
      if (key.size() > 2 && key.compare(key.size() - 2, 2, "_s") == 0) continue;  // times
      EXPECT_EQ(da[i].second, db[i].second) << config << " " << key;
    }
    std::string why;
    EXPECT_TRUE(b.validate(&why)) << why;
  }
}

// Cancelling in each phase, at its start and in its middle, on one thread and on all: the build
// throws slim::Cancelled naming the phase, and no call follows the one that returned false.
// (Leaks would show in the ASan suite.)
TEST(BuildProgress, CancelInEveryPhase) {
  const PolyMesh mesh = terrain();
  for (const char* config : {"bvh8-tri4v", "clbvh-compact", "lossy-grid", "costa-PFV"}) {
    for (const char* phase : {"prepare", "bvh2", "collapse"}) {
      for (bool middle : {false, true}) {
        for (int threads : {1, 0}) {
          SCOPED_TRACE(std::string(config) + " " + phase + (middle ? " middle" : " start") +
                       " threads " + std::to_string(threads));
          BuildOptions opt = BuildOptions::from_config(config);
          opt.threads = threads;
          std::atomic<int> after{0};
          std::atomic<bool> said_no{false};
          opt.progress = [&](const BuildProgress& p) {
            if (said_no) {
              after++;
              return true;
            }
            const bool here =
                p.phase == phase && (middle ? p.done > 0 && p.done < p.total : p.done == 0);
            if (here) said_no = true;
            return !here;
          };
          // Every phase reports its start; "prepare" has no middle report, nor has a collapse
          // over fewer primitives than one parallel subtree (lossy-grid's sub-grids here).
          const bool must_cancel =
              !middle || (std::string(config) == "bvh8-tri4v" && std::string(phase) != "prepare");
          try {
            Scene s = Scene::build(mesh, opt);
            EXPECT_FALSE(said_no) << "the callback said false, yet the build went through";
            EXPECT_FALSE(must_cancel) << "the phase made no report to cancel in";
          } catch (const slim::Cancelled& e) {
            EXPECT_TRUE(said_no);
            EXPECT_NE(std::string(e.what()).find(std::string("'") + phase + "'"), std::string::npos)
                << e.what();
          }
          EXPECT_EQ(after.load(), 0);
        }
      }
    }
  }
}

// A callback that throws: its exception leaves Scene::build as it is.
TEST(BuildProgress, CallbackExceptionPropagates) {
  const PolyMesh mesh = terrain();
  BuildOptions opt = BuildOptions::from_config("bvh8-tri4v");
  opt.progress = [](const BuildProgress& p) -> bool {
    if (p.phase == "bvh2" && p.done > 0) throw std::runtime_error("stop here");
    return true;
  };
  EXPECT_THROW(Scene::build(mesh, opt), std::runtime_error);
}

}  // namespace
