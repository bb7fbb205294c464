// slimrt scene: the one public entry point for building acceleration structures and tracing rays.
//
//   slim::PolyMesh mesh = slim::load("dragon.ply");
//   slim::BuildOptions opt = slim::BuildOptions::from_config("clbvh-tri4v");
//   slim::Scene scene = slim::Scene::build(mesh, opt);
//   slim::Hit hit = scene.intersect(ray);     // thread-safe, const
//   bool blocked = scene.occluded(ray);
//   slim::MemoryStats m = scene.memory();     // everything the scene keeps
//
// The input meshes (PolyMesh, or MeshView over the caller's arrays) may be freed after build(): the
// scene owns all it needs.
#pragma once

#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "slimrt/decoded.h"
#include "slimrt/error.h"
#include "slimrt/math.h"
#include "slimrt/mesh.h"
#include "slimrt/progress.h"
#include "slimrt/ray.h"

namespace slim {

// A configuration is a node layout, a leaf format and the options of that format. The named
// configurations (bvh8-tri4v, clbvh-compact, lossy-grid, costa-PFV, ...) are the rows of one
// registry (configs() below); BuildOptions::from_config(name) gives a row's options.

// Node layout of the BVH8.
enum class Nodes : uint8_t {
  Bvh8,            // 256-byte nodes: 8 float boxes + 8 child references
  QBvh8,           // 136-byte nodes: 8 boxes quantized to 8 bits in the node's box
  CompressedLeaf,  // BVH8 inner nodes + 72-byte multi-leaf nodes with the leaf data behind them
};

// Leaf (primitive) format.
enum class Leaf : uint8_t {
  Triangles,         // "tri4v": 4 triangles with their vertices gathered into the leaf
  IndexedTriangles,  // "tri4i": 4 triangles as indices into one shared vertex array
  CompactTriangles,  // indices into a per-multi-leaf vertex dictionary (CompressedLeaf only)
  Pairs,             // triangle pairs sharing an edge, 4 pairs per leaf
  Grids,             // uncompressed 5x5 sub-grids over grid-ordered vertices
  LossyGrids,        // 128-byte lossy sub-grids (bilinear patch + 21 quantized displacements)
  SharedLossyGrids,  // 68-byte lossy sub-grids over shared corner lattices (CompressedLeaf only)
  Costa,             // quantized n-gon mesh (letters in BuildOptions::costa)
  // Compressed triangle clusters (prim/cluster.h; CompressedLeaf only): positions on one
  // scene-wide lattice within BuildOptions::cluster_error, or exact floats.
  Clusters,
  LosslessClusters,
};

// Displacement encoding of the lossy sub-grids (Benthin et al., "Ray Tracing Lossy Compressed Grid
// Primitives", section 4).
enum class GridEncoding : uint8_t {
  Octahedral = 1,      // 3-bit octant + 10-bit direction index + 11-bit length (the paper's)
  SharedExponent = 2,  // 3 sign bits + shared 6-bit exponent + three 5-bit mantissas
};

// How the Pairs leaf pairs triangles.
enum class PairingMethod : uint8_t {
  EdgeHeuristic,  // the paper's edge-box surface-area heuristic (PairingOptions below)
  Window2,        // the paper's baseline: consecutive triangles in input order (window N = 2)
};

// Options of the edge-heuristic pairing ("Fast Triangle Pairing for Ray Tracing").
struct PairingOptions {
  // Paper, "Edge key representation & compression": key the half-edges by the edge midpoint and
  // the edge-box surface area, 24 bits each (16 B per half-edge), instead of by vertex indices.
  // For meshes whose vertices are not welded. Default: vertex indices.
  bool coordinate_keys = false;
  // Merge bit-identical vertex positions before pairing (index keys then pair across duplicated
  // vertices too). Geometry is unchanged; only the connectivity the pairing sees.
  bool weld = false;
  // After the paper's greedy scan, re-pair along augmenting paths of length 3 (an unpaired
  // triangle t next to a pair (n, p) whose p has an unpaired neighbour u becomes (t, n) + (p, u)),
  // preferring the largest edge boxes. Not in the paper: the greedy scan alone leaves 11-12% of
  // the triangles of some scans unpaired (nefertiti, koala); this brings them above 89%.
  bool augment = true;
  // Pre-scan (paper, "Results"): if at least this fraction of the triangles pairs in input order
  // (window N = 2, e.g. fan-triangulated quads), the input order is kept and the edge-heuristic
  // pairing is skipped. > 1 disables the pre-scan.
  double prescan_threshold = 0.99;
};

// How the binary BVH is collapsed into 8-wide nodes.
enum class Collapse : uint8_t {
  Auto,     // Optimal, but Slots for the compressed-leaf BVH other than the clusters'
  Optimal,  // SAH-optimal choice of the up to 8 descendants each node takes (for the clusters
            // with a node's memory in the cost)
  Slots,    // open the largest child until 8 slots are taken (spends fewer inner nodes around
            // multi-leaves)
};

// Where the grid formats put the cells and triangles that form no grid of 2+ cells.
enum class GridLeftovers : uint8_t {
  Auto,       // whichever takes less memory (estimated per scene)
  Grids,      // 2x2 sub-grids (a lone triangle as a degenerate quad)
  Triangles,  // triangle leaves in a second BVH
};

struct BuildOptions {
  Nodes nodes = Nodes::Bvh8;
  Leaf leaf = Leaf::Triangles;
  GridEncoding grid_encoding = GridEncoding::Octahedral;  // LossyGrids, SharedLossyGrids
  std::string costa = "PFV";  // Costa: any of the letters T, P, F, V in that order
  PairingMethod pairing = PairingMethod::EdgeHeuristic;  // Pairs
  PairingOptions pairing_options;                        // Pairs with EdgeHeuristic
  Collapse collapse = Collapse::Auto;
  // Grid formats under CompressedLeaf nodes: each sub-grid is split into this many multi-leaf
  // children (1, 2 or 4; 0 = 4 under CompressedLeaf, 1 otherwise).
  int grid_parts = 0;
  GridLeftovers grid_leftovers = GridLeftovers::Auto;
  int sah_bins = 32;      // binned SAH: bins per axis (2..64)
  int max_leaf_size = 4;  // primitives per leaf (triangles; pairs and sub-grids use their own)
  int threads = 0;        // build threads; 0 = all cores
  // Leaf::Clusters: every vertex lies within this fraction of the scene's box diagonal of its
  // input position (the lattice's steps, one per axis, of at most 4 significant bits: the three of
  // largest product meeting it; on a grid, whose rows lie on a coarser power-of-two lattice, powers
  // of two, coarser on those axes).
  double cluster_error = 1e-5;
  // Leaf::Clusters and Leaf::LosslessClusters: two sibling clusters of the SAH's divide their
  // triangles anew where that stores fewer vertices (smaller scenes, longer builds: README's
  // options table).
  bool cluster_redivide = false;
  // The box the lossy formats derive their scene-wide quantities from (the cluster lattice's origin
  // and steps, the grids' displacement bias); empty = the bounds of the meshes being built. A
  // chunked build gives every chunk the whole input's box, so that chunks quantize onto one
  // lattice. Must contain every finite vertex of the meshes (check_mesh-style error otherwise).
  // With a box, the cluster lattice's steps depend on the box alone (no coarser exact axes).
  Box3f lattice_box;
  // Optional progress report and cancellation (BuildProgress above). Empty: nothing is reported
  // and the build does no extra work.
  BuildProgressFn progress;

