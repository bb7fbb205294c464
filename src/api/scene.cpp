// slim::Scene: build dispatch and the thread-safe queries.
#include "slimrt/scene.h"

#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <string>
#include <string_view>

#include "api/registry.h"
#include "api/scene_impl.h"
#include "core/large_array.h"
#include "core/progress.h"
#include "mesh/triangulate.h"
#include "slimrt/analysis.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_reduce.h>
#include <tbb/task_arena.h>

namespace slim {

Scene::Scene() = default;
Scene::~Scene() = default;
Scene::Scene(Scene&&) noexcept = default;
Scene& Scene::operator=(Scene&&) noexcept = default;

namespace {

std::string fmt_g(double x) {
  char b[32];
  std::snprintf(b, sizeof b, "%g", x);
  return b;
}

// The range of slimrt/scene.h (kMaxCoordinate, kMinExtent), over the vertices of finite faces
// (faces with a NaN/Inf vertex are skipped by every builder, unused vertices are ignored).
void check_coordinate_range(const MeshList& meshes) {
  Box3f box;
  for (size_t mi = 0; mi < meshes.size(); ++mi) {
    const MeshView& m = *meshes[mi];
    const size_t nv = m.positions.size();
    // One byte per vertex (kFinite, kBeyond) so that the faces gather bytes, not positions
    // (fg_terrain_hawaii: 1 MB instead of 12 MB of random reads); the faces mark the vertices
    // they use, whose box is then taken in one stream over the positions.
    constexpr uint8_t kFinite = 1, kBeyond = 2;
    LargeArray<uint8_t> flag(nv), used(nv, uint8_t(0));
    tbb::parallel_for(
        tbb::blocked_range<size_t>(0, nv, 16384), [&](const tbb::blocked_range<size_t>& r) {
          for (size_t i = r.begin(); i < r.end(); ++i) {
            const Vec3f& p = m.positions[i];
            const bool beyond = std::fabs(p.x) > kMaxCoordinate ||
                                std::fabs(p.y) > kMaxCoordinate || std::fabs(p.z) > kMaxCoordinate;
            flag[i] = is_finite(p) ? uint8_t(kFinite | (beyond ? kBeyond : 0)) : 0;
          }
        });
    // In parallel over chunks of faces; the first offending vertex in face order is reported.
    const FaceChunks fc = face_chunks(m);
    struct Part {
      uint64_t bad_face = ~uint64_t(0);
      uint32_t bad_vertex = 0;
    };
    std::vector<Part> parts(fc.count());
    for_each_face_chunk(m, fc, [&](size_t ch, size_t f0, size_t f1, const uint32_t* idx) {
      for (size_t f = f0; f < f1; idx += m.face_sizes[f], ++f) {
        const uint32_t n = m.face_sizes[f];
        // A face with a non-finite corner is skipped by every builder.
        if (!face_finite(flag.data(), idx, n)) continue;
        for (uint32_t c = 0; c < n; ++c) {
          if (flag[idx[c]] & kBeyond) {
            parts[ch] = {f, idx[c]};
            return;
          }
          std::atomic_ref<uint8_t>(used[idx[c]]).store(1, std::memory_order_relaxed);
        }
      }
    });
    for (const Part& part : parts)
      if (part.bad_face != ~uint64_t(0))
        throw Error("mesh '" + m.name + "' (" + std::to_string(mi) + "): vertex " +
                    std::to_string(part.bad_vertex) + " of face " + std::to_string(part.bad_face) +
                    " lies beyond +-1e12, the coordinate range slimrt supports (the float " +
                    "watertight test would overflow); scale the scene");
    box.extend(tbb::parallel_reduce(
        tbb::blocked_range<size_t>(0, nv, 16384), Box3f(),
        [&](const tbb::blocked_range<size_t>& r, Box3f b) {
          for (size_t i = r.begin(); i < r.end(); ++i)
            if (used[i]) b.extend(m.positions[i]);
          return b;
        },
        [](Box3f a, const Box3f& b) {
          a.extend(b);
          return a;
        }));
  }
  if (box.empty()) return;
  const Vec3f d = box.hi - box.lo;
  const double diag = std::sqrt(double(d.x) * d.x + double(d.y) * d.y + double(d.z) * d.z);
  if (diag > 0.0 && diag < double(kMinExtent))
    throw Error("scene extent " + fmt_g(diag) +
                " is below 1e-12, the smallest slimrt supports (the float watertight test " +
                "would underflow); scale the scene");
}

}  // namespace

std::unique_ptr<Scene::Impl> build_scene_impl(const MeshList& meshes, const BuildOptions& opt) {
  // The format's builder ends "prepare" when its BVH build starts (api/bvh_scene.h).
  if (opt.progress) report_progress(opt.progress, "prepare", 0, 1);
  for (const MeshView* m : meshes) {
    if (!m) throw Error("Scene::build: null mesh");
    check_mesh(*m);
  }
  check_coordinate_range(meshes);
  opt.check();
  std::unique_ptr<Scene::Impl> impl = format_of(opt.leaf).build(meshes, opt);
  impl->opt = opt;
  impl->opt.progress = nullptr;  // the caller's callback may not outlive the build
  impl->ray_setup = RaySetupBounds(impl->bounds);
  return impl;
}

namespace {

std::unique_ptr<Scene::Impl> build_timed(const MeshList& meshes, const BuildOptions& opt) {
  check_cpu_isa();
  const auto t0 = std::chrono::steady_clock::now();
  std::unique_ptr<Scene::Impl> impl;
  // Every parallel step of the build (checks, triangulation, pairing, grids, BVH) runs on
  // opt.threads threads, the figure `slimrt bench --threads` compares with Embree's.
  if (opt.threads > 0) {
    tbb::task_arena arena(opt.threads);
    arena.execute([&] { impl = build_scene_impl(meshes, opt); });
  } else {
    impl = build_scene_impl(meshes, opt);
  }
  impl->stats.build_seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return impl;
}

}  // namespace

Scene Scene::build(const std::vector<const MeshView*>& meshes, const BuildOptions& opt) {
  Scene s;
  s.impl_ = build_timed(meshes, opt);
  return s;
}

Scene Scene::build(const MeshView& mesh, const BuildOptions& opt) {
  Scene s;
  s.impl_ = build_timed({&mesh}, opt);
  return s;
}

// The PolyMesh builds read their meshes through views (MeshList): nothing is copied.
Scene Scene::build(const std::vector<const PolyMesh*>& meshes, const BuildOptions& opt) {
  Scene s;
  s.impl_ = build_timed(meshes, opt);
  return s;
}

Scene Scene::build(const std::vector<PolyMesh>& meshes, const BuildOptions& opt) {
  std::vector<const PolyMesh*> ptrs;
  for (const PolyMesh& m : meshes) ptrs.push_back(&m);
  Scene s;
  s.impl_ = build_timed(ptrs, opt);
  return s;
}

Scene Scene::build(const PolyMesh& mesh, const BuildOptions& opt) {
  Scene s;
  s.impl_ = build_timed({&mesh}, opt);
  return s;
}

Hit Scene::intersect(const Ray& ray) const {
  Hit hit;
  TravRay tr;
  if (!impl_ || !make_box_ray(ray, impl_->ray_setup, tr)) return hit;
  impl_->intersect(tr, hit);
  return hit;
}

bool Scene::occluded(const Ray& ray) const {
  TravRay tr;
  if (!impl_ || !make_box_ray(ray, impl_->ray_setup, tr)) return false;
  return impl_->occluded(tr);
}

Hit intersect_counted(const Scene& scene, const Ray& ray, TraversalCounters& counters) {
  Hit hit;
  counters.rays++;
  TravRay tr;
  const Scene::Impl* impl = scene.impl_.get();
  if (!impl || !make_box_ray(ray, impl->ray_setup, tr)) return hit;
  impl->intersect_counted(tr, hit, counters);
  return hit;
}

MemoryStats Scene::memory() const { return impl_ ? impl_->mem : MemoryStats{}; }

const SceneStats& Scene::stats() const {
  static const SceneStats empty;
  return impl_ ? impl_->stats : empty;
}

const StatDetails& stat_details(const Scene& scene) {
  static const StatDetails empty;
  return scene.impl_ ? scene.impl_->stats.details : empty;
}

std::optional<double> stat_detail(const Scene& scene, std::string_view name) {
  for (const auto& [k, v] : stat_details(scene))
    if (k == name) return v;
  return std::nullopt;
}

Box3f Scene::bounds() const { return impl_ ? impl_->bounds : Box3f(); }

const BuildOptions& Scene::options() const {
  static const BuildOptions def;
  return impl_ ? impl_->opt : def;
}

bool Scene::is_lossy() const { return impl_ && describe(impl_->opt).lossy; }

double Scene::error_bound() const { return impl_ ? impl_->error_bound : 0.0; }

std::optional<DecodedTriangles> Scene::decoded_triangles() const {
  if (!impl_ || !describe(impl_->opt).own_geometry) return std::nullopt;
  std::optional<DecodedTriangles> t = impl_->decoded_triangles();
  if (!t)
    throw Error(impl_->opt.config_name() +
                ": the built scene does not decode its triangles; decoded_triangles(meshes, "
                "options) rebuilds them from the input");
  return t;
}

std::optional<DecodedTriangles> decoded_triangles(const Scene& scene,
                                                  const std::vector<const PolyMesh*>& meshes) {
  if (!scene.impl_ || !describe(scene.impl_->opt).own_geometry) return std::nullopt;
  if (std::optional<DecodedTriangles> t = scene.impl_->decoded_triangles()) return t;
  return decoded_triangles(meshes, scene.impl_->opt);
}

bool Scene::validate(std::string* why) const {
  if (!impl_) {
    if (why) *why = "scene was not built";
    return false;
  }
  return impl_->validate(why);
}

}  // namespace slim
