// Chunk sources that generate their chunks on demand: nothing is spilled to disk and nothing is
// kept but a table of the chunks. The other source, ChunkSet (mesh/chunks.h), streams any face
// stream and spills it.
//
// Procedural tiles (open_procedural_chunks): terrain:N, canyon:N, torus:N with N up to 65534.
// A chunk is a rectangle of the quad grid (mesh/procedural.h ProceduralGrid): the grid is cut
// into tx x ty tiles of nearly equal sides (they differ by at most one quad), each of at most
// max_triangles fan triangles (a quad is 2; a tile has at least one quad): the fewest tiles,
// and among those the squarest. Tiles are numbered row by row (tile row outer). load(i) generates
// the tile's vertex rows j0..j1, columns i0..i1 (wrapped to 0 at a torus seam), bit for bit the
// positions of make_terrain / make_canyon / make_torus; the chunk mesh is indexed, one position
// per grid vertex of the tile, its quads row by row (j outer, i inner) with the in-memory mesh's
// corner order and face ids (j * cells_x + i). The constructor generates every vertex row once
// (rows on tile borders twice) for the exact bounds of each tile (ChunkInfo::bounds) and of the
// scene; that pass is the source's whole set-up cost (bounds_seconds()).
//
// Subdivided meshes (open_subdivided_chunks): a base mesh (slim::load, so a file or a procedural
// name) is fan-triangulated as the library does ((v0, vk, vk+1) for k = 1 .. size-2; base
// triangle t is the t-th fan triangle of the mesh, faces in order) and every base triangle
// (A, B, C) is split into n^2 triangles, n = 2^levels, over the lattice of points
//   P(u, v) = ((n - u - v) A + u B + v C) / n,  u, v >= 0, u + v <= n,
// computed in double with only the nonzero terms: the products are exact (a float times an
// integer <= 2^12), so a point on a base edge is a sum of two exact terms, which IEEE addition
// gives the same bits in either order (and contraction into an FMA cannot change); both base
// triangles sharing the edge therefore make the same point, and a base vertex stays itself.
// This is midpoint subdivision applied `levels` times (every midpoint of midpoints is a lattice
// point), with each point rounded once from the base corners instead of from its parents.
// Displacement (subdiv:, not subdiv-flat:): every point p not a base vertex moves by
//   kDisplacement * l * h(p),  h(p) in [-1, 1)^3 a hash of p's three float bit patterns,
// l = |A - B| / n for a point on base edge AB (the same from both sides: the difference is
// negated exactly, its square identical) and the shortest edge of the base triangle / n for an
// interior point. It depends only on the point's exact coordinates and its edge, so the surface
// stays watertight: a closed base mesh gives a closed subdivided mesh. Displaced surfaces are not
// planar within a base triangle (each fine triangle is tilted), the fine triangles stay within
// about a fifth of their edge of the flat lattice (no folds for base triangles that are not
// slivers).
// Face ids: base_triangle * 4^levels + local, local numbering the n^2 triangles of a base
// triangle row by row: row v = 0 .. n-1 starts at local v * (2n - v); in it, for u = 0 .. n-1-v,
// the "up" triangle (P(u,v), P(u+1,v), P(u,v+1)) at 2u, then, if u + v < n - 1, the "down"
// triangle (P(u+1,v), P(u+1,v+1), P(u,v+1)) at 2u + 1. Both wind as (A, B, C) does.
// Base triangles with a non-finite corner are left out (their ids are unused).
// Chunks: the base triangles sorted by the Morton code (21 bits per axis) of their centroids in
// the centroids' box, ties by index, then cut into runs of max(1, max_triangles / 4^levels)
// base triangles. A chunk exceeds max_triangles only when 4^levels alone does. Its mesh is
// indexed and welded by lattice key (base vertices welded by position bits first, so a base mesh
// whose duplicated vertices share an edge still welds): faces of 3 corners, base triangles in
// chunk order, each one's triangles in local order. Displaced, the constructor computes every
// point once (twice on base edges) for the exact bounds; undisplaced, the base corners' box is
// exact (a rounded convex combination of floats stays between them) and no point is made then.
//
// Both sources are immutable after construction: load() may run from several threads at once.
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "mesh/chunks.h"
#include "mesh/procedural.h"
#include "slimrt/mesh.h"

