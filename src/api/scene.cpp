// slim::Scene: build dispatch and the thread-safe queries.
#include "slimrt/scene.h"

#include <chrono>
#include <cmath>
#include <cstdio>
#include <string>

#include "api/scene_impl.h"

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
void check_coordinate_range(const std::vector<const PolyMesh*>& meshes) {
  Box3f box;
  for (size_t mi = 0; mi < meshes.size(); ++mi) {
    const PolyMesh& m = *meshes[mi];
    uint64_t k = 0;
    for (size_t f = 0; f < m.face_sizes.size(); k += m.face_sizes[f], ++f) {
      bool finite = true;
      for (uint32_t c = 0; c < m.face_sizes[f]; ++c)
        finite = finite && is_finite(m.positions[m.face_indices[k + c]]);
      if (!finite) continue;
      for (uint32_t c = 0; c < m.face_sizes[f]; ++c) {
        const uint32_t v = m.face_indices[k + c];
        const Vec3f& p = m.positions[v];
        if (std::fabs(p.x) > kMaxCoordinate || std::fabs(p.y) > kMaxCoordinate ||
            std::fabs(p.z) > kMaxCoordinate)
          throw Error("mesh '" + m.name + "' (" + std::to_string(mi) + "): vertex " +
                      std::to_string(v) + " of face " + std::to_string(f) +
                      " lies beyond +-1e12, the coordinate range slimrt supports (the float " +
                      "watertight test would overflow); scale the scene");
        box.extend(p);
      }
    }
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

Scene Scene::build(const std::vector<const PolyMesh*>& meshes, const BuildOptions& opt) {
  auto t0 = std::chrono::steady_clock::now();
  for (const PolyMesh* m : meshes) {
    if (!m) throw Error("Scene::build: null mesh");
    check_mesh(*m);
  }
  check_coordinate_range(meshes);
  if (opt.sah_bins < 2 || opt.sah_bins > 64) throw Error("BuildOptions: sah_bins must be 2..64");
  if (opt.max_leaf_size < 1) throw Error("BuildOptions: max_leaf_size must be >= 1");
  std::unique_ptr<Impl> impl;
  switch (opt.geometry) {
    case Geometry::Triangles:
    case Geometry::IndexedTriangles:
      impl = build_triangle_scene(meshes, opt);
      break;
    case Geometry::Pairs:
      impl = build_pair_scene(meshes, opt);
      break;
    case Geometry::Grids:
    case Geometry::LossyGrids:
    case Geometry::LossyGridsE2:
      impl = build_grid_scene(meshes, opt);
      break;
    case Geometry::Quantized:
      impl = build_costa_scene(meshes, opt);
      break;
  }
  impl->opt = opt;
  impl->ray_setup = RaySetupBounds(impl->bounds);
  impl->stats.build_seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  Scene s;
  s.impl_ = std::move(impl);
  return s;
}

Scene Scene::build(const std::vector<PolyMesh>& meshes, const BuildOptions& opt) {
  std::vector<const PolyMesh*> ptrs;
  for (const PolyMesh& m : meshes) ptrs.push_back(&m);
  return build(ptrs, opt);
}

Scene Scene::build(const PolyMesh& mesh, const BuildOptions& opt) {
  return build(std::vector<const PolyMesh*>{&mesh}, opt);
}

Hit Scene::intersect(const Ray& ray) const {
  Hit hit;
  TravRay tr;
  if (!impl_ || !make_trav_ray(ray, impl_->ray_setup, tr)) return hit;
  impl_->intersect(tr, hit);
  return hit;
}

bool Scene::occluded(const Ray& ray) const {
  TravRay tr;
  if (!impl_ || !make_trav_ray(ray, impl_->ray_setup, tr)) return false;
  return impl_->occluded(tr);
}

Hit Scene::intersect(const Ray& ray, TraversalCounters& counters) const {
  Hit hit;
  counters.rays++;
  TravRay tr;
  if (!impl_ || !make_trav_ray(ray, impl_->ray_setup, tr)) return hit;
  impl_->intersect_counted(tr, hit, counters);
  return hit;
}

MemoryStats Scene::memory() const { return impl_ ? impl_->mem : MemoryStats{}; }

const SceneStats& Scene::stats() const {
  static const SceneStats empty;
  return impl_ ? impl_->stats : empty;
}

Box3f Scene::bounds() const { return impl_ ? impl_->bounds : Box3f(); }

const BuildOptions& Scene::options() const {
  static const BuildOptions def;
  return impl_ ? impl_->opt : def;
}

bool Scene::validate(std::string* why) const {
  if (!impl_) {
    if (why) *why = "scene was not built";
    return false;
  }
  return impl_->validate(why);
}

}  // namespace slim
