// slimrt scene: the one public entry point for building acceleration structures and tracing rays.
//
//   slim::PolyMesh mesh = slim::load("dragon.ply");
//   slim::BuildOptions opt = slim::BuildOptions::from_config("clbvh-tri4v");
//   slim::Scene scene = slim::Scene::build(mesh, opt);
//   slim::Hit hit = scene.intersect(ray);     // thread-safe, const
//   bool blocked = scene.occluded(ray);
//   slim::MemoryStats m = scene.memory();     // everything the scene keeps
//
// The input meshes may be freed after build(): the scene owns all it needs.
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include "slimrt/error.h"
#include "slimrt/math.h"
#include "slimrt/mesh.h"

namespace slim {

constexpr uint32_t kInvalidID = 0xffffffffu;

// The coordinate range slimrt supports. Beyond it the float products of the watertight test
// overflow (t = inf or a miss) or underflow (misses), as in every float ray tracer. So:
// Scene::build throws slim::Error when a vertex used by a finite face lies beyond
// +-kMaxCoordinate, or when the scene's extent (box diagonal) is nonzero and below kMinExtent;
// rays whose origin lies beyond +-kMaxCoordinate miss.
constexpr float kMaxCoordinate = 1e12f;
constexpr float kMinExtent = 1e-12f;

// Directions whose largest component is below kMinDirection in magnitude count as zero
// directions: t = distance / |dir| would reach 1e30 and beyond, past what the float ray setup
// resolves (the box test's reciprocals are clamped at 1 / kMinDirection).
constexpr float kMinDirection = 1e-18f;

// A ray segment [tnear, tfar]. Rays with a NaN or zero direction (below kMinDirection), a NaN
// origin or one beyond +-kMaxCoordinate, or tnear > tfar (or NaN bounds) never hit anything. A
// hit is reported with a finite t: one whose t would exceed the float range is no hit.
struct Ray {
  Vec3f org;
  float tnear = 0.0f;
  Vec3f dir;
  float tfar = kInf;
};

// Kind of primitive a hit landed on (for debug shading, paper "Costa" Table 4 colours).
enum class PrimKind : uint8_t { Triangle = 0, Quad = 1, Fan = 2, Strip = 3, Pair = 4, Grid = 5 };

struct Hit {
  float t = kInf;
  // Barycentric coordinates of the hit inside the triangle that was hit (weights of its 2nd and
  // 3rd vertex); for grid formats, the per-grid u,v of the paper (grid_u, grid_v in [0,1]).
  float u = 0.0f, v = 0.0f;
  Vec3f Ng;                      // geometric normal of the triangle hit (not normalized)
  uint32_t geomID = kInvalidID;  // index of the input mesh
  uint32_t primID = kInvalidID;  // index of the face in the input mesh
  PrimKind kind = PrimKind::Triangle;

  bool valid() const { return geomID != kInvalidID; }
};

// Geometry (leaf) formats. See BENCHMARK.md for the configuration names that combine them.
enum class Geometry : uint8_t {
  Triangles,         // leaves of up to 4 pre-gathered triangles ("tri4v")
  IndexedTriangles,  // leaves of vertex indices into one shared vertex array ("tri4i")
  Pairs,             // triangle pairs (fast triangle pairing)
  Grids,             // uncompressed 5x5 sub-grids referencing grid-ordered vertices
  LossyGrids,        // 128-byte lossy sub-grids, displacement encoding 1
  LossyGridsE2,      // 128-byte lossy sub-grids, displacement encoding 2
  Quantized,         // Costa quantized n-gon mesh (options in BuildOptions::costa)
  PairsWindow2,      // triangle pairs of the paper's baseline: in-order window N = 2
};

// Node formats.
enum class Bvh : uint8_t {
  Bvh8,                   // 256-byte BVH8 nodes
  Quantized8,             // 136-byte QBVH8 nodes everywhere
  CompressedLeaf,         // BVH8 inner nodes + 72-byte compressed multi-leaf nodes
  CompressedLeafCompact,  // the same, with per-multi-leaf vertex-index dictionaries
};

struct BuildOptions {
  Geometry geometry = Geometry::Triangles;
  Bvh bvh = Bvh::Bvh8;
  int sah_bins = 32;          // binned SAH: bins per axis
  int max_leaf_size = 4;      // primitives per leaf (triangles; pairs and sub-grids use their own)
  std::string costa = "PFV";  // Geometry::Quantized: any of the letters T, P, F, V
  int threads = 0;            // build threads; 0 = all cores

