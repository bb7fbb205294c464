// BuildOptions::lattice_box ("one quantization lattice for the whole scene"): a
// mesh cut into spatial pieces whose pieces are built apart, each with the whole mesh's box, must
// meet without a crack. For every lossy configuration of the registry and three meshes (torus:64,
// terrain:64 and a closed quad scan from ../shared/data), cut into 4 pieces along staircase cuts:
//  (a) every vertex shared by pieces decodes to the same bits in every piece (the decoded
//      triangles of each piece, mapped back to the input vertices through their face ids);
//  (b) rays aimed exactly at the decoded shared edges and vertices, from both sides and at slants,
//      traced against all pieces (closest hit), always hit at the aimed point or before it;
//  (c) every decoded vertex lies within its scene's error_bound() of the input, and the cluster
//      bound within cluster_error x the whole box's diagonal.
// Without lattice_box each piece quantizes in its own box and (a) and (b) fail in every lossy
// configuration, so the test can fail. Also: a lattice_box that misses a vertex, or is not finite,
// is refused; scene files keep the option.
#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <cstring>
#include <map>
#include <set>
#include <string>
#include <unordered_map>
#include <vector>

#include "io/face_stream.h"
#include "mesh/chunks.h"
#include "slimrt/analysis.h"
#include "slimrt/slimrt.h"
#include "temp_dir.h"
#include "test_util.h"