  // The options of a registry row ("bvh8-tri4v", "clbvh-compact", "lossy-grid", "costa-PFV",
  // ...). Throws slim::Error for an unknown name, listing the known ones.
  static BuildOptions from_config(const std::string& name);
  // A registry row's format with the tuning of `tuning`: nodes, leaf, grid_encoding, costa and
  // pairing from the row; every other field (pairing_options, collapse, grid_parts,
  // grid_leftovers, sah_bins, max_leaf_size, threads, cluster_error, cluster_redivide,
  // lattice_box, progress) from `tuning`. Throws slim::Error for an unknown name.
  static BuildOptions from_config(const std::string& name, const BuildOptions& tuning);
  // The name of the registry row with these nodes, leaf and encoding, or a descriptive name
  // ("qbvh8-pairs") for a combination that has no row.
  std::string config_name() const;
  // Throws slim::Error if the options are out of range or combine a leaf with nodes it cannot
  // live in (CompactTriangles and SharedLossyGrids need CompressedLeaf nodes).
  void check() const;
};

// One row of the registry: a named configuration and the properties of its format.
struct ConfigInfo {
  std::string name;
  BuildOptions options;  // nodes, leaf, encoding, pairing
  // Decoded positions may differ from the input's: Scene::error_bound() > 0 for such a scene.
  bool lossy = false;
  // Intersects other triangles than the input's fan triangulation (lossy positions, or another
  // split of n-gons): checked against a reference run on its own decoded triangles
  // (decoded_triangles() in slimrt/analysis.h), hits mapped back to the input faces.
  bool own_geometry = false;
  std::string error_bound;  // what Scene::error_bound() reports for it ("0" when lossless)
  std::string summary;      // one line for tables and --help
  // What the format's specification promises on `meshes` built with `options`, from the input
  // alone (never from a built scene): a bound, in scene units, on the distance between every
  // decoded vertex and its input vertex, so Scene::error_bound() <= promised_error(meshes) for a
  // scene built from them; 0 for a lossless format. Each decoded triangle is the hull of decoded
  // vertices within that bound of the input ones, so every hit lies within it of the input
  // surface. Throws slim::Error for a null or malformed mesh (check_mesh).
  double promised_error(const std::vector<const PolyMesh*>& meshes) const;
  double promised_error(const std::vector<const MeshView*>& meshes) const;
};
// Every configuration, triangles first (costa: its 16 letter combinations last).
const std::vector<ConfigInfo>& configs();
// The row of a name; throws slim::Error for an unknown name, listing the known ones.
const ConfigInfo& config_info(const std::string& name);
// The row of a name, or nullptr.
const ConfigInfo* find_config(const std::string& name);
// The properties of any options' format: their registry row (with these options) when they have
// one, else the same properties derived for the combination.
ConfigInfo describe(const BuildOptions& opt);
// Every configuration name, in the order of configs().
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

struct SceneStats {
  double build_seconds = 0;
  uint64_t input_faces = 0;
  uint64_t triangles = 0;      // after fan triangulation
  uint64_t skipped_faces = 0;  // faces dropped at build: NaN/Inf vertex (see README)
  uint64_t primitives = 0;     // primitives the BVH was built over (triangles, pairs, ...)
  // The format's own figures (node counts per type, leaf fill, SAH cost, ...) are measurement
  // hooks: stat_details() in slimrt/analysis.h.
};

// Scene::build_chunked: an input larger than memory, built chunk by chunk (README.md "Inputs larger
// than memory"). The input is streamed (PLY, OBJ, procedural scenes; never loaded whole), cut into
// spatial chunks, each chunk built on its own with the same BuildOptions on one lattice
// (BuildOptions::lattice_box = the whole input's box), and a top-level BVH joins the chunk scenes.
struct ChunkedBuildOptions {
  // Bytes the build may hold besides the finished chunk scenes: the spill buffers while the input
  // is partitioned, then one chunk's mesh and its build. 0 = default_memory_budget().
  uint64_t memory_budget = 0;
  // Fan triangles per chunk; 0 = the budget divided by kChunkBuildBytesPerTriangle.
  uint64_t max_chunk_triangles = 0;
  // Where the partition's temporary files go ("" = $TMPDIR, else /tmp); removed at the end.
  std::string spill_dir;
};
// What one triangle of a chunk may cost at the peak of its build (the mesh, references, BVH2 and
// the format's encoder; bvh8-tri4v needs about 140 bytes): sizes chunks from the budget.
constexpr uint64_t kChunkBuildBytesPerTriangle = 160;
// A quarter of the physical memory (1 GiB where it cannot be read).
uint64_t default_memory_budget();

// How Scene::open() checks a scene file (docs: the "Scene files" section of README.md).
struct OpenOptions {
  // Checks every section's xxHash (XXH3-64) against the section table before the scene is used:
  // reads the whole file once (cold page cache: at disk speed). Off, only the header and the
  // section table are checked (their own checksum, always verified) and the sections are trusted:
  // for big files written by slimrt itself.
  bool verify_checksums = true;
  // Walks every node and leaf block and checks every offset and index the traversal follows
  // (bounds-safe, reads the whole file): for files of unknown origin opened without checksums.
  // Throws slim::Error naming the section and the byte offset of the first bad reference; a scene
  // it accepts traces reading inside its sections only. Every configuration.
  bool check_structure = false;
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
  // The same build from arrays the caller keeps (MeshView, slimrt/mesh.h): read in place, not
  // copied into a PolyMesh first; the same scene as the build of a PolyMesh holding those arrays.
  // The arrays must stay unchanged until build() returns, and may go after.
  static Scene build(const std::vector<const MeshView*>& meshes, const BuildOptions& opt = {});
  static Scene build(const MeshView& mesh, const BuildOptions& opt = {});
  // Builds a mesh file or procedural scene (the names slim::load takes, glTF excepted; also
  // "subdiv:LEVELS:MESH", README "Inputs larger than memory") chunk by chunk within
  // chunking.memory_budget (ChunkedBuildOptions above): one scene (geomID 0, primID
  // the face index slim::load would give) whose hits equal those of Scene::build on the loaded
  // mesh up to ties, for lossless configurations; lossy ones keep their error bound and stay
  // watertight across chunk borders. Throws slim::Error as build() and the readers do.
  static Scene build_chunked(const std::string& input, const BuildOptions& opt = {},
                             const ChunkedBuildOptions& chunking = {});

