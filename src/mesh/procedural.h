// The procedural scenes' vertex grids, shared by make_terrain/make_canyon/make_torus and the
// tile-by-tile face stream (io/face_stream.h), so that both give the same bits.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "slimrt/math.h"

namespace slim::detail {

struct ProceduralSpec {
  std::string kind;  // "terrain", "canyon" or "torus"
  int n = 0;
};
// The largest N of the streamed and chunked procedural scenes: the generators' own limit ((N+1)^2
// vertex indices in 32 bits); the in-memory load stops lower.
constexpr int kMaxProceduralN = 65534;
// Parses "kind:N" strictly (decimal digits, no sign or leading zero) with N <= max_n; a torus
// needs N even and >= 6. Throws slim::Error naming the spec and the accepted range.
ProceduralSpec parse_procedural(const std::string& spec, int max_n);

// The quads of a procedural scene over its vertex grid: quad (i, j), 0 <= i < cells_x,
// 0 <= j < cells_y, has id j * cells_x + i and the corners (i,j), (i+1,j), (i+1,j+1), (i,j+1);
// on a torus (wrap) index cells_x / cells_y means 0.
class ProceduralGrid {
 public:
  ProceduralGrid(const ProceduralSpec& spec, uint32_t seed = 1);
  int cells_x = 0, cells_y = 0;  // quads per row, rows
  int verts_x = 0, verts_y = 0;  // vertex grid: n+1 x n+1 (heightfield), n x n/2 (torus)
  bool wrap = false;
  // Vertex row j (0 <= j < verts_y): verts_x positions into out.
  void vertex_row(int j, Vec3f* out) const { vertex_span(j, 0, verts_x, out); }
  // Vertices i0 <= i < i1 of row j (0 <= i0 <= i1 <= verts_x): the same bits as vertex_row's, each
  // vertex computed on its own (a tile generates its columns only).
  void vertex_span(int j, int i0, int i1, Vec3f* out) const;
  // Appends the quads (i, j) with i0 <= i < i1, j0 <= j < j1 (row by row) to sizes / face_ids /
  // corners, bit for bit the positions of the in-memory mesh.
  void tile(int i0, int i1, int j0, int j1, std::vector<uint32_t>& sizes,
            std::vector<uint64_t>& face_ids, std::vector<Vec3f>& corners) const;

 private:
  enum class Kind { Terrain, Canyon, Torus } kind_ = Kind::Terrain;
  int n_ = 0;
  uint32_t s_ = 0;                         // mixed seed
  std::vector<double> su_, cu_, sv_, cv_;  // torus angle tables
};

}  // namespace slim::detail
