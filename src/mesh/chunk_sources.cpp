// Generated chunk sources: see chunk_sources.h.
#include "mesh/chunk_sources.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_reduce.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstring>
#include <limits>
#include <unordered_map>
#include <utility>

#include "slimrt/error.h"

namespace slim::detail {
namespace {

using Clock = std::chrono::steady_clock;
double since(Clock::time_point t0) {
  return std::chrono::duration<double>(Clock::now() - t0).count();
}

void check_max_triangles(const std::string& name, uint64_t max_triangles) {
  if (max_triangles < 1 || max_triangles > (uint64_t(1) << 31))
    throw Error(name + ": max_triangles is " + std::to_string(max_triangles) +
                "; expected 1 to 2^31");
}

// Boundary k of `parts` nearly equal runs over [0, cells).
int split(int cells, int parts, int k) { return int(int64_t(k) * cells / parts); }

void extend_finite(Box3f& b, const Vec3f& p) {
  if (is_finite(p)) b.extend(p);
}

// ---- subdivision lattice ----

uint32_t float_bits(float f) {
  uint32_t b;
  std::memcpy(&b, &f, 4);
  return b;
}

// splitmix64's finalizer (Steele, Lea, Flood 2014): full avalanche on 64 bits.
uint64_t mix64(uint64_t z) {
  z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
  z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
  return z ^ (z >> 31);
}

// Spreads the low 21 bits of v to every third bit of 63.
uint64_t part1by2_21(uint64_t v) {
  v &= 0x1fffff;
  v = (v | v << 32) & 0x1f00000000ffffull;
  v = (v | v << 16) & 0x1f0000ff0000ffull;
  v = (v | v << 8) & 0x100f00f00f00f00full;
  v = (v | v << 4) & 0x10c30c30c30c30c3ull;
  v = (v | v << 2) & 0x1249249249249249ull;
  return v;
}

// |p - q| in double: the same bits for (p, q) and (q, p) (the differences are negated exactly
// by round-to-nearest, their squares are equal).
double distance(const Vec3f& p, const Vec3f& q) {
  const double dx = double(p.x) - double(q.x), dy = double(p.y) - double(q.y),
               dz = double(p.z) - double(q.z);
  return std::sqrt(dx * dx + dy * dy + dz * dz);
}

// The lattice of one base triangle (A, B, C), n = 2^levels: P(u, v) = ((n-u-v) A + u B + v C) / n.
// Edge e: 0 = AB (v == 0), 1 = BC (u + v == n), 2 = CA (u == 0).
struct Lattice {
  Vec3f p[3];
  int n = 1;
  double inv_n = 1;
  bool displaced = false;
  double edge_l[3] = {0, 0, 0};  // lattice edge length along each base edge
  double inner_l = 0;            // for interior points: the shortest base edge / n

  Lattice(const Vec3f& a, const Vec3f& b, const Vec3f& c, int levels, bool disp)
      : p{a, b, c}, n(1 << levels), inv_n(1.0 / double(1 << levels)), displaced(disp) {
    if (!displaced) return;
    for (int e = 0; e < 3; ++e) edge_l[e] = distance(p[e], p[(e + 1) % 3]) * inv_n;
    inner_l = std::min(edge_l[0], std::min(edge_l[1], edge_l[2]));
  }

  // One coordinate: only the nonzero terms, each an exact product, summed in a fixed order.
  // A sum of two terms (a base edge point) does not depend on the order, so the triangle on the
  // other side of the edge gets the same bits.
  float coord(int axis, int w, int u, int v) const {
    const double a = double(p[0][axis]), b = double(p[1][axis]), c = double(p[2][axis]);
    double s;
    if (w == 0)
      s = u == 0 ? double(v) * c : v == 0 ? double(u) * b : double(u) * b + double(v) * c;
    else if (u == 0)
      s = v == 0 ? double(w) * a : double(w) * a + double(v) * c;
    else if (v == 0)
      s = double(w) * a + double(u) * b;
    else
      s = double(w) * a + double(u) * b + double(v) * c;
    return float(s * inv_n);
  }

