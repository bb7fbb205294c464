// Triangle formats: bvh8-tri4v/tri4i, qbvh8-tri4v/tri4i, clbvh-tri4v/tri4i.
#include "api/bvh_scene.h"
#include "mesh/triangulate.h"
#include "prim/triangles.h"

namespace slim {

namespace {

template <class Leaf>
std::unique_ptr<Scene::Impl> build_with(TriangleMesh& tm, const BuildOptions& opt) {
  auto s = std::make_unique<BvhScene<Leaf>>();
  TriangleSource src{tm.vertices.data(), tm.tris.data(), tm.geom_ids.data(), tm.prim_ids.data()};
  s->build(src, uint32_t(tm.tri_count()), opt);
  if constexpr (std::is_base_of_v<Tri4i, Leaf>) {
    // The scene keeps the shared vertex array (geometry); the index data lives in the leaves.
    // A copy in memory that a scene may keep (core/large_array.h): the triangulation's array is
    // a temporary on huge pages.
    auto verts = std::make_shared<LargeVector<Vec3f, true>>(tm.vertices.begin(), tm.vertices.end());
    s->ctx.vertices = verts->data();
    s->ctx.vertex_count = verts->size();
    s->mem.geometry_bytes += verts->size() * sizeof(Vec3f);
    s->keepalive = verts;
  }
  return s;
}

}  // namespace

std::unique_ptr<Scene::Impl> empty_triangle_scene(const BuildOptions& opt) {
  if (opt.leaf == Leaf::CompactTriangles) return std::make_unique<BvhScene<Tri4iCompact>>();
  if (opt.leaf == Leaf::IndexedTriangles) return std::make_unique<BvhScene<Tri4i>>();
  return std::make_unique<BvhScene<Tri4v>>();
}

std::unique_ptr<Scene::Impl> build_triangle_scene(const MeshList& meshes, const BuildOptions& opt) {
  TriangleMesh tm = triangulate_fan(meshes);
  std::unique_ptr<Scene::Impl> s;
  if (opt.leaf == Leaf::CompactTriangles)
    s = build_with<Tri4iCompact>(tm, opt);
  else if (opt.leaf == Leaf::IndexedTriangles)
    s = build_with<Tri4i>(tm, opt);
  else
    s = build_with<Tri4v>(tm, opt);
  s->set_input(tm.input_faces, tm.input_triangles, tm.skipped_faces);
  return s;
}

}  // namespace slim