  // Options for a configuration name of BENCHMARK.md ("bvh8-tri4v", "clbvh-compact",
  // "lossy-grid", "costa-PFV", ...). Throws slim::Error for an unknown name.
  static BuildOptions from_config(const std::string& name);
  // The configuration name of these options ("bvh8-tri4v", ...).
  std::string config_name() const;
};
// Every slimrt configuration name, in the order of BENCHMARK.md.
std::vector<std::string> all_config_names();

// The SIMD path slimrt was compiled for: "avx512", "avx2" or "scalar" (CMake option SLIM_ISA).
const char* simd_isa();
// Throws slim::Error if this CPU lacks an instruction set slimrt was compiled for (simd_isa();
// SLIM_ISA=auto takes the build machine's). Scene::build calls it, so does the CLI first thing.
void check_cpu_isa();

// Bytes kept by a scene: geometry (vertices, leaf primitive data), BVH nodes, side tables.
struct MemoryStats {
  uint64_t geometry_bytes = 0;
  uint64_t bvh_bytes = 0;
  uint64_t other_bytes = 0;
  uint64_t triangles = 0;  // input triangles after fan triangulation (the per-triangle divisor)
  uint64_t total() const { return geometry_bytes + bvh_bytes + other_bytes; }
  double bytes_per_triangle() const { return triangles ? double(total()) / double(triangles) : 0; }
};

// Counters of one traversal (box tests = individual child boxes tested, prim tests = triangles
// tested, including the triangles of pairs, grids and fans).
struct TraversalCounters {
  uint64_t rays = 0;
  uint64_t node_visits = 0;
  uint64_t box_tests = 0;
  uint64_t prim_tests = 0;
  // Primitive records tested, a triangle pair counting once (the paper's dual triangle test
  // unit, "Fast Triangle Pairing", Results); equals prim_tests for formats without pairs.
  uint64_t prim_records = 0;
};

struct SceneStats {
  double build_seconds = 0;
  uint64_t input_faces = 0;
  uint64_t triangles = 0;      // after fan triangulation
  uint64_t skipped_faces = 0;  // faces dropped at build: NaN/Inf vertex (see README)
  uint64_t primitives = 0;     // primitives the BVH was built over (triangles, pairs, ...)
  // Format-specific figures (node counts per type, leaf fill, SAH cost, ...), in order.
  std::vector<std::pair<std::string, double>> details;
};

class Scene {
 public:
  Scene();
  ~Scene();
  Scene(Scene&&) noexcept;
  Scene& operator=(Scene&&) noexcept;

  // Builds the acceleration structure. Mesh i becomes geomID i. Throws slim::Error on malformed
  // meshes (check_mesh) and on options that do not apply (e.g. grids of a mesh without quads is
  // fine, but an unknown costa letter is not).
  static Scene build(const std::vector<const PolyMesh*>& meshes, const BuildOptions& opt = {});
  static Scene build(const std::vector<PolyMesh>& meshes, const BuildOptions& opt = {});
  static Scene build(const PolyMesh& mesh, const BuildOptions& opt = {});

  // Closest hit in [ray.tnear, ray.tfar]; an invalid Hit on a miss. Thread-safe.
  Hit intersect(const Ray& ray) const;
  // Any hit in [ray.tnear, ray.tfar]. Thread-safe.
  bool occluded(const Ray& ray) const;
  // intersect() that also counts traversal work (slower; for statistics, not for timing).
  Hit intersect(const Ray& ray, TraversalCounters& counters) const;

  MemoryStats memory() const;
  const SceneStats& stats() const;
  Box3f bounds() const;
  const BuildOptions& options() const;

  // Walks the whole structure and checks every invariant (every primitive referenced exactly
  // once, child boxes inside parents, quantized boxes conservative). Returns false and fills
  // `why` with the first violation.
  bool validate(std::string* why = nullptr) const;

  struct Impl;

 private:
  std::unique_ptr<Impl> impl_;
};

}  // namespace slim