  // Closest hit in [ray.tnear, ray.tfar]; an invalid Hit on a miss. Thread-safe.
  Hit intersect(const Ray& ray) const;
  // Any hit in [ray.tnear, ray.tfar]. Thread-safe.
  bool occluded(const Ray& ray) const;

  MemoryStats memory() const;
  const SceneStats& stats() const;
  Box3f bounds() const;
  const BuildOptions& options() const;

  // The scene's format may decode positions that differ from the input (describe(options())).
  bool is_lossy() const;
  // Largest distance between a decoded vertex and its input vertex, in scene units, measured at
  // build; 0 for the formats that store positions exactly (and for a lossy format whose every
  // vertex happened to be encoded exactly).
  double error_bound() const;
  // The triangles the scene intersects when its format has its own geometry
  // (describe(options()).own_geometry: lossy grids, grid, costa), decoded from the built scene
  // exactly as its leaves decode them, each with the input mesh and face it stands for, in the
  // scene's leaf order; std::nullopt for the formats that intersect the input's fan triangles.
  // Throws slim::Error for a format whose built scene does not decode its leaves (cluster):
  // decoded_triangles(meshes, options) in slimrt/analysis.h rebuilds those from the input.
  std::optional<DecodedTriangles> decoded_triangles() const;

  // Walks the whole structure and checks every invariant (every primitive referenced exactly
  // once, child boxes inside parents, quantized boxes conservative). Returns false and fills
  // `why` with the first violation.
  bool validate(std::string* why = nullptr) const;

