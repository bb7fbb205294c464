// slim::Scene: build dispatch and the thread-safe queries.
#include "slimrt/scene.h"

#include <chrono>

#include "api/scene_impl.h"

namespace slim {

Scene::Scene() = default;
Scene::~Scene() = default;
Scene::Scene(Scene&&) noexcept = default;
Scene& Scene::operator=(Scene&&) noexcept = default;

Scene Scene::build(const std::vector<const PolyMesh*>& meshes, const BuildOptions& opt) {
  auto t0 = std::chrono::steady_clock::now();
  for (const PolyMesh* m : meshes) {
    if (!m) throw Error("Scene::build: null mesh");
    check_mesh(*m);
  }
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