  Vec3f at(int u, int v) const {
    const int w = n - u - v;
    Vec3f q(coord(0, w, u, v), coord(1, w, u, v), coord(2, w, u, v));
    if (!displaced) return q;
    const int zeros = (w == 0) + (u == 0) + (v == 0);
    if (zeros >= 2) return q;  // a base vertex stays itself
    const double l = zeros == 0 ? inner_l : v == 0 ? edge_l[0] : w == 0 ? edge_l[1] : edge_l[2];
    // h(q) in [-1, 1)^3 from q's bit patterns: 21 bits per axis.
    const uint64_t h = mix64((uint64_t(float_bits(q.x)) << 32 | float_bits(q.y)) ^
                             mix64(uint64_t(float_bits(q.z)) + 0x9E3779B97F4A7C15ull));
    const double scale = double(kDisplacement) * l;
    for (int axis = 0; axis < 3; ++axis) {
      const double r = double((h >> (21 * axis)) & 0x1fffff) * (1.0 / 1048576.0) - 1.0;
      q[axis] = float(double(q[axis]) + scale * r);
    }
    return q;
  }
};

}  // namespace

// ---- procedural tiles ----

ProceduralChunks::ProceduralChunks(const std::string& spec, uint64_t max_triangles)
    : name_(spec), grid_(parse_procedural(spec, kMaxProceduralN)) {
  check_max_triangles(spec, max_triangles);
  const int cx = grid_.cells_x, cy = grid_.cells_y;
  // The fewest tiles of at most q quads, tx x ty with sides ceil(cx / tx) x ceil(cy / ty); among
  // those the squarest (ratio of the longer side to the shorter).
  const uint64_t q = std::max<uint64_t>(1, max_triangles / 2);
  uint64_t best = std::numeric_limits<uint64_t>::max();
  double best_ratio = 0;
  for (uint64_t tx = 1; tx <= uint64_t(cx); ++tx) {
    const uint64_t w = (uint64_t(cx) + tx - 1) / tx;
    if (w > q) continue;
    const uint64_t hmax = std::min<uint64_t>(q / w, uint64_t(cy));
    const uint64_t ty = (uint64_t(cy) + hmax - 1) / hmax;
    const uint64_t h = (uint64_t(cy) + ty - 1) / ty;
    const double ratio = double(std::max(w, h)) / double(std::min(w, h));
    if (tx * ty < best || (tx * ty == best && ratio < best_ratio)) {
      best = tx * ty;
      best_ratio = ratio;
      tiles_x_ = int(tx);
      tiles_y_ = int(ty);
    }
  }
  const uint64_t count = uint64_t(tiles_x_) * uint64_t(tiles_y_);
  if (count > (uint64_t(1) << 24))
    throw Error(spec + ": " + std::to_string(count) + " tiles of at most " +
                std::to_string(max_triangles) +
                " triangles; expected at most 2^24 (a larger max_triangles)");
  tiles_.resize(count);
  info_.resize(count);
  for (int t = 0; t < tiles_y_; ++t)
    for (int k = 0; k < tiles_x_; ++k) {
      Tile& tl = tiles_[size_t(t) * tiles_x_ + k];
      tl = {split(cx, tiles_x_, k), split(cx, tiles_x_, k + 1), split(cy, tiles_y_, t),
            split(cy, tiles_y_, t + 1)};
      ChunkInfo& ci = info_[size_t(t) * tiles_x_ + k];
      ci.faces = uint64_t(tl.i1 - tl.i0) * uint64_t(tl.j1 - tl.j0);
      ci.triangles = 2 * ci.faces;
      ci.corners = 4 * ci.faces;
    }

  // Bounds: every vertex row of each tile row (its border rows twice), full width; each row's
  // columns x_k .. x_k+1 (inclusive: the tiles share their border vertices) go to tile k.
  const auto t0 = Clock::now();
  const int tx = tiles_x_;
  using Boxes = std::vector<Box3f>;
  tbb::parallel_for(0, tiles_y_, [&](int t) {
    const int j0 = split(cy, tiles_y_, t), j1 = split(cy, tiles_y_, t + 1);
    const Boxes boxes = tbb::parallel_reduce(
        tbb::blocked_range<int>(j0, j1 + 1), Boxes(size_t(tx)),
        [&](const tbb::blocked_range<int>& r, Boxes acc) {
          std::vector<Vec3f> row(size_t(grid_.verts_x));
          for (int j = r.begin(); j != r.end(); ++j) {
            grid_.vertex_row(grid_.wrap && j == grid_.verts_y ? 0 : j, row.data());
            for (int k = 0; k < tx; ++k) {
              const int x0 = split(cx, tx, k), x1 = split(cx, tx, k + 1);
              for (int c = x0; c <= x1; ++c)
                extend_finite(acc[size_t(k)], row[c == grid_.verts_x ? 0 : c]);
            }
          }
          return acc;
        },
        [](Boxes a, const Boxes& b) {
          for (size_t k = 0; k < a.size(); ++k) a[k].extend(b[k]);
          return a;
        });
    for (int k = 0; k < tx; ++k) info_[size_t(t) * tx + k].bounds = boxes[size_t(k)];
  });
  for (const ChunkInfo& ci : info_) bounds_.extend(ci.bounds);
  bounds_seconds_ = since(t0);
}

Chunk ProceduralChunks::load(size_t i) const {
  const Tile& tl = tiles_.at(i);
  const bool wrap = grid_.wrap;
  // Vertex columns i0 .. i1 and rows j0 .. j1; on a torus a tile spanning the whole grid meets
  // itself at the seam, so its last column / row is its first one.
  const int nc = wrap && tl.i0 == 0 && tl.i1 == grid_.cells_x ? grid_.cells_x : tl.i1 - tl.i0 + 1;
  const int nr = wrap && tl.j0 == 0 && tl.j1 == grid_.cells_y ? grid_.cells_y : tl.j1 - tl.j0 + 1;
  const int direct = std::min(nc, grid_.verts_x - tl.i0);  // columns before the seam
  Chunk out;
  PolyMesh& m = out.mesh;
  m.name = name_ + " tile " + std::to_string(i);
  m.positions.resize(size_t(nr) * size_t(nc));
  tbb::parallel_for(tbb::blocked_range<int>(0, nr), [&](const tbb::blocked_range<int>& r) {
    for (int k = r.begin(); k != r.end(); ++k) {
      const int j = wrap && tl.j0 + k == grid_.verts_y ? 0 : tl.j0 + k;
      Vec3f* row = m.positions.data() + size_t(k) * size_t(nc);
      grid_.vertex_span(j, tl.i0, tl.i0 + direct, row);
      if (direct < nc) grid_.vertex_span(j, 0, nc - direct, row + direct);  // the seam column
    }
  });
  const int w = tl.i1 - tl.i0;
  const size_t quads = size_t(w) * size_t(tl.j1 - tl.j0);
  m.face_sizes.assign(quads, 4u);
  m.face_indices.resize(4 * quads);
  out.face_ids.resize(quads);
  tbb::parallel_for(tbb::blocked_range<int>(tl.j0, tl.j1), [&](const tbb::blocked_range<int>& r) {
    for (int j = r.begin(); j != r.end(); ++j) {
      const uint32_t r0 = uint32_t((j - tl.j0) % nr) * uint32_t(nc);
      const uint32_t r1 = uint32_t((j + 1 - tl.j0) % nr) * uint32_t(nc);
      size_t f = size_t(j - tl.j0) * size_t(w);
      for (int c = 0; c < w; ++c, ++f) {
        const uint32_t c0 = uint32_t(c), c1 = uint32_t((c + 1) % nc);
        uint32_t* idx = m.face_indices.data() + 4 * f;
        idx[0] = r0 + c0;
        idx[1] = r0 + c1;
        idx[2] = r1 + c1;
        idx[3] = r1 + c0;
        out.face_ids[f] = uint64_t(j) * uint64_t(grid_.cells_x) + uint64_t(tl.i0 + c);
      }
    }
  });
  return out;
}

// ---- subdivided meshes ----

bool is_subdivision(const std::string& name) {
  return name.rfind("subdiv:", 0) == 0 || name.rfind("subdiv-flat:", 0) == 0;
}

SubdivisionSpec parse_subdivision(const std::string& spec) {
  SubdivisionSpec s;
  size_t at;
  if (spec.rfind("subdiv:", 0) == 0) {
    at = 7;
  } else if (spec.rfind("subdiv-flat:", 0) == 0) {
    at = 12;
    s.displaced = false;
  } else {
    throw Error(spec + ": expected subdiv:LEVELS:MESH or subdiv-flat:LEVELS:MESH");
  }
  const size_t colon = spec.find(':', at);
  const std::string digits = spec.substr(at, colon == std::string::npos ? 0 : colon - at);
  const bool ok =
      !digits.empty() && digits.size() <= 2 && (digits.size() == 1 || digits[0] != '0') &&
      std::all_of(digits.begin(), digits.end(), [](char c) { return c >= '0' && c <= '9'; });
  if (!ok || std::stoi(digits) > kMaxSubdivisionLevels || colon + 1 >= spec.size())
    throw Error(spec + ": expected " + spec.substr(0, at) +
                "LEVELS:MESH with LEVELS an integer from 0 to " +
                std::to_string(kMaxSubdivisionLevels) +
                " and MESH a mesh file or procedural scene");
  s.levels = std::stoi(digits);
  s.path = spec.substr(colon + 1);
  return s;
}

SubdividedChunks::SubdividedChunks(const SubdivisionSpec& spec, uint64_t max_triangles)
    : SubdividedChunks(slim::load(spec.path), spec.levels, spec.displaced, max_triangles) {}

SubdividedChunks::SubdividedChunks(PolyMesh base, int levels, bool displaced,
                                   uint64_t max_triangles)
    : name_(base.name), levels_(levels), displaced_(displaced) {
  if (levels < 0 || levels > kMaxSubdivisionLevels)
    throw Error(name_ + ": " + std::to_string(levels) + " subdivision levels; expected 0 to " +
                std::to_string(kMaxSubdivisionLevels));
  check_max_triangles(name_, max_triangles);
  check_mesh(base);
  const auto t0 = Clock::now();
  // Base vertices welded by position bits: weld[v] = the first vertex with v's bits.
  const size_t nv = base.positions.size();
  if (nv > std::numeric_limits<uint32_t>::max())
    throw Error(name_ + ": more than 2^32 - 1 vertices");
  std::vector<uint32_t> weld(nv);
  {
    auto key = [&](uint32_t v) {
      const Vec3f& p = base.positions[v];
      return std::make_tuple(float_bits(p.x), float_bits(p.y), float_bits(p.z), v);
    };
    std::vector<uint32_t> idx(nv);
    for (uint32_t v = 0; v < nv; ++v) idx[v] = v;
    std::sort(idx.begin(), idx.end(), [&](uint32_t a, uint32_t b) { return key(a) < key(b); });
    for (size_t k = 0; k < nv; ++k)
      weld[idx[k]] = k > 0 && std::memcmp(&base.positions[idx[k]], &base.positions[idx[k - 1]],
                                          sizeof(Vec3f)) == 0
                         ? weld[idx[k - 1]]
                         : idx[k];
  }
  // Fan triangles, faces in order: (v0, vk, vk+1).
  const uint64_t fan = base.fan_triangle_count();
  if (fan > std::numeric_limits<uint32_t>::max())
    throw Error(name_ + ": more than 2^32 - 1 base triangles");
  tris_.reserve(3 * fan);
  uint64_t corner = 0;
  for (uint32_t n : base.face_sizes) {
    const uint32_t* f = base.face_indices.data() + corner;
    for (uint32_t k = 1; k + 1 < n; ++k)
      tris_.insert(tris_.end(), {weld[f[0]], weld[f[k]], weld[f[k + 1]]});
    corner += n;
  }
  positions_ = std::move(base.positions);
  setup_seconds_ = since(t0);
  setup(max_triangles);
}

void SubdividedChunks::setup(uint64_t max_triangles) {
  const auto t0 = Clock::now();
  const uint64_t T = tris_.size() / 3;
  auto corner = [&](uint64_t t, int k) -> const Vec3f& { return positions_[tris_[3 * t + k]]; };
  // Finite base triangles, their centroids' box, Morton order.
  Box3f cbox;
  std::vector<std::pair<uint64_t, uint32_t>> keyed;
  for (uint64_t t = 0; t < T; ++t) {
    if (!is_finite(corner(t, 0)) || !is_finite(corner(t, 1)) || !is_finite(corner(t, 2))) continue;
    const Vec3f c = (corner(t, 0) + corner(t, 1) + corner(t, 2)) * (1.0f / 3.0f);
    if (is_finite(c)) cbox.extend(c);
    keyed.push_back({0, uint32_t(t)});
  }
  const Vec3f lo = cbox.empty() ? Vec3f(0, 0, 0) : cbox.lo;
  const Vec3f ext = cbox.empty() ? Vec3f(0, 0, 0) : cbox.hi - cbox.lo;
  tbb::parallel_for(size_t(0), keyed.size(), [&](size_t k) {
    const uint64_t t = keyed[k].second;
    const Vec3f c = (corner(t, 0) + corner(t, 1) + corner(t, 2)) * (1.0f / 3.0f);
    uint64_t code = 0;
    for (int a = 0; a < 3; ++a) {
      const float x = ext[a] > 0 ? (c[a] - lo[a]) / ext[a] * 2097151.0f : 0.0f;
      const uint64_t q = x >= 1.0f ? uint64_t(std::min(x, 2097151.0f)) : 0;  // NaN: 0
      code |= part1by2_21(q) << a;
    }
    keyed[k].first = code;
  });
  std::sort(keyed.begin(), keyed.end());
  order_.resize(keyed.size());
  for (size_t k = 0; k < keyed.size(); ++k) order_[k] = keyed[k].second;
  std::vector<std::pair<uint64_t, uint32_t>>().swap(keyed);

  // Runs of `per` base triangles.
  const uint64_t sub = uint64_t(1) << (2 * levels_);
  const uint64_t per = std::max<uint64_t>(1, max_triangles / sub);
  for (uint64_t s = 0; s < order_.size(); s += per) first_.push_back(s);
  first_.push_back(order_.size());
  const size_t chunks = first_.size() - 1;
  info_.resize(chunks);
  faces_ = order_.size() * sub;
  // Bounds: undisplaced, the base corners' box is exact; displaced, every point is made.
  tbb::parallel_for(size_t(0), chunks, [&](size_t c) {
    ChunkInfo& ci = info_[c];
    ci.faces = (first_[c + 1] - first_[c]) * sub;
    ci.triangles = ci.faces;
    ci.corners = 3 * ci.faces;
    ci.bounds = tbb::parallel_reduce(
        tbb::blocked_range<uint64_t>(first_[c], first_[c + 1]), Box3f(),
        [&](const tbb::blocked_range<uint64_t>& r, Box3f b) {
          for (uint64_t k = r.begin(); k != r.end(); ++k) {
            const uint64_t t = order_[k];
            if (!displaced_) {
              for (int e = 0; e < 3; ++e) b.extend(corner(t, e));
              continue;
            }
            const Lattice lat(corner(t, 0), corner(t, 1), corner(t, 2), levels_, true);
            for (int v = 0; v <= lat.n; ++v)
              for (int u = 0; u + v <= lat.n; ++u) extend_finite(b, lat.at(u, v));
          }
          return b;
        },
        [](Box3f a, const Box3f& b) {
          a.extend(b);
          return a;
        });
  });
  for (const ChunkInfo& ci : info_) bounds_.extend(ci.bounds);
  setup_seconds_ += since(t0);
}

Chunk SubdividedChunks::load(size_t i) const {
  const uint64_t b0 = first_.at(i), b1 = first_.at(i + 1);
  const int n = 1 << levels_;
  const uint64_t sub = uint64_t(n) * uint64_t(n);
  const uint32_t edge_pts = uint32_t(n - 1);
  const uint64_t inner_pts = uint64_t(n - 1) * uint64_t(std::max(n - 2, 0)) / 2;
  // Vertex numbering (serial): base corners and base edges get their points once, from the
  // first triangle that names them (the owner, which also computes them); interior points are
  // the triangle's own. Edge points are numbered from the lower welded vertex to the higher one.
  struct Rec {
    uint32_t corner[3];
    uint32_t edge_first[3];
    bool edge_forward[3];  // the triangle's edge direction (A->B, B->C, C->A) is low -> high
    bool owns_corner[3], owns_edge[3];
    uint32_t inner_first;
  };
  const size_t count = size_t(b1 - b0);
  std::vector<Rec> rec(count);
  std::unordered_map<uint32_t, uint32_t> corners;
  std::unordered_map<uint64_t, uint32_t> edges;
  corners.reserve(count * 2);
  edges.reserve(count * 2);
  uint64_t next = 0;
  for (size_t k = 0; k < count; ++k) {
    const uint32_t* v = tris_.data() + 3 * uint64_t(order_[b0 + k]);
    Rec& r = rec[k];
    for (int e = 0; e < 3; ++e) {
      auto [it, fresh] = corners.try_emplace(v[e], uint32_t(next));
      r.corner[e] = it->second;
      r.owns_corner[e] = fresh;
      next += fresh;
    }
    for (int e = 0; e < 3; ++e) {
      const uint32_t a = v[e], b = v[(e + 1) % 3];
      r.edge_forward[e] = a <= b;
      r.owns_edge[e] = false;
      r.edge_first[e] = 0;
      if (edge_pts == 0) continue;
      auto [it, fresh] =
          edges.try_emplace(uint64_t(std::min(a, b)) << 32 | std::max(a, b), uint32_t(next));
      r.edge_first[e] = it->second;
      r.owns_edge[e] = fresh;
      next += fresh ? edge_pts : 0;
    }
    r.inner_first = uint32_t(next);
    next += inner_pts;
    if (next > std::numeric_limits<uint32_t>::max())
      throw Error(name_ + ": chunk " + std::to_string(i) +
                  " has more than 2^32 - 1 vertices; expected a smaller max_triangles");
  }
  Chunk out;
  PolyMesh& m = out.mesh;
  m.name = name_ + " subdivided " + std::to_string(levels_) + " chunk " + std::to_string(i);
  m.positions.resize(next);
  m.face_sizes.assign(count * sub, 3u);
  m.face_indices.resize(3 * count * sub);
  out.face_ids.resize(count * sub);
  tbb::parallel_for(size_t(0), count, [&](size_t k) {
    const uint64_t t = order_[b0 + k];
    const uint32_t* v = tris_.data() + 3 * t;
    const Rec& r = rec[k];
    const Lattice lat(positions_[v[0]], positions_[v[1]], positions_[v[2]], levels_, displaced_);
    // Vertex index of lattice point (u, v); `own` says whether this triangle computes it.
    auto index = [&](int u, int w_v, bool& own) -> uint32_t {
      const int w = n - u - w_v;
      int e = -1, s = 0;  // edge and the weight on its second end (A->B: u, B->C: v, C->A: w)
      const int c = u == 0 && w_v == 0 ? 0 : w == 0 && w_v == 0 ? 1 : w == 0 && u == 0 ? 2 : -1;
      if (c >= 0) {
        own = r.owns_corner[c];
        return r.corner[c];
      }
      if (w_v == 0) {
        e = 0;
        s = u;
      } else if (w == 0) {
        e = 1;
        s = w_v;
      } else if (u == 0) {
        e = 2;
        s = w;
      }
      if (e >= 0) {
        own = r.owns_edge[e];
        const int kk = r.edge_forward[e] ? s : n - s;
        return r.edge_first[e] + uint32_t(kk - 1);
      }
      own = true;
      // Interior rows v = 1 .. n-2, u = 1 .. n-1-v.
      const uint64_t row =
          uint64_t(w_v - 1) * uint64_t(n - 1) - uint64_t(w_v - 1) * uint64_t(w_v) / 2;
      return r.inner_first + uint32_t(row + uint64_t(u - 1));
    };
    for (int pv = 0; pv <= n; ++pv)
      for (int pu = 0; pu + pv <= n; ++pu) {
        bool own = false;
        const uint32_t idx = index(pu, pv, own);
        if (own) m.positions[idx] = lat.at(pu, pv);
      }
    bool own;
    uint64_t f = uint64_t(k) * sub;
    uint32_t* out_idx = m.face_indices.data() + 3 * f;
    for (int pv = 0; pv < n; ++pv)
      for (int pu = 0; pu + pv < n; ++pu) {
        const uint32_t p00 = index(pu, pv, own), p10 = index(pu + 1, pv, own),
                       p01 = index(pu, pv + 1, own);
        *out_idx++ = p00, *out_idx++ = p10, *out_idx++ = p01;
        out.face_ids[f] = t * sub + (f - uint64_t(k) * sub);
        ++f;
        if (pu + pv < n - 1) {
          const uint32_t p11 = index(pu + 1, pv + 1, own);
          *out_idx++ = p10, *out_idx++ = p11, *out_idx++ = p01;
          out.face_ids[f] = t * sub + (f - uint64_t(k) * sub);
          ++f;
        }
      }
  });
  return out;
}

// ---- entry points ----

std::unique_ptr<ChunkSource> open_procedural_chunks(const std::string& spec,
                                                    uint64_t max_triangles) {
  return std::make_unique<ProceduralChunks>(spec, max_triangles);
}

std::unique_ptr<ChunkSource> open_subdivided_chunks(const std::string& path, int levels,
                                                    uint64_t max_triangles, bool displaced) {
  return std::make_unique<SubdividedChunks>(SubdivisionSpec{path, levels, displaced},
                                            max_triangles);
}

std::unique_ptr<ChunkSource> open_generated_chunks(const std::string& name,
                                                   uint64_t max_triangles) {
  if (is_subdivision(name))
    return std::make_unique<SubdividedChunks>(parse_subdivision(name), max_triangles);
  if (is_procedural(name)) return open_procedural_chunks(name, max_triangles);
  return nullptr;
}

}  // namespace slim::detail