  // Writes the scene to `path` (a scene file, conventionally *.slim) atomically (slimrt/output.h):
  // a header with the options, figures and a section table, then the buffers the scene keeps, as
  // 64-byte aligned sections with an xxHash each. Throws slim::Error naming the path.
  void save(const std::string& path) const;
  // Maps a scene file read-only (mmap MAP_SHARED: processes that open the same file share its
  // pages) and returns a scene ready to trace that reads its buffers straight from the mapping
  // (no copy; the mapping lives as long as the scene). memory(), stats(), bounds(), options() and
  // error_bound() are the saved scene's. A damaged, truncated, foreign or incompatible file (other
  // version, byte order, or an instruction set this CPU lacks) throws slim::Error naming the file,
  // the section and the byte offset.
  static Scene open(const std::string& path, const OpenOptions& options = {});
  // The scene file this scene maps, or "" for a scene built in memory.
  const std::string& file() const;

  struct Impl;

 private:
  friend std::optional<DecodedTriangles> decoded_triangles(const Scene& scene,
                                                           const std::vector<const PolyMesh*>&);
  friend Hit intersect_counted(const Scene& scene, const Ray& ray, TraversalCounters& counters);
  friend const std::vector<std::pair<std::string, double>>& stat_details(const Scene& scene);
  // slimrt/clusters.h: reads the clusters' faces in leaf order, cluster-lossless's too.
  friend std::vector<uint32_t> cluster_face_order(const MeshView& mesh, const BuildOptions& opt);
  std::unique_ptr<Impl> impl_;
};

}  // namespace slim
