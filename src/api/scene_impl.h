// The inside of slim::Scene: one implementation per geometry format behind a small virtual
// interface (one indirect call per query).
#pragma once

#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "core/ray.h"
#include "mesh/mesh_list.h"
#include "slimrt/decoded.h"
#include "slimrt/scene.h"

namespace slim {

class SectionVisitor;  // api/scene_file.h

// Scene::stats() and the format's own figures (stat_details() in slimrt/analysis.h), which the
// builders append as name/value pairs and a scene file keeps.
struct SceneStatsAndDetails : SceneStats {
  std::vector<std::pair<std::string, double>> details;
};

struct Scene::Impl {
  BuildOptions opt;
  SceneStatsAndDetails stats;
  MemoryStats mem;
  Box3f bounds;
  RaySetupBounds ray_setup;  // from bounds, set by Scene::build
  // Largest |decoded - input| over the vertices, measured by the builder of a lossy format
  // (Scene::error_bound()); 0 for formats that store positions exactly.
  double error_bound = 0;

  virtual ~Impl() = default;
  // The input figures every builder reports: input faces, fan triangles (also the per-triangle
  // divisor of memory) and faces skipped for a NaN/Inf vertex.
  void set_input(uint64_t faces, uint64_t triangles, uint64_t skipped) {
    stats.input_faces = faces;
    stats.triangles = triangles;
    stats.skipped_faces = skipped;
    mem.triangles = triangles;
  }
  virtual void intersect(TravRay& ray, HitRecord& hit) const = 0;
  virtual bool occluded(TravRay& ray) const = 0;
  virtual void intersect_counted(TravRay& ray, HitRecord& hit, TraversalCounters& c) const = 0;
  virtual bool validate(std::string* why) const = 0;
  // The triangles the scene intersects, decoded from what it stores (Scene::decoded_triangles):
  // overridden by the formats with their own geometry; std::nullopt where the scene intersects the
  // input's fan triangles, or cannot decode its leaves.
  virtual std::optional<DecodedTriangles> decoded_triangles() const { return std::nullopt; }

  // Scene files (api/scene_file.h): the kept buffers as named sections, one visitor for saving
  // and opening.
  virtual void sections(SectionVisitor& v) = 0;
  // After opening: the cheap checks every open runs (root reference, block size); with `deep`,
  // the bounds-safe walk of every reference (OpenOptions::check_structure). Throw SectionFault.
  virtual void check_opened(bool deep) const = 0;

  // A scene joined from chunk scenes (api/scene_joined.h): its chunk count; std::nullopt for a
  // format's own scene.
  virtual std::optional<uint32_t> joined_chunks() const { return std::nullopt; }

  std::string file;                     // the scene file mapped, "" when built in memory
  std::shared_ptr<const void> mapping;  // the file's mapping (munmap when the scene goes)
};

// Whether this CPU has an instruction set named as simd_isa() names them ("scalar", "avx2",
// "avx512"); false for any other name (cpu_check.cpp: a scene file's requirement).
bool cpu_has_isa(const std::string& isa);

// An empty scene of the type `opt` builds, for Scene::open to fill (registry.cpp's format_of
// dispatches to the format files below).
std::unique_ptr<Scene::Impl> empty_triangle_scene(const BuildOptions& opt);
std::unique_ptr<Scene::Impl> empty_pair_scene(const BuildOptions& opt);
std::unique_ptr<Scene::Impl> empty_grid_scene(const BuildOptions& opt);
std::unique_ptr<Scene::Impl> empty_costa_scene(const BuildOptions& opt);
std::unique_ptr<Scene::Impl> empty_cluster_scene(const BuildOptions& opt);

// Checks the meshes (check_mesh, coordinate range) and options, then builds with the format's
// builder; ray_setup set, build time not (Scene::build, the chunks of a joined scene).
std::unique_ptr<Scene::Impl> build_scene_impl(const MeshList& meshes, const BuildOptions& opt);

// Format builders (one per file under api/). Each fills stats/mem/bounds except build time.
std::unique_ptr<Scene::Impl> build_triangle_scene(const MeshList& meshes,
                                                  const BuildOptions& opt);  // scene_triangles.cpp
std::unique_ptr<Scene::Impl> build_pair_scene(const MeshList& meshes,
                                              const BuildOptions& opt);  // scene_pairs.cpp
std::unique_ptr<Scene::Impl> build_grid_scene(const MeshList& meshes,
                                              const BuildOptions& opt);  // scene_grids.cpp
std::unique_ptr<Scene::Impl> build_costa_scene(const MeshList& meshes,
                                               const BuildOptions& opt);  // scene_costa.cpp
std::unique_ptr<Scene::Impl> build_cluster_scene(const MeshList& meshes,
                                                 const BuildOptions& opt);  // scene_clusters.cpp

}  // namespace slim
