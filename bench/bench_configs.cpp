// Configuration names and properties for `slimrt bench`: see bench_configs.h.
#include "bench_configs.h"

#include "embree_scene.h"

namespace slim::bench {

std::vector<std::string> default_configs() {
  std::vector<std::string> v = EmbreeScene::config_names();
  for (const std::string& n : all_config_names()) v.push_back(n);
  return v;
}

void check_config_name(const std::string& name) {
  if (EmbreeScene::is_config(name)) return;
  try {
    BuildOptions::from_config(name);
  } catch (const Error& e) {
    throw Error(std::string(e.what()) +
                "; Embree anchors: embree-tri, embree-tri-compact, "
                "embree-quad, embree-quad-pairs, embree-grid");
  }
}

bool is_lossy_config(const std::string& name) {
  const ConfigInfo* c = find_config(name);
  return c && c->lossy;
}

namespace {

template <class Tris>
OwnGeometry own_geometry_from(const Tris& t) {
  OwnGeometry g;
  g.mesh.name = "decoded";
  g.mesh.positions = t.vertices;
  g.mesh.face_sizes.assign(t.size(), 3);
  g.mesh.face_indices.resize(3 * t.size());
  for (size_t i = 0; i < g.mesh.face_indices.size(); ++i) g.mesh.face_indices[i] = uint32_t(i);
  g.geom = t.geom;
  g.face = t.face;
  return g;
}

}  // namespace

std::optional<OwnGeometry> own_geometry(const Scene& scene,
                                        const std::vector<const PolyMesh*>& meshes) {
  if (std::optional<DecodedTriangles> t = decoded_triangles(scene, meshes))
    return own_geometry_from(*t);
  return std::nullopt;
}

}  // namespace slim::bench