namespace slim {
namespace {

using test::error_of;

// One spatial piece of a mesh: its faces as a mesh of their own (vertices renumbered in order of
// first use, positions copied bit for bit), with the input vertex of each piece vertex.
struct Piece {
  PolyMesh mesh;
  std::vector<uint32_t> vertex;       // input vertex of each piece vertex
  std::vector<uint64_t> face_offset;  // first corner of each piece face
};

std::vector<uint64_t> face_offsets(const PolyMesh& m) {
  std::vector<uint64_t> off(m.face_sizes.size() + 1, 0);
  for (size_t f = 0; f < m.face_sizes.size(); ++f) off[f + 1] = off[f] + m.face_sizes[f];
  return off;
}

// Cuts m into up to 4 pieces by face centroid: u = p[a] + 0.37 p[b] against 43% of its range and
// v = p[b] against 61% (a, b the two longest axes of the box), so that the cuts are oblique
// staircases through the faces, not a grid line.
std::vector<Piece> cut(const PolyMesh& m) {
  const Box3f box = m.bounds();
  const Vec3f ext = box.size();
  int a = 0, b = 1;
  for (int k = 0; k < 3; ++k)
    if (ext[k] > ext[a]) a = k;
  b = a == 0 ? 1 : 0;
  for (int k = 0; k < 3; ++k)
    if (k != a && ext[k] > ext[b]) b = k;
  const std::vector<uint64_t> off = face_offsets(m);
  auto centroid = [&](size_t f) {
    Vec3f c{0, 0, 0};
    for (uint64_t i = off[f]; i < off[f + 1]; ++i) c = c + m.positions[m.face_indices[i]];
    return c * (1.0f / float(m.face_sizes[f]));
  };
  const float u0 = box.lo[a] + 0.37f * box.lo[b], u1 = box.hi[a] + 0.37f * box.hi[b];
  const float cu = u0 + 0.43f * (u1 - u0), cv = box.lo[b] + 0.61f * ext[b];
  std::vector<Piece> pieces(4);
  std::vector<std::vector<uint32_t>> local(4, std::vector<uint32_t>(m.positions.size(), ~0u));
  for (size_t f = 0; f < m.face_sizes.size(); ++f) {
    const Vec3f c = centroid(f);
    const int k = (c[a] + 0.37f * c[b] > cu ? 1 : 0) + (c[b] > cv ? 2 : 0);
    Piece& p = pieces[k];
    p.mesh.face_sizes.push_back(m.face_sizes[f]);
    for (uint64_t i = off[f]; i < off[f + 1]; ++i) {
      const uint32_t v = m.face_indices[i];
      if (local[k][v] == ~0u) {
        local[k][v] = uint32_t(p.vertex.size());
        p.vertex.push_back(v);
        p.mesh.positions.push_back(m.positions[v]);
      }
      p.mesh.face_indices.push_back(local[k][v]);
    }
  }
  std::vector<Piece> out;
  for (int k = 0; k < 4; ++k)
    if (!pieces[k].mesh.face_sizes.empty()) {
      pieces[k].mesh.name = m.name + " piece " + std::to_string(k);
      pieces[k].face_offset = face_offsets(pieces[k].mesh);
      out.push_back(std::move(pieces[k]));
    }
  return out;
}

// A position's bits, -0 as +0: a lossy grid decodes an exact -0 coordinate as -0 and a zero
// displacement over a -0 patch coordinate as +0 (-0 + 0 = +0); both are one point to the
// watertight test, which compares values.
using Bits = std::array<uint32_t, 3>;
Bits bits_of(Vec3f p) {
  const float f[3] = {p.x + 0.0f, p.y + 0.0f, p.z + 0.0f};
  Bits b;
  std::memcpy(b.data(), f, 12);
  return b;
}
struct BitsHash {
  size_t operator()(const Bits& b) const {
    return size_t((uint64_t(b[0]) * 0x9E3779B97F4A7C15ull) ^ (uint64_t(b[1]) << 21) ^ b[2]);
  }
};
Vec3f from_bits(const Bits& b) {
  float f[3];
  std::memcpy(f, b.data(), 12);
  return {f[0], f[1], f[2]};
}

// A built piece and its decoded vertices: the bits of each input vertex as the piece decodes it.
struct BuiltPiece {
  Scene scene;
  std::unordered_map<uint32_t, Bits> decoded;  // input vertex -> decoded position
  uint64_t inconsistent = 0;  // vertices decoded to two different positions within the piece
  double max_error = 0;       // largest |decoded - input| over the decoded vertices
};

// The decoded triangles of a piece mapped back to input vertices: each decoded corner is the
// corner of its face nearest to it (the decoding error is far below the face size).
BuiltPiece build_piece(const Piece& p, const BuildOptions& opt) {
  BuiltPiece b;
  b.scene = Scene::build(p.mesh, opt);
  const std::optional<DecodedTriangles> d = decoded_triangles(b.scene, {&p.mesh});
  if (!d) throw std::logic_error("a lossy configuration without its own geometry");
  for (size_t t = 0; t < d->size(); ++t) {
    const uint32_t f = d->face[t];
    for (int k = 0; k < 3; ++k) {
      const Vec3f q = d->vertices[3 * t + k];
      uint32_t best = 0;
      double best_d = INFINITY;
      for (uint64_t i = p.face_offset[f]; i < p.face_offset[f + 1]; ++i) {
        const double e = length(q - p.mesh.positions[p.mesh.face_indices[i]]);
        if (e < best_d) best_d = e, best = p.mesh.face_indices[i];
      }
      b.max_error = std::max(b.max_error, best_d);
      auto [it, fresh] = b.decoded.emplace(p.vertex[best], bits_of(q));
      if (!fresh && it->second != bits_of(q)) b.inconsistent++;
    }
  }
  return b;
}

struct SharedFigures {
  uint64_t shared = 0;      // input vertices used by 2+ pieces
  uint64_t mismatched = 0;  // of those: decoded to different bits by two pieces
  uint64_t missing = 0;     // a piece using the vertex decoded no triangle with it
};

SharedFigures compare_shared(const std::vector<Piece>& pieces,
                             const std::vector<BuiltPiece>& built) {
  std::unordered_map<uint32_t, std::vector<size_t>> users;
  for (size_t k = 0; k < pieces.size(); ++k)
    for (uint32_t v : pieces[k].vertex) users[v].push_back(k);
  SharedFigures s;
  for (const auto& [v, ks] : users) {
    if (ks.size() < 2) continue;
    s.shared++;
    std::set<Bits> seen;
    for (size_t k : ks) {
      auto it = built[k].decoded.find(v);
      if (it == built[k].decoded.end())
        s.missing++;
      else
        seen.insert(it->second);
    }
    if (seen.size() > 1) s.mismatched++;
  }
  return s;
}

// Edges of faces in two different pieces (input vertex ids) with the summed normals of the faces
// around them (Newell normals, not normalized).
struct SharedEdge {
  uint32_t a, b;
  Vec3f normal;
  bool a_on_border;  // a lies on the whole mesh's boundary (a ray at it may pass beside the mesh)
};

std::vector<SharedEdge> shared_edges(const std::vector<Piece>& pieces) {
  struct Use {
    uint32_t pieces = 0, faces = 0;
    Vec3f normal{0, 0, 0};
  };
  std::map<std::pair<uint32_t, uint32_t>, Use> edges;
  for (size_t k = 0; k < pieces.size(); ++k) {
    const Piece& p = pieces[k];
    for (size_t f = 0; f + 1 < p.face_offset.size(); ++f) {
      const uint64_t o = p.face_offset[f], n = p.face_offset[f + 1] - o;
      Vec3f nrm{0, 0, 0};
      for (uint64_t i = 0; i < n; ++i) {
        const Vec3f c = p.mesh.positions[p.mesh.face_indices[o + i]];
        const Vec3f d = p.mesh.positions[p.mesh.face_indices[o + (i + 1) % n]];
        nrm = nrm + cross(c, d);
      }
      const float len = length(nrm);
      if (len > 0) nrm = nrm * (1.0f / len);
      for (uint64_t i = 0; i < n; ++i) {
        uint32_t u = p.vertex[p.mesh.face_indices[o + i]];
        uint32_t v = p.vertex[p.mesh.face_indices[o + (i + 1) % n]];
        if (u > v) std::swap(u, v);
        Use& e = edges[{u, v}];
        e.pieces |= 1u << k;
        e.faces++;
        e.normal = e.normal + nrm;
      }
    }
  }
  std::set<uint32_t> border;
  for (const auto& [key, use] : edges)
    if (use.faces == 1) border.insert({key.first, key.second});
  std::vector<SharedEdge> out;
  for (const auto& [key, use] : edges)
    if (__builtin_popcount(use.pieces) >= 2)
      out.push_back({key.first, key.second, use.normal, border.count(key.first) > 0});
  return out;
}

struct LeakFigures {
  uint64_t rays = 0, leaks = 0;
};

// Rays aimed exactly at points of the decoded shared edges (ends, 1/4, 1/2, 3/4), from both sides
// of the surface, along the normal and slanted across the edge both ways, starting `reach` away.
// Closest hit over all pieces; a leak is a miss or a hit beyond the aimed point.
LeakFigures trace_cuts(const std::vector<SharedEdge>& edges, const std::vector<BuiltPiece>& built,
                       float reach) {
  LeakFigures f;
  auto decoded = [&](uint32_t v, Vec3f& out) {
    for (const BuiltPiece& b : built) {
      auto it = b.decoded.find(v);
      if (it != b.decoded.end()) {
        out = from_bits(it->second);
        return true;
      }
    }
    return false;
  };
  for (const SharedEdge& e : edges) {
    Vec3f A, B;
    if (!decoded(e.a, A) || !decoded(e.b, B)) continue;
    const Vec3f along = B - A;
    if (!(length(along) > 0) || !(length(e.normal) > 0)) continue;
    const Vec3f n = normalize(e.normal);
    const Vec3f side = safe_normalize(cross(along, n));
    for (float t : {0.0f, 0.25f, 0.5f, 0.75f}) {
      if (t == 0.0f && e.a_on_border) continue;
      const Vec3f target = A + along * t;
      for (float s : {1.0f, -1.0f})
        for (float slant : {0.0f, 0.8f, -0.8f}) {
          const Vec3f dir = normalize(n * (-s) + side * slant);
          Ray r;
          r.org = target - dir * reach;
          r.dir = dir;
          float best = kInf;
          for (const BuiltPiece& b : built) {
            const Hit h = b.scene.intersect(r);
            if (h.valid()) best = std::min(best, h.t);
          }
          f.rays++;
          if (!(best <= reach * 1.0001f)) f.leaks++;
        }
    }
  }
  return f;
}

// The meshes of the tests: procedural ones always, the closed quad scan when ../shared/data has it.
PolyMesh test_mesh(const std::string& name) {
  if (name == "spot") return load(test::shared_data_dir() + "/spot_quadrangulated.obj");
  return load(name);
}

bool mesh_available(const std::string& name) {
  return name != "spot" ||
         std::filesystem::exists(test::shared_data_dir() + "/spot_quadrangulated.obj");
}

std::vector<std::string> lossy_configs() {
  std::vector<std::string> v;
  for (const ConfigInfo& c : configs())
    if (c.lossy) v.push_back(c.name);
  return v;
}

struct Case {
  std::string config, mesh;
  GridLeftovers leftovers = GridLeftovers::Auto;
};

void PrintTo(const Case& c, std::ostream* os) {
  *os << c.config << " on " << c.mesh
      << (c.leftovers == GridLeftovers::Grids ? ", leftover grids" : "");
}

std::vector<Case> cases() {
  std::vector<Case> v;
  for (const char* m : {"torus:64", "terrain:64", "spot"})
    for (const std::string& c : lossy_configs()) {
      v.push_back({c, m});
      // The grid formats' leftovers as 2x2 sub-grids too (lossy corners of another kind).
      const Leaf leaf = config_info(c).options.leaf;
      if ((leaf == Leaf::LossyGrids || leaf == Leaf::SharedLossyGrids) &&
          config_info(c).options.nodes == Nodes::CompressedLeaf)
        v.push_back({c, m, GridLeftovers::Grids});
    }
  return v;
}

std::string case_name(const testing::TestParamInfo<Case>& i) {
  std::string n = i.param.config + "_" + i.param.mesh +
                  (i.param.leftovers == GridLeftovers::Grids ? "_leftover_grids" : "");
  for (char& c : n)
    if (!std::isalnum(static_cast<unsigned char>(c))) c = '_';
  return n;
}

class LatticeBoxPieces : public testing::TestWithParam<Case> {};

TEST_P(LatticeBoxPieces, SharedVerticesDecodeIdenticallyAndCutsDoNotLeak) {
  const Case& c = GetParam();
  if (!mesh_available(c.mesh)) SLIM_MISSING_DATA("missing shared mesh spot_quadrangulated.obj");
  const PolyMesh m = test_mesh(c.mesh);
  const std::vector<Piece> pieces = cut(m);
  ASSERT_GE(pieces.size(), 2u) << c.mesh;
  BuildOptions opt = BuildOptions::from_config(c.config);
  opt.grid_leftovers = c.leftovers;
  opt.lattice_box = m.bounds();
  std::vector<BuiltPiece> built;
  for (const Piece& p : pieces) built.push_back(build_piece(p, opt));

  // (a) one decoded position per shared vertex, in every piece using it.
  const SharedFigures s = compare_shared(pieces, built);
  EXPECT_GT(s.shared, 100u) << "the cut shares too few vertices to show anything";
  EXPECT_EQ(s.mismatched, 0u) << s.shared << " shared vertices";
  EXPECT_EQ(s.missing, 0u);
  for (const BuiltPiece& b : built) EXPECT_EQ(b.inconsistent, 0u);

  // (c) the error bound, against the input.
  const double diag = length(m.bounds().size());
  for (size_t k = 0; k < built.size(); ++k) {
    const double bound = built[k].scene.error_bound();
    EXPECT_LE(built[k].max_error, bound * (1 + 1e-6) + 1e-30) << pieces[k].mesh.name;
    EXPECT_LT(bound, 1e-3 * diag) << pieces[k].mesh.name;
    if (opt.leaf == Leaf::Clusters) {
      EXPECT_LE(bound, opt.cluster_error * diag * (1 + 1e-6));
    }
  }

  // (b) no ray aimed at a cut passes between the pieces.
  const std::vector<SharedEdge> edges = shared_edges(pieces);
  ASSERT_GT(edges.size(), 50u);
  // Well outside the decoding error, well inside the local feature size (the torus tube, the
  // scan's ears): a few mean edge lengths.
  double edge_len = 0;
  for (const SharedEdge& e : edges) edge_len += length(m.positions[e.b] - m.positions[e.a]);
  const float reach = float(2.0 * edge_len / double(edges.size()));
  const LeakFigures lf = trace_cuts(edges, built, reach);
  EXPECT_GT(lf.rays, 1000u);
  EXPECT_EQ(lf.leaks, 0u) << "of " << lf.rays << " rays at " << edges.size() << " cut edges";
}

INSTANTIATE_TEST_SUITE_P(LossyConfigs, LatticeBoxPieces, testing::ValuesIn(cases()), case_name);

// Without lattice_box each piece is quantized in its own box (and the grids keep their cut
// vertices lossy): in every lossy configuration the pieces then decode shared vertices to
// different bits and rays at the cuts leak, which is what the test above would catch.
TEST(LatticeBox, WithoutItPiecesDisagreeAndLeak) {
  const PolyMesh m = load("torus:64");
  const std::vector<Piece> pieces = cut(m);
  const std::vector<SharedEdge> edges = shared_edges(pieces);
  double edge_len = 0;
  for (const SharedEdge& e : edges) edge_len += length(m.positions[e.b] - m.positions[e.a]);
  const float reach = float(2.0 * edge_len / double(edges.size()));
  for (const std::string& config : lossy_configs()) {
    const BuildOptions opt = BuildOptions::from_config(config);
    std::vector<BuiltPiece> built;
    for (const Piece& p : pieces) built.push_back(build_piece(p, opt));
    const SharedFigures s = compare_shared(pieces, built);
    EXPECT_GT(s.mismatched, s.shared / 4) << config << ": " << s.shared << " shared vertices";
    const LeakFigures lf = trace_cuts(edges, built, reach);
    EXPECT_GT(lf.leaks, lf.rays / 20) << config << ": " << lf.rays << " rays";
  }
}

// The chunker's own chunks (mesh/chunks.h: Morton cells, spilled and welded by position), each
// built with lattice_box = ChunkSet::bounds() as a chunked build does: (a) and (b) as above, vertex
// identity across chunks by position bits.
TEST(LatticeBox, ChunkSetChunksMeetWithoutCracks) {
  test::TempDir dir("slimrt_lattice_chunks");
  detail::ChunkOptions co;
  co.spill_dir = dir.dir();
  co.max_triangles = 800;
  auto stream = detail::open_face_stream("torus:96");
  detail::ChunkSet set(*stream, co);
  ASSERT_GE(set.size(), 8u);
  std::vector<Piece> pieces;
  std::unordered_map<Bits, uint32_t, BitsHash> ids;
  std::vector<Vec3f> positions;
  for (size_t i = 0; i < set.size(); ++i) {
    Piece p;
    p.mesh = set.load(i).mesh;
    for (const Vec3f& q : p.mesh.positions) {
      auto [it, fresh] = ids.emplace(bits_of(q), uint32_t(positions.size()));
      if (fresh) positions.push_back(q);
      p.vertex.push_back(it->second);
    }
    p.face_offset = face_offsets(p.mesh);
    pieces.push_back(std::move(p));
  }
  const std::vector<SharedEdge> edges = shared_edges(pieces);
  ASSERT_GT(edges.size(), 100u);
  double edge_len = 0;
  for (const SharedEdge& e : edges) edge_len += length(positions[e.b] - positions[e.a]);
  const float reach = float(2.0 * edge_len / double(edges.size()));
  for (const char* config : {"lossy-grid", "lossy-grid-shared", "cluster", "costa-PFV"}) {
    BuildOptions opt = BuildOptions::from_config(config);
    opt.lattice_box = set.bounds();
    std::vector<BuiltPiece> built;
    for (const Piece& p : pieces) built.push_back(build_piece(p, opt));
    const SharedFigures s = compare_shared(pieces, built);
    EXPECT_GT(s.shared, 100u) << config;
    EXPECT_EQ(s.mismatched, 0u) << config;
    EXPECT_EQ(s.missing, 0u) << config;
    const LeakFigures lf = trace_cuts(edges, built, reach);
    EXPECT_GT(lf.rays, 1000u) << config;
    EXPECT_EQ(lf.leaks, 0u) << config << ": " << lf.rays << " rays";
  }
}

// End to end: Scene::build_chunked (which gives every chunk lattice_box = the input's box) of the
// closed torus:128 in 16+ chunks, for each lossy format family. Rays aimed at every edge of the
// mesh (its ends and middle, from both sides, straight and slanted), so at every chunk cut among
// them, must hit at the aimed point or just before: a crack lets a ray through to the far side of
// the tube or out of the torus. The aimed points are the decoded edges where the chunks decode as
// the whole mesh (cluster, costa V: one lattice), else the input's (the lossy grids store cut
// vertices exactly; elsewhere their decoding error is far below the slack allowed).
TEST(LatticeBox, ChunkedBuildOfTheTorusHasNoLeaks) {
  test::TempDir dir("slimrt_lattice_chunked");
  const PolyMesh m = load("torus:128");
  ChunkedBuildOptions chunking;
  chunking.max_chunk_triangles = 1024;
  chunking.spill_dir = dir.dir();
  Piece whole;
  whole.mesh = m;
  for (uint32_t v = 0; v < m.positions.size(); ++v) whole.vertex.push_back(v);
  whole.face_offset = face_offsets(m);
  // Every edge with the summed normals of its faces.
  std::map<std::pair<uint32_t, uint32_t>, Vec3f> edges;
  for (size_t f = 0; f + 1 < whole.face_offset.size(); ++f) {
    const uint64_t o = whole.face_offset[f], n = whole.face_offset[f + 1] - o;
    Vec3f nrm{0, 0, 0};
    for (uint64_t i = 0; i < n; ++i)
      nrm = nrm +
            cross(m.positions[m.face_indices[o + i]], m.positions[m.face_indices[o + (i + 1) % n]]);
    nrm = safe_normalize(nrm);
    for (uint64_t i = 0; i < n; ++i) {
      uint32_t u = m.face_indices[o + i], v = m.face_indices[o + (i + 1) % n];
      if (u > v) std::swap(u, v);
      Vec3f& e = edges[{u, v}];
      e = e + nrm;
    }
  }
  const float reach = 0.05f;  // the tube's radius is 0.4, its edges 0.02 to 0.07 long
  for (const char* config :
       {"lossy-grid", "lossy-grid-e2", "lossy-grid-shared", "cluster", "costa-PFV", "costa-TV"}) {
    const BuildOptions opt = BuildOptions::from_config(config);
    const Scene joined = Scene::build_chunked("torus:128", opt, chunking);
    double chunks = 0;
    for (const auto& [k, v] : stat_details(joined))
      if (k == "chunks") chunks = v;
    EXPECT_GE(chunks, 16) << config;
    std::vector<Vec3f> aim = m.positions;
    if (opt.leaf == Leaf::Clusters || opt.leaf == Leaf::Costa) {
      BuildOptions boxed = opt;
      boxed.lattice_box = m.bounds();
      const BuiltPiece w = build_piece(whole, boxed);
      for (const auto& [v, bits] : w.decoded) aim[v] = from_bits(bits);
    }
    uint64_t rays = 0, leaks = 0;
    for (const auto& [key, normal] : edges) {
      const Vec3f A = aim[key.first], B = aim[key.second];
      const Vec3f n = safe_normalize(normal), side = safe_normalize(cross(B - A, n));
      for (float t : {0.0f, 0.5f})
        for (float s : {1.0f, -1.0f})
          for (float slant : {0.0f, 0.7f}) {
            Ray r;
            r.dir = normalize(n * (-s) + side * slant * s);
            r.org = A + (B - A) * t - r.dir * reach;
            const Hit h = joined.intersect(r);
            rays++;
            if (!h.valid() || h.t > 1.25f * reach || !joined.occluded(r)) leaks++;
          }
    }
    EXPECT_EQ(leaks, 0u) << config << ": of " << rays << " rays at " << edges.size() << " edges";
  }
}

// Cluster and costa V quantize onto one lattice derived from the box alone: a piece built with the
// whole mesh's box decodes every vertex exactly as the whole mesh's build does. On a grid terrain
// the whole mesh's own `cluster` lattice is another (its grid rows on power-of-two steps,
// cluster::quantize), so there the whole mesh is built on the box too; on the torus (no grid) its
// own lattice is the box's.
TEST(LatticeBox, PiecesDecodeAsTheWholeMesh) {
  for (const char* name : {"terrain:64", "torus:64"}) {
    const PolyMesh m = load(name);
    const std::vector<Piece> pieces = cut(m);
    for (const char* config : {"cluster", "costa-V", "costa-TPFV"}) {
      BuildOptions opt = BuildOptions::from_config(config);
      BuildOptions whole_opt = opt;
      if (std::string(config) == "cluster" && std::string(name) == "terrain:64")
        whole_opt.lattice_box = m.bounds();
      Piece whole;
      whole.mesh = m;
      for (uint32_t v = 0; v < m.positions.size(); ++v) whole.vertex.push_back(v);
      whole.face_offset = face_offsets(m);
      const BuiltPiece w = build_piece(whole, whole_opt);
      opt.lattice_box = m.bounds();
      uint64_t compared = 0, differ = 0;
      for (const Piece& p : pieces) {
        const BuiltPiece b = build_piece(p, opt);
        for (const auto& [v, bits] : b.decoded) {
          compared++;
          if (w.decoded.at(v) != bits) differ++;
        }
      }
      EXPECT_GE(compared, m.positions.size()) << name << " " << config;
      EXPECT_EQ(differ, 0u) << name << " " << config;
    }
  }
}

// A lossy grid vertex on a cut is stored exactly (lossy_subgrid.h's escape): with lattice_box the
// pieces' boundary vertices decode to the input's bits. Without it the same vertices are
// quantized displacements, and a closed mesh (no boundary) escapes nothing more.
TEST(LatticeBox, GridBoundaryVerticesAreExact) {
  const PolyMesh m = load("terrain:64");
  const std::vector<Piece> pieces = cut(m);
  for (const char* config : {"lossy-grid", "lossy-grid-shared"}) {
    BuildOptions opt = BuildOptions::from_config(config);
    opt.lattice_box = m.bounds();
    std::unordered_map<uint32_t, int> users;
    for (const Piece& p : pieces)
      for (uint32_t v : p.vertex) users[v]++;
    uint64_t shared = 0, inexact = 0;
    for (const Piece& p : pieces) {
      const BuiltPiece b = build_piece(p, opt);
      for (const auto& [v, bits] : b.decoded)
        if (users[v] > 1) {
          shared++;
          if (bits != bits_of(m.positions[v])) inexact++;
        }
    }
    EXPECT_GT(shared, 100u) << config;
    EXPECT_EQ(inexact, 0u) << config;
    // The closed torus has no boundary edge: lattice_box adds no exact vertex to its build.
    const PolyMesh torus = load("torus:64");
    BuildOptions plain = BuildOptions::from_config(config);
    BuildOptions boxed = plain;
    boxed.lattice_box = torus.bounds();
    auto exact = [&](const BuildOptions& o) {
      const Scene scene = Scene::build(torus, o);
      for (const auto& [k, v] : stat_details(scene))
        if (k == "exact_vertices") return v;
      return -1.0;
    };
    EXPECT_EQ(exact(plain), exact(boxed)) << config;
  }
}

TEST(LatticeBox, VertexOutsideTheBoxIsRefused) {
  const PolyMesh m = load("torus:16");
  Box3f small = m.bounds();
  small.hi.x = (small.lo.x + small.hi.x) * 0.5f;
  for (const std::string& c : lossy_configs()) {
    BuildOptions opt = BuildOptions::from_config(c);
    opt.lattice_box = small;
    const std::string e = error_of([&] { Scene::build(m, opt); });
    EXPECT_NE(e.find("outside BuildOptions::lattice_box"), std::string::npos) << c << ": " << e;
    EXPECT_NE(e.find("must contain every finite vertex"), std::string::npos) << c << ": " << e;
  }
  // The whole box is accepted, and a NaN vertex (its faces are skipped) needs no room in it.
  PolyMesh with_nan = m;
  with_nan.positions.push_back({NAN, 0, 0});
  with_nan.face_sizes.push_back(3);
  with_nan.face_indices.insert(with_nan.face_indices.end(),
                               {0, 1, uint32_t(with_nan.positions.size() - 1)});
  BuildOptions opt = BuildOptions::from_config("cluster");
  opt.lattice_box = m.bounds();
  EXPECT_EQ(error_of([&] { Scene::build(with_nan, opt); }), "");
}

TEST(LatticeBox, NonFiniteBoxIsRefused) {
  const PolyMesh m = load("torus:16");
  for (const Box3f& b : {Box3f({0, 0, 0}, {1, kInf, 1}), Box3f({NAN, 0, 0}, {1, 1, 1}),
                         Box3f({-kInf, -kInf, -kInf}, {kInf, kInf, kInf})}) {
    BuildOptions opt = BuildOptions::from_config("cluster");
    opt.lattice_box = b;
    const std::string e = error_of([&] { Scene::build(m, opt); });
    EXPECT_NE(e.find("lattice_box"), std::string::npos) << e;
    EXPECT_NE(e.find("not a finite box"), std::string::npos) << e;
  }
}

// Scene files keep lattice_box: the opened scene's options are the built one's, bit for bit, and
// the default (empty) box stays empty.
TEST(LatticeBox, SceneFileKeepsIt) {
  test::TempDir dir("slimrt_lattice");
  const PolyMesh m = load("torus:16");
  for (bool given : {true, false}) {
    BuildOptions opt = BuildOptions::from_config("cluster");
    if (given) {
      opt.lattice_box = m.bounds();
      opt.lattice_box.lo.x -= 0.25f;
      opt.lattice_box.hi.z += 1.5f;
    }
    const Scene s = Scene::build(m, opt);
    const std::string path = dir.path(given ? "given.slim" : "empty.slim");
    s.save(path);
    const Scene o = Scene::open(path);
    EXPECT_EQ(std::memcmp(&o.options().lattice_box, &s.options().lattice_box, sizeof(Box3f)), 0);
    EXPECT_EQ(o.options().lattice_box.empty(), !given);
    EXPECT_EQ(o.error_bound(), s.error_bound());
  }
}

}  // namespace
}  // namespace slim