namespace slim::detail {

// Displacement amplitude, relative to the local lattice edge (see above).
constexpr float kDisplacement = 0.125f;
constexpr int kMaxSubdivisionLevels = 12;

class ProceduralChunks : public ChunkSource {
 public:
  // terrain:N, canyon:N or torus:N (parse_procedural, N <= 65534) in tiles of at most
  // max_triangles fan triangles. Throws slim::Error on a bad spec, max_triangles outside
  // [1, 2^31], or more than 2^24 tiles.
  ProceduralChunks(const std::string& spec, uint64_t max_triangles);

  size_t size() const override { return tiles_.size(); }
  const ChunkInfo& info(size_t i) const override { return info_[i]; }
  Chunk load(size_t i) const override;
  uint64_t faces() const override { return uint64_t(grid_.cells_x) * uint64_t(grid_.cells_y); }
  uint64_t triangles() const override { return 2 * faces(); }
  Box3f bounds() const override { return bounds_; }

  struct Tile {
    int i0, i1, j0, j1;  // quads i0 <= i < i1, j0 <= j < j1
  };
  const Tile& tile(size_t i) const { return tiles_[i]; }
  int tiles_x() const { return tiles_x_; }
  int tiles_y() const { return tiles_y_; }
  const ProceduralGrid& grid() const { return grid_; }
  double bounds_seconds() const { return bounds_seconds_; }  // the constructor's bounds pass

 private:
  std::string name_;
  ProceduralGrid grid_;
  int tiles_x_ = 0, tiles_y_ = 0;
  std::vector<Tile> tiles_;
  std::vector<ChunkInfo> info_;
  Box3f bounds_;
  double bounds_seconds_ = 0;
};

struct SubdivisionSpec {
  std::string path;  // base mesh: a file or a procedural name, as slim::load takes
  int levels = 0;    // 0 .. kMaxSubdivisionLevels
  bool displaced = true;
};
// "subdiv:LEVELS:PATH" (displaced) or "subdiv-flat:LEVELS:PATH" (the plain lattice): LEVELS
// decimal, 0 to kMaxSubdivisionLevels; PATH is everything after the second colon (it may hold
// colons, e.g. subdiv:2:torus:64). Throws slim::Error naming the spec and what was expected.
SubdivisionSpec parse_subdivision(const std::string& spec);
// True if `name` starts with "subdiv:" or "subdiv-flat:" (whether or not the rest parses).
bool is_subdivision(const std::string& name);

class SubdividedChunks : public ChunkSource {
 public:
  // Loads spec.path (slim::load's errors) and subdivides it in chunks of at most max_triangles.
  // Throws slim::Error on levels out of range or max_triangles outside [1, 2^31].
  SubdividedChunks(const SubdivisionSpec& spec, uint64_t max_triangles);
  // The same over a mesh in memory (its name for messages); check_mesh's errors.
  SubdividedChunks(PolyMesh base, int levels, bool displaced, uint64_t max_triangles);

  size_t size() const override { return info_.size(); }
  const ChunkInfo& info(size_t i) const override { return info_[i]; }
  Chunk load(size_t i) const override;
  uint64_t faces() const override { return faces_; }
  uint64_t triangles() const override { return faces_; }
  Box3f bounds() const override { return bounds_; }

  int levels() const { return levels_; }
  uint64_t base_triangles() const { return tris_.size() / 3; }    // fan triangles, all of them
  uint64_t base_triangles_used() const { return order_.size(); }  // finite ones
  double setup_seconds() const { return setup_seconds_; }         // load excluded

 private:
  void setup(uint64_t max_triangles);
  std::string name_;
  int levels_ = 0;
  bool displaced_ = true;
  std::vector<Vec3f> positions_;  // base vertices
  std::vector<uint32_t> tris_;    // 3 welded base vertex indices per fan triangle
  std::vector<uint32_t> order_;   // finite base triangles in Morton order
  std::vector<uint64_t> first_;   // chunk k = order_[first_[k] .. first_[k+1])
  std::vector<ChunkInfo> info_;
  uint64_t faces_ = 0;
  Box3f bounds_;
  double setup_seconds_ = 0;
};

std::unique_ptr<ChunkSource> open_procedural_chunks(const std::string& spec,
                                                    uint64_t max_triangles);
std::unique_ptr<ChunkSource> open_subdivided_chunks(const std::string& path, int levels,
                                                    uint64_t max_triangles, bool displaced = true);
// A procedural name (terrain:N, canyon:N, torus:N) or a subdivision spec as a generated source;
// nullptr for anything else (a mesh file: stream it into a ChunkSet).
std::unique_ptr<ChunkSource> open_generated_chunks(const std::string& name, uint64_t max_triangles);

}  // namespace slim::detail
