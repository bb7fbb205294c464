// Compressed triangle clusters (prim/cluster.h, configurations `cluster` and `cluster-lossless`):
// the block codec bit for bit, the checker, hits against bvh8-tri4v (lossless) and a brute force
// over the decoded triangles (lossy), watertightness across cluster borders, statistics.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cfenv>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <numeric>
#include <optional>
#include <random>
#include <string>

#include "bvh/bvh8.h"
#include "mesh/triangulate.h"
#include "prim/cluster.h"
#include "slimrt/analysis.h"
#include "slimrt/clusters.h"
#include "test_util.h"

using namespace slim;
using namespace slim::test;

namespace {

uint32_t bits_of(float f) {
  uint32_t u;
  std::memcpy(&u, &f, 4);
  return u;
}

// Two scenes of the same decoded triangles: 2000 random rays hit the same face at the same t, u
// and v bit for bit (and more than 500 of them hit).
void expect_same_hits(const Scene& a, const Scene& b, uint64_t seed) {
  Rng rng(seed);
  int hits = 0;
  for (int i = 0; i < 2000; ++i) {
    const Ray r = random_ray(rng, a.bounds());
    const Hit ha = a.intersect(r), hb = b.intersect(r);
    hits += ha.valid();
    ASSERT_EQ(ha.valid(), hb.valid()) << i;
    ASSERT_EQ(bits_of(ha.t), bits_of(hb.t)) << i;
    ASSERT_EQ(bits_of(ha.u), bits_of(hb.u)) << i;
    ASSERT_EQ(bits_of(ha.v), bits_of(hb.v)) << i;
    ASSERT_EQ(ha.primID, hb.primID) << i;
  }
  EXPECT_GT(hits, 500);
}

// Decoded triangles as sorted rows (the 9 coordinates' bits, geomID, face): equal for two scenes
// that hold the same triangles, whatever their order.
std::vector<std::array<uint32_t, 11>> rows(const DecodedTriangles& t) {
  std::vector<std::array<uint32_t, 11>> r(t.size());
  for (size_t i = 0; i < t.size(); ++i) {
    std::memcpy(r[i].data(), &t.vertices[3 * i], 36);
    r[i][9] = t.geom[i];
    r[i][10] = t.face[i];
  }
  std::sort(r.begin(), r.end());
  return r;
}

// Two scenes of the same triangles in other leaves hit the same: 20000 random rays, t bit for bit,
// the face too unless two faces meet at that t. face_of_b: a's face of each of b's faces (b built
// from a's mesh with its faces reordered), or null for the same faces.
void expect_same_t(const Scene& a, const Scene& b, uint64_t seed,
                   const std::vector<uint32_t>* face_of_b = nullptr) {
  Rng rng(seed);
  int hits = 0, ties = 0;
  for (int i = 0; i < 20000; ++i) {
    const Ray r = random_ray(rng, a.bounds());
    const Hit ha = a.intersect(r), hb = b.intersect(r);
    ASSERT_EQ(ha.valid(), hb.valid()) << "ray " << i;
    if (!ha.valid()) continue;
    ++hits;
    ASSERT_EQ(bits_of(ha.t), bits_of(hb.t)) << "ray " << i;
    ties += ha.primID != (face_of_b ? (*face_of_b)[hb.primID] : hb.primID);
  }
  EXPECT_GT(hits, 5000);
  EXPECT_LE(ties, 1 + hits / 1000);
}

// `m` with every coordinate printed with `digits` decimals and parsed back (as an OBJ file written
// with %.6f and read again): the nearest floats to decimals q x 10^-digits.
PolyMesh printed(PolyMesh m, int digits) {
  for (Vec3f& p : m.positions)
    for (int a = 0; a < 3; ++a) {
      char buf[64];
      std::snprintf(buf, sizeof buf, "%.*f", digits, double(p[a]));
      p[a] = std::strtof(buf, nullptr);
    }
  return m;
}

// The build-time source of the triangles of `tm` quantized as `z`.
ClusterSource source_of(const TriangleMesh& tm, const cluster::Quantized& z, bool lossless) {
  ClusterSource src;
  src.vertices = z.decoded.data();
  src.codes = z.codes.data();
  src.tris = tm.tris.data();
  src.geom_ids = tm.geom_ids.data();
  src.prim_ids = tm.prim_ids.data();
  src.lossless = lossless;
  src.lattice = z.lattice;  // the anchors' widths
  return src;
}

// A lossy icosphere of `level` as the cluster encoder's source (quantized with the default bound).
struct SphereSource {
  TriangleMesh tm;
  cluster::Quantized z;
  ClusterSource src;
  explicit SphereSource(int level) {
    PolyMesh sphere = icosphere(level);
    tm = triangulate_fan({&sphere});
    z = cluster::quantize(tm.vertices.data(), tm.vertices.size(), tm.tris.data(), tm.tri_count(),
                          1e-5, false);
    src = source_of(tm, z, false);
  }
};

// The stored form of a lossy multi-leaf's boxes (the coarse plane values and the scale bytes).
cluster::LatticeBoxes8 packed(const cluster::MultiLeafPlanes& mp) {
  cluster::LatticeBoxes8 lb{};
  cluster::pack_planes(mp.q, &lb, nullptr);
  std::memcpy(lb.scale, mp.scale, 3);
  return lb;
}

// The multi-leaf boxes of the cluster `data` (k children with the given boxes) as the builder
// writes them right ahead of it (cluster::write_multileaf_boxes): Boxes is cluster::LatticeBoxes8
// (lossy) or cluster::ExactBoxes8 (lossless), write(boxes, start, extent) the builder's frame,
// frame(p, start, extent) the traversal's. The two frames are equal, bound(axis, start, extent)
// checks each axis, the traversal's planes (AVX2 where built) are the structure check's, and
// every child's box decoded as the traversal decodes it contains the child's decoded triangles
// (all 8 lanes, the padding included).
// `ml` receives the boxes and the cluster behind them (a multi-leaf: the lossy clusters' per-child
// vertex ranges come from these boxes).
template <class Boxes, bool kLossless, class Write, class Frame, class Bound>
void check_multileaf_boxes(const std::vector<uint8_t>& data, const ClusterLattice& lat,
                           const Box3f* boxes, int k, Write&& write, Frame&& frame, Bound&& bound,
                           std::vector<uint8_t>& ml) {
  ml.assign(sizeof(Boxes) + data.size(), 0);
  std::memcpy(ml.data() + sizeof(Boxes), data.data(), data.size());
  auto& hb = *reinterpret_cast<Boxes*>(ml.data());
  float start[4], extent[4], s2[4], e2[4];
  ASSERT_TRUE(write(hb, start, extent));
  ASSERT_TRUE(cluster::write_multileaf_boxes(lat, kLossless, ml.data() + sizeof(Boxes), k, boxes,
                                             ml.data()));
  frame(ml.data(), s2, e2);
  ASSERT_EQ(std::memcmp(start, s2, 3 * sizeof(float)), 0);
  ASSERT_EQ(std::memcmp(extent, e2, 3 * sizeof(float)), 0);
  for (int a = 0; a < 3; ++a) bound(a, start[a], extent[a]);
  using Leaf = ClusterLeaf<kLossless>;
  uint8_t q[6][8];
  Leaf::multileaf_planes8(ml.data(), q);
  simd::vint8 v[6];
  Leaf::multileaf_planes(ml.data(), v);
  for (uint32_t i = 0; i < 6; ++i)
    for (int c = 0; c < 8; ++c) ASSERT_EQ(v[i][c], int(q[i][c])) << "plane " << i << " child " << c;
  if constexpr (!kLossless) {
    // Fine planes are the builder's 8-bit planes in its frame; coarse ones those rounded outward
    // to multiples of 4, taken where they grow the children's boxes by at most
    // kCoarsePlaneGrowth in surface area (the rule derived here again).
    uint8_t p8[6][8];
    quantize_planes(start, extent, boxes, k, p8);
    ClusterHeader h;
    std::memcpy(&h, data.data(), sizeof(h));
    const bool fine = cluster::has_fine_planes(h);
    double area = 0, coarse_area = 0;
    for (int c = 0; c < k; ++c) {
      double d[3], dc[3];
      for (int a = 0; a < 3; ++a) {
        const int lo = p8[2 * a][c], hi = p8[2 * a + 1][c];
        const int clo = lo - lo % 4, chi = hi - hi % 4 + 3;
        ASSERT_EQ(q[2 * a][c], fine ? lo : clo) << "child " << c << " axis " << a;
        ASSERT_EQ(q[2 * a + 1][c], fine ? hi : chi) << "child " << c << " axis " << a;
        d[a] = double(hi - lo) * extent[a];
        dc[a] = double(chi - clo) * extent[a];
      }
      area += d[0] * d[1] + d[1] * d[2] + d[2] * d[0];
      coarse_area += dc[0] * dc[1] + dc[1] * dc[2] + dc[2] * dc[0];
    }
    EXPECT_EQ(fine, coarse_area > (1.0 + cluster::kCoarsePlaneGrowth) * area);
  }
  for (int c = 0; c < k; ++c) {
    const Box3f b = dequantize_planes(q, s2, e2, c);
    cluster::Decoded8 d;
    cluster::decode_child<kLossless>(lat, ml.data() + sizeof(Boxes), uint32_t(k), c, d);
    for (int l = 0; l < 8; ++l)
      for (int q = 0; q < 3; ++q)
        ASSERT_TRUE(b.contains(Vec3f(d.v[q][0][l], d.v[q][1][l], d.v[q][2][l])))
            << "child " << c << " lane " << l;
  }
}

// Encodes the triangles of `tm` in clusters of random shape (1..8 children of 1..8 triangles;
// `full`: 8 children of 8, 64 triangles, as the builder makes most clusters; in the order of
// `order`) and checks that every child decodes to the source's positions and ids bit
// for bit. *decimal (if given) receives the count of clusters in the lossless decimal mode,
// *clusters the count of clusters, *wide the count of children with per-child vertex ranges whose
// vertices take more than 32 bits.
void check_codec(const TriangleMesh& tm, bool lossless, double rel_error, uint32_t seed,
                 bool shuffle, size_t* decimal = nullptr, size_t* clusters_out = nullptr,
                 std::vector<ClusterHeader>* headers = nullptr, bool full = false,
                 size_t* wide = nullptr) {
  const cluster::Quantized z = cluster::quantize(
      tm.vertices.data(), tm.vertices.size(), tm.tris.data(), tm.tri_count(), rel_error, lossless);
  ClusterSource src = source_of(tm, z, lossless);
  std::vector<uint32_t> order(tm.tri_count());
  std::iota(order.begin(), order.end(), 0u);
  std::mt19937 rng(seed);
  if (shuffle) std::shuffle(order.begin(), order.end(), rng);
  size_t pos = 0, clusters = 0;
  while (pos < order.size()) {
    const int k = full ? 8 : 1 + int(rng() % 8);
    const uint32_t* prims[8];
    uint32_t counts[8];
    int kk = 0;
    for (; kk < k && pos < order.size(); ++kk) {
      counts[kk] = std::min<uint32_t>(full ? 8 : 1 + rng() % 8, uint32_t(order.size() - pos));
      prims[kk] = &order[pos];
      pos += counts[kk];
    }
    // As the builder encodes a multi-leaf's cluster (lossy: with per-child vertex ranges when
    // they are smaller).
    std::vector<uint8_t> data = cluster::encode(src, prims, counts, kk, true, true);
    ClusterHeader hdr;
    std::memcpy(&hdr, data.data(), sizeof(hdr));
    if (!lossless) {
      ASSERT_EQ(cluster::coord_mode(hdr), 0u);
    }
    if (decimal) *decimal += cluster::coord_mode(hdr) != 0;
    if (headers) headers->push_back(hdr);
    // The multi-leaf boxes as the builder writes them, right ahead of the cluster.
    Box3f boxes[8], all;
    for (int c = 0; c < kk; ++c) {
      for (uint32_t j = 0; j < counts[c]; ++j)
        for (int q = 0; q < 3; ++q)
          boxes[c].extend(z.decoded[tm.tris[3 * size_t(prims[c][j]) + q]]);
      all.extend(boxes[c]);
    }
    std::vector<uint8_t> ml;  // the boxes, then the cluster
    if (!lossless) {
      // On the lattice: the extent at most 1/8 above the smallest that reaches the cluster's top
      // (one scale byte).
      check_multileaf_boxes<cluster::LatticeBoxes8, false>(
          data, z.lattice, boxes, kk,
          [&](cluster::LatticeBoxes8& lb, float* start, float* extent) {
            return cluster::write_box_frame(z.lattice, data.data(), all, lb, start, extent);
          },
          [&](const uint8_t* p, float* start, float* extent) {
            cluster::box_frame(cluster::lattice_frame(z.lattice), p, start, extent);
          },
          [&](int a, float start, float extent) {
            const double need = (double(all.hi[a]) - double(start)) / 255.0;
            EXPECT_LE(double(extent), std::max(1.125 * need, double(z.lattice.step[a])) * 1.0001);
          },
          ml);
    } else {
      // From the stream's start floats: the cluster's lowest coordinate exactly (a vertex's), the
      // extent at most 1/128 above the exact 1/255 of the span
      // (one bfloat16), or the least normal float.
      check_multileaf_boxes<cluster::ExactBoxes8, true>(
          data, z.lattice, boxes, kk,
          [&](cluster::ExactBoxes8& eb, float* start, float* extent) {
            return cluster::write_exact_box_frame(data.data(), all, eb, start, extent);
          },
          [&](const uint8_t* p, float* start, float* extent) {
            cluster::exact_box_frame(p, start, extent);
          },
          [&](int a, float start, float extent) {
            EXPECT_EQ(bits_of(start), bits_of(all.lo[a])) << "axis " << a;
            const double need = (double(all.hi[a]) - double(start)) / 255.0;
            EXPECT_LE(double(extent), std::max(need * (1.0 + 1.0 / 64), 1.2e-38)) << "axis " << a;
          },
          ml);
    }
    ASSERT_FALSE(::testing::Test::HasFatalFailure());
    // From here on the cluster is the one behind its boxes.
    const size_t head = lossless ? sizeof(cluster::ExactBoxes8) : sizeof(cluster::LatticeBoxes8);
    data.assign(ml.begin() + ptrdiff_t(head), ml.end());
    std::string why;
    ASSERT_TRUE(cluster::check(ml.data() + head, data.size() - kClusterReadSlack, uint32_t(kk),
                               z.lattice, lossless, &why, lossless ? nullptr : ml.data()))
        << why;
    if (cluster::has_ranges(hdr) && !lossless) {
      // Without its boxes the ranges have no source: check() refuses the cluster.
      EXPECT_FALSE(cluster::check(ml.data() + head, data.size() - kClusterReadSlack, uint32_t(kk),
                                  z.lattice, lossless, &why));
    }
    const uint8_t* cd = ml.data() + head;
    // One view of the cluster serves all its children (as in the traversal).
    const cluster::View view = lossless ? cluster::view<true>(z.lattice, cd, uint32_t(kk))
                                        : cluster::view<false>(z.lattice, cd, uint32_t(kk));
    if (wide && view.ranges)
      for (int c = 0; c < kk; ++c) *wide += view.r.w[c] > 32;
    if (!lossless) {
      // The traversal's vertex decode (AVX2 where built) gives the scalar decode's bits.
      for (int c = 0; c < kk; ++c) {
        cluster::Decoded8 d, ds;
        cluster::decode_child<false>(z.lattice, view, c, d);
        cluster::decode_child<false, true>(z.lattice, view, c, ds);
        ASSERT_EQ(std::memcmp(d.v, ds.v, sizeof(d.v)), 0) << "child " << c;
      }
    }
#if defined(SLIM_SIMD_AVX2)
    if (view.ranges) {
      // The AVX2 ranges (the traversal's view) equal the scalar ones (check()'s).
      cluster::LatticeBoxes8 lb;
      std::memcpy(&lb, ml.data(), sizeof(lb));
      uint8_t q[6][8];
      cluster::lattice_planes(ml.data(), cluster::plane_lows(cd), q);
      const cluster::Layout L0 = cluster::layout(hdr, uint32_t(kk), z.lattice, false);
      cluster::ChildRanges rs;
      cluster::child_ranges(hdr, L0, cluster::stream_of(cd), view.anchor, q, lb.scale, uint32_t(kk),
                            rs);
      const cluster::ChildRanges& rv = view.r;
      ASSERT_EQ(rs.total, rv.total);
      ASSERT_EQ(rs.wmax, rv.wmax);
      for (int c = 0; c < 8; ++c) {
        ASSERT_EQ(rs.first[c], rv.first[c]) << c;
        ASSERT_EQ(rs.pos[c], rv.pos[c]) << c;
        ASSERT_EQ(rs.w[c], rv.w[c]) << c;
        for (int a = 0; a < 3; ++a) {
          ASSERT_EQ(rs.radix[a][c], rv.radix[a][c]) << c << " " << a;
          ASSERT_EQ(rs.base[a][c], rv.base[a][c]) << c << " " << a;
        }
      }
    }
#endif
    for (int c = 0; c < kk; ++c) {
      cluster::Decoded8 d, dv;
      if (lossless) {
        cluster::decode_child<true>(z.lattice, cd, uint32_t(kk), c, d);
        cluster::decode_child<true>(z.lattice, view, c, dv);
      } else {
        cluster::decode_child<false>(z.lattice, cd, uint32_t(kk), c, d);
        cluster::decode_child<false>(z.lattice, view, c, dv);
      }
      ASSERT_EQ(d.n, int(counts[c]));
      ASSERT_EQ(dv.n, d.n);
      ASSERT_EQ(dv.first, d.first);
      ASSERT_EQ(std::memcmp(dv.v, d.v, sizeof(d.v)), 0) << "child " << c;
      // The strip order is the encoder's: the child's triangles (positions and ids) as multisets.
      std::vector<std::vector<uint32_t>> got, want;
      for (int l = 0; l < d.n; ++l) {
        uint32_t g, p;
        if (lossless)
          cluster::decode_ids<true>(z.lattice, cd, uint32_t(kk), uint32_t(d.first + l), g, p);
        else
          cluster::decode_ids<false>(z.lattice, cd, uint32_t(kk), uint32_t(d.first + l), g, p);
        uint32_t gv, pv;
        cluster::decode_ids(view, uint32_t(d.first + l), gv, pv);
        ASSERT_EQ(gv, g);
        ASSERT_EQ(pv, p);
        std::vector<uint32_t> row = {g, p};
        for (int j = 0; j < 3; ++j)
          for (int a = 0; a < 3; ++a) row.push_back(bits_of(d.v[j][a][l]));
        got.push_back(row);
        const uint32_t t = prims[c][l];
        row = {tm.geom_ids[t], tm.prim_ids[t]};
        for (int j = 0; j < 3; ++j)
          for (int a = 0; a < 3; ++a) {
            const uint32_t vi = tm.tris[3 * size_t(t) + j];
            row.push_back(bits_of(z.decoded[vi][a]));
            if (lossless) {
              ASSERT_EQ(bits_of(z.decoded[vi][a]), bits_of(tm.vertices[vi][a]));
            }
          }
        want.push_back(row);
      }
      std::sort(got.begin(), got.end());
      std::sort(want.begin(), want.end());
      ASSERT_EQ(got, want);
      // Padding lanes repeat the last triangle.
      for (int l = d.n; l < 8; ++l)
        for (int j = 0; j < 3; ++j)
          for (int a = 0; a < 3; ++a) ASSERT_EQ(bits_of(d.v[j][a][l]), bits_of(d.v[j][a][d.n - 1]));
    }
    clusters++;
  }
  EXPECT_GT(clusters, 0u);
  if (clusters_out) *clusters_out += clusters;
}

TEST(ClusterCodec, DecodeEqualsEncodeRandomMeshes) {
  PolyMesh soup = random_soup(3000, 11);
  PolyMesh sphere = icosphere(3);
  // A third mesh with ids and coordinates far from the others (wide id and code ranges).
  PolyMesh far = random_soup(500, 12, 0.3f);
  for (Vec3f& p : far.positions) p = p * 1000.0f - Vec3f(5000.0f, -20.0f, 3.0f);
  for (bool lossless : {false, true}) {
    TriangleMesh tm = triangulate_fan({&soup, &sphere, &far});
    check_codec(tm, lossless, 1e-5, 1, true);
    check_codec(tm, lossless, 1e-5, 2, false);
    check_codec(tm, lossless, 1e-2, 3, false);
  }
}

// The primID runs (cluster.h): every triangle's ids decode to the input's where a cluster's ids
// fall into long runs of nearby ids far apart (several runs of width 2^ob > 1, Elias-Fano run
// starts with low bits and high parts), in random order (one run per triangle), near the top of
// the id range, and with ids shared by neighbouring triangles (quads: the repeat bits).
TEST(ClusterCodec, DecodeEqualsEncodeIdRuns) {
  PolyMesh soup = random_soup(2000, 41);
  PolyMesh sphere = icosphere(3);
  TriangleMesh tm = triangulate_fan({&soup, &sphere});
  struct Case {
    uint32_t run, stride, gap, base;  // face f's id: runs of `run` ids `stride` apart, the runs
                                      // `gap` apart from `base` on (mod 2^32)
    bool shuffle;
    uint32_t share = 1;  // triangles t of one face f = t / share
  };
  for (const Case& k : {Case{6, 1, 100000, 7, false}, Case{4, 3, 777, 0, false},
                        Case{5, 2, 1u << 20, 0xfff00000u, false}, Case{1, 1, 1, 0, true},
                        Case{8, 1, 40, 12345, true}, Case{3, 1, 5000, 9, false, 2},
                        Case{1, 1, 1, 0, false, 3}, Case{1, 1, 1, 0, true, 2}}) {
    for (size_t t = 0; t < tm.tri_count(); ++t) {
      const uint32_t f = uint32_t(t / k.share);
      tm.prim_ids[t] = k.base + (f / k.run) * k.gap + (f % k.run) * k.stride;
    }
    for (bool lossless : {false, true}) {
      std::vector<ClusterHeader> headers;
      check_codec(tm, lossless, 1e-5, 5 + k.run, k.shuffle, nullptr, nullptr, &headers);
      ASSERT_FALSE(::testing::Test::HasFatalFailure());
      size_t wide = 0, highs = 0, repeats = 0, steps = 0, singles = 0, doubles = 0;
      for (const ClusterHeader& h : headers) {
        wide += cluster::run_count(h) > 1 && cluster::offset_bits(h) > 0;
        highs += cluster::run_count(h) > 2;
        repeats += cluster::has_repeats(h) && !cluster::has_steps(h);
        steps += cluster::has_steps(h);
        singles += cluster::id_flag_planes(h) == 2;
        doubles += cluster::id_flag_planes(h) == 3;
      }
      // Faces numbered two or three apart: the double steps take strip neighbours; shuffled,
      // almost never.
      if (!k.shuffle && k.stride > 1 && k.share == 1) {
        EXPECT_GT(doubles, 0u) << k.run << " " << k.stride;
      }
      if (k.shuffle) {
        EXPECT_LE(doubles, headers.size() / 10) << k.run;
      }
      // Faces numbered in order one apart (stride 1): strip neighbours often differ by one, and
      // the step bits take them (two planes in some clusters at least); shuffled, almost never.
      if (!k.shuffle && k.stride == 1 && k.share == 1 && k.run > 4) {
        EXPECT_GT(singles, 0u) << k.run;
      }
      if (k.shuffle) {
        EXPECT_LE(steps, headers.size() / 10) << k.run;
      }
      // In order: runs of ids (their offsets, or step bits within them); shuffled (dense ids):
      // one run (base + offset) in most clusters.
      if (!k.shuffle && k.run > 1) {
        EXPECT_GT(wide + steps, headers.size() / 2) << k.run << " " << k.gap;
        EXPECT_GT(highs, headers.size() / 2) << k.run << " " << k.gap;
      }
      if (k.share > 1 && !k.shuffle) {  // shared ids: repeat bits (alone or with step bits)
        EXPECT_GT(repeats + steps, headers.size() / 2) << k.share;
      }
      if (k.share == 1 || k.shuffle) {
        EXPECT_EQ(repeats, 0u);
      }
      if (k.run > 1 || k.shuffle) {
        EXPECT_GT(highs, 0u) << k.run << " " << k.gap;
      }
    }
  }
}

// Full clusters (8 children of 8 triangles, the most a cluster holds): decode equals encode, with
// repeat bits (two triangles a face) and without, in mesh and in random order.
TEST(ClusterCodec, DecodeEqualsEncodeFullClusters) {
  PolyMesh sphere = icosphere(4);
  PolyMesh soup = random_soup(1000, 43);
  TriangleMesh tm = triangulate_fan({&sphere, &soup});
  for (uint32_t share : {1u, 2u})
    for (bool shuffle : {false, true}) {
      for (size_t t = 0; t < tm.tri_count(); ++t) tm.prim_ids[t] = uint32_t(t / share);
      for (bool lossless : {false, true}) {
        std::vector<ClusterHeader> headers;
        check_codec(tm, lossless, 1e-5, 7 + share, shuffle, nullptr, nullptr, &headers, true);
        ASSERT_FALSE(::testing::Test::HasFatalFailure());
        size_t full = 0, repeats = 0, ranged = 0;
        for (const ClusterHeader& h : headers) {
          full += cluster::tri_count(h, 8) == 64;
          repeats += cluster::has_repeats(h);
          ranged += !lossless && cluster::has_ranges(h);
        }
        EXPECT_GE(full, headers.size() - 1);
        if (!lossless && !shuffle) {
          // Children of nearby triangles: their ranges are smaller than the cluster's.
          EXPECT_GT(ranged, headers.size() / 2);
        }
        if (share == 2 && !shuffle) {
          EXPECT_GT(repeats, 0u);  // the soup's clusters: its strips follow the input order
        }
      }
    }
}

// The strip search prefers triangles whose ids follow the last one's (prim/cluster.cpp): a closed
// fan of six triangles numbered 10..15 around its center, given to the encoder as one child in
// the order 10, 15, 11, 12, 13, 14. From triangle 10 the first neighbour in that order is 15, and
// a strip that takes it first has a triangle whose id does not follow (15 after 10); the strip
// 10, 11, ..., 15 has none, and no more restarts.
TEST(ClusterCodec, StripsFollowTheIds) {
  PolyMesh fan;
  fan.positions.push_back({0.0f, 0.0f, 0.0f});
  for (int i = 0; i < 6; ++i) {
    const double a = 2.0 * M_PI * i / 6;
    fan.positions.push_back({float(std::cos(a)), float(std::sin(a)), 0.1f * float(i % 2)});
  }
  for (uint32_t i = 0; i < 6; ++i) {
    fan.face_sizes.push_back(3);
    for (uint32_t v : {0u, 1 + i, 1 + (i + 1) % 6}) fan.face_indices.push_back(v);
  }
  TriangleMesh tm = triangulate_fan({&fan});
  ASSERT_EQ(tm.tri_count(), 6u);
  for (uint32_t t = 0; t < 6; ++t) tm.prim_ids[t] = 10 + t;
  for (bool lossless : {false, true}) {
    const cluster::Quantized z = cluster::quantize(tm.vertices.data(), tm.vertices.size(),
                                                   tm.tris.data(), tm.tri_count(), 1e-5, lossless);
    const ClusterSource src = source_of(tm, z, lossless);
    const uint32_t order[6] = {0, 5, 1, 2, 3, 4}, count = 6;
    const uint32_t* prims = order;
    const std::vector<uint8_t> data = cluster::encode(src, &prims, &count, 1, true);
    std::string why;
    ASSERT_TRUE(
        cluster::check(data.data(), data.size() - kClusterReadSlack, 1, z.lattice, lossless, &why))
        << why;
    std::vector<uint32_t> ids;
    for (uint32_t t = 0; t < 6; ++t) {
      uint32_t g, p;
      if (lossless)
        cluster::decode_ids<true>(z.lattice, data.data(), 1, t, g, p);
      else
        cluster::decode_ids<false>(z.lattice, data.data(), 1, t, g, p);
      ids.push_back(p);
    }
    // Ascending or descending: both strips follow the ids.
    if (ids[0] > ids[5]) std::reverse(ids.begin(), ids.end());
    EXPECT_EQ(ids, (std::vector<uint32_t>{10, 11, 12, 13, 14, 15})) << lossless;
  }
}

// Lossless clusters of decimal coordinates (cluster.h, the decimal mode): meshes whose coordinates
// were printed with 0 to 6 decimals and parsed back decode bit for bit, mostly in the decimal mode;
// where one vertex in 40 is one float step off its decimal, the clusters that hold such a vertex
// keep the float keys and still decode bit for bit.
TEST(ClusterCodec, DecodeEqualsEncodeDecimalMeshes) {
  PolyMesh soup = random_soup(3000, 31);
  PolyMesh sphere = icosphere(3);
  for (Vec3f& p : sphere.positions) p = p * 37.0f - Vec3f(3.0f, 100.0f, -0.5f);
  PolyMesh far = random_soup(500, 32, 0.3f);
  for (Vec3f& p : far.positions) p = p * 1000.0f - Vec3f(5000.0f, -20.0f, 3.0f);
  struct Case {
    std::vector<PolyMesh> meshes;
    bool mixed;
  };
  std::vector<Case> cases;
  cases.push_back({{printed(soup, 6), printed(sphere, 4), printed(far, 2)}, false});
  cases.push_back({{printed(soup, 3), printed(sphere, 0), printed(far, 1)}, false});
  cases.push_back({{printed(soup, 6), printed(sphere, 5)}, true});
  for (Case& c : cases) {
    if (c.mixed)
      for (PolyMesh& m : c.meshes)
        for (size_t i = 0; i < m.positions.size(); i += 40)
          m.positions[i].y = std::nextafter(m.positions[i].y, 1e30f);
    std::vector<const PolyMesh*> ptrs;
    for (const PolyMesh& m : c.meshes) ptrs.push_back(&m);
    TriangleMesh tm = triangulate_fan(ptrs);
    size_t decimal = 0, clusters = 0;
    check_codec(tm, true, 1e-5, 7, true, &decimal, &clusters);
    check_codec(tm, true, 1e-5, 8, false, &decimal, &clusters);
    std::printf("  decimal clusters: %zu of %zu%s\n", decimal, clusters,
                c.mixed ? " (one vertex in 40 off its decimal)" : "");
    EXPECT_GT(decimal, clusters / 2);
    if (c.mixed) {
      EXPECT_LT(decimal, clusters);
    }
  }
}

// The decimal mode's choice on single triangles: per axis the smallest number of digits that gives
// every coordinate back (at least the cluster's less 3), and the float keys where none does (a
// float off its decimal, -0) or where they take fewer bits.
TEST(ClusterCodec, DecimalModeDigits) {
  auto mode_of = [](std::array<float, 9> c) {
    PolyMesh m;
    m.positions = {Vec3f(c[0], c[1], c[2]), Vec3f(c[3], c[4], c[5]), Vec3f(c[6], c[7], c[8])};
    m.face_indices = {0, 1, 2};
    m.face_sizes = {3};
    const TriangleMesh tm = triangulate_fan({&m});
    const cluster::Quantized z =
        cluster::quantize(tm.vertices.data(), tm.vertices.size(), tm.tris.data(), 1, 1e-5, true);
    ClusterSource src = source_of(tm, z, true);
    const uint32_t prim = 0, count = 1;
    const uint32_t* prims = &prim;
    const std::vector<uint8_t> data = cluster::encode(src, &prims, &count, 1, true);
    std::string why;
    EXPECT_TRUE(
        cluster::check(data.data(), data.size() - kClusterReadSlack, 1, z.lattice, true, &why))
        << why;
    cluster::Decoded8 d;
    cluster::decode_child<true>(z.lattice, data.data(), 1, 0, d);
    for (int k = 0; k < 3; ++k)
      for (int a = 0; a < 3; ++a)
        EXPECT_EQ(bits_of(d.v[k][a][0]), bits_of(tm.vertices[tm.tris[k]][a]));
    ClusterHeader h;
    std::memcpy(&h, data.data(), sizeof(h));
    if (cluster::coord_mode(h))  // the axes' digits, the cluster's k the largest
      return std::array<uint32_t, 4>{cluster::coord_mode(h), cluster::axis_digits(h, 0),
                                     cluster::axis_digits(h, 1), cluster::axis_digits(h, 2)};
    return std::array<uint32_t, 4>{0, 0, 0, 0};
  };
  using A = std::array<uint32_t, 4>;
  EXPECT_EQ(mode_of({0.1f, 0.2f, 0.3f, 1.5f, -2.25f, 0.7f, 1.0f, 0.0f, 3.0f}), (A{3, 1, 2, 1}));
  EXPECT_EQ(mode_of({0.1f, 0.2f, 0.3f, 1.5f, -2.2f, 0.7f, 1.0f, 0.0f, 3.0f}), (A{2, 1, 1, 1}));
  EXPECT_EQ(mode_of({-0.777853f, 2.740647f, 3.930020f, -0.777854f, 2.740647f, 3.930021f, -0.777855f,
                     2.740649f, 3.930022f}),
            (A{7, 6, 6, 6}));
  EXPECT_EQ(mode_of({100.0f, 2000.0f, -30.0f, 101.0f, 2001.0f, -31.0f, 103.0f, 2000.0f, -29.0f}),
            (A{1, 0, 0, 0}));
  // %g with 6 significant digits: x near 100 with 3 decimals, y near 8 with 5, z near 0.05 with 6.
  EXPECT_EQ(mode_of({101.87f, 8.88925f, 0.050586f, 102.012f, 8.91352f, 0.050726f, 102.155f,
                     8.88921f, 0.050585f}),
            (A{7, 3, 5, 6}));
  // Axes at most 3 digits below the cluster's k: x takes 3 digits for 6 (x with 0 would do).
  EXPECT_EQ(
      mode_of({101.0f, 8.889f, 0.050586f, 102.0f, 8.913f, 0.050726f, 103.0f, 8.889f, 0.050585f}),
      (A{7, 3, 3, 6}));
  // One float step above 0.001 (steps of 1.2e-10): 9 digits do not give it back.
  EXPECT_EQ(
      mode_of({0.1f, 0.2f, std::nextafter(0.001f, 1.0f), 1.5f, -2.2f, 0.7f, 1.0f, 0.0f, 3.0f}),
      (A{0, 0, 0, 0}));
  // One float step above 3 (steps of 2.4e-7) takes 7 digits, which raises x and y from 2 to 4
  // (3 at most below the cluster's k): still fewer bits than the keys.
  EXPECT_EQ(mode_of({3.0f, 3.5f, 3.25f, 3.5f, 3.0f, 3.0f, 3.25f, 3.75f, 3.5f}), (A{3, 2, 2, 2}));
  EXPECT_EQ(
      mode_of({3.0f, 3.5f, 3.25f, 3.5f, 3.0f, std::nextafter(3.0f, 4.0f), 3.25f, 3.75f, 3.5f}),
      (A{8, 4, 4, 7}));
  // Beyond 2^31 x 10^-k: 2.5 x 10^9 needs 0 digits but does not fit 32 bits.
  EXPECT_EQ(mode_of({0.5f, 0.25f, 2.5e9f, 1.5f, -2.25f, 0.75f, 1.0f, 0.0f, 3.0f}), (A{0, 0, 0, 0}));
  // -0 is not a decimal (q = 0 decodes to +0).
  EXPECT_EQ(mode_of({0.1f, 0.2f, -0.0f, 1.5f, -2.2f, 0.7f, 1.0f, 0.0f, 3.0f}), (A{0, 0, 0, 0}));
}

// A lossless cluster's anchors from its start floats: the float keys, or the decimal codes
// round(f x 10^k) under any rounding mode (the encoder's codes), -2^31 (kNoDecimal, which check()
// rejects) beyond 32 bits.
TEST(ClusterCodec, LosslessAnchorFromTheStartFloat) {
  auto bits = [](float f) { return bits_of(f); };
  const float inf = std::numeric_limits<float>::infinity();
  for (float f : {0.0f, -0.0f, 1.5f, -2.25f, 1e-40f, inf, -inf})
    EXPECT_EQ(cluster::lossless_anchor(bits(f), 0, 0), cluster::float_key(f)) << f;
  for (int mode : {FE_TONEAREST, FE_DOWNWARD, FE_UPWARD, FE_TOWARDZERO}) {
    ASSERT_EQ(std::fesetround(mode), 0);
    volatile float seven = 0.7f, minus = -0.7f, hundred = 100.0f, big = 3e9f, digits = 1.0001f;
    EXPECT_EQ(cluster::lossless_anchor(bits(seven), 2, 1), 7u) << mode;  // 0.69999998807907
    EXPECT_EQ(cluster::lossless_anchor(bits(minus), 2, 1), uint32_t(-7)) << mode;
    EXPECT_EQ(cluster::lossless_anchor(bits(hundred), 1, 0), 100u) << mode;
    EXPECT_EQ(cluster::lossless_anchor(bits(digits), 5, 4), 10001u) << mode;
    EXPECT_EQ(cluster::lossless_anchor(bits(big), 1, 0), 0x80000000u) << mode;
    EXPECT_EQ(cluster::lossless_anchor(bits(std::numeric_limits<float>::quiet_NaN()), 1, 0),
              0x80000000u);
    EXPECT_EQ(cluster::lossless_anchor(bits(inf), 1, 0), 0x80000000u);
  }
  std::fesetround(FE_TONEAREST);
}

TEST(ClusterCodec, DecodeEqualsEncodeRealMesh) {
  SLIM_REQUIRE_SHARED_DATA();
  PolyMesh m = load(shared_data_dir() + "/stanford_bunny.obj.xz");  // %f decimals
  TriangleMesh tm = triangulate_fan({&m});
  for (bool lossless : {false, true}) {
    size_t decimal = 0, clusters = 0, wide = 0;
    check_codec(tm, lossless, 1e-5, 4, false, &decimal, &clusters, nullptr, false, &wide);
    if (!lossless) {
      // Mixed-radix vertices of more than 32 bits (the encoder's second field) occur.
      std::printf("  bunny: %zu children with vertices of more than 32 bits\n", wide);
      EXPECT_GT(wide, 0u);
    }
    if (lossless) {
      std::printf("  bunny: %zu of %zu clusters decimal\n", decimal, clusters);
      EXPECT_GT(decimal, clusters * 9 / 10);
    }
  }
}

// Encodes three one-triangle children of the six vertices `codes` (lattice steps 1, anchor widths
// `bits`): children 0 and 1 narrow (their ranges win), child 2 spanning the cluster with old
// vertices. Expects check() to accept the cluster behind its multi-leaf boxes and returns whether
// it took per-child vertex ranges; children 0 and 1 alone must take them.
bool ranges_of_three_children(const std::vector<uint32_t>& codes, const uint8_t (&bits)[3]) {
  ClusterLattice lat;  // steps 1
  for (int a = 0; a < 3; ++a) lat.anchor_bits[a] = bits[a];
  std::vector<Vec3f> decoded(6);
  for (int i = 0; i < 6; ++i)
    for (int a = 0; a < 3; ++a) decoded[i][a] = cluster::lattice_coord(lat, a, codes[3 * i + a]);
  const std::vector<uint32_t> tris = {0, 1, 2, 3, 4, 5, 0, 3, 1};
  const std::vector<uint32_t> geom(3, 0), prim = {0, 1, 2};
  const ClusterSource src{decoded.data(), codes.data(), tris.data(), geom.data(),
                          prim.data(),    false,        lat};
  const uint32_t p[3] = {0, 1, 2}, counts[3] = {1, 1, 1};
  const uint32_t* prims[3] = {&p[0], &p[1], &p[2]};
  const std::vector<uint8_t> enc = cluster::encode(src, prims, counts, 3, true, true);
  const uint32_t anchor[3] = {0, 0, 0};
  cluster::MultiLeafPlanes mp;
  EXPECT_TRUE(cluster::multileaf_boxes(src, prims, counts, 3, anchor, mp));
  const cluster::LatticeBoxes8 lb = packed(mp);
  std::vector<uint8_t> ml(sizeof(lb) + enc.size());
  std::memcpy(ml.data(), &lb, sizeof(lb));
  std::memcpy(ml.data() + sizeof(lb), enc.data(), enc.size());
  std::string why;
  EXPECT_TRUE(cluster::check(ml.data() + sizeof(lb), enc.size() - kClusterReadSlack, 3, lat, false,
                             &why, ml.data()))
      << why;
  ClusterHeader h;
  std::memcpy(&h, cluster::encode(src, prims, counts, 2, true, true).data(), sizeof(h));
  EXPECT_TRUE(cluster::has_ranges(h));
  std::memcpy(&h, enc.data(), sizeof(h));
  return cluster::has_ranges(h);
}

// Per-child vertex ranges: a child without new vertices whose range needs more than 24 bits (a
// cluster spanning the whole 24-bit lattice) keeps the cluster out of the ranges, so that check()
// accepts every cluster the encoder writes.
TEST(ClusterCodec, RangesKeepEveryChildWithin24Bits) {
  const uint32_t T = (1u << 24) - 1;
  EXPECT_FALSE(ranges_of_three_children({0, 0, 0, 1, 1, 0, 0, 1, 1, T, 0, 0, T - 1, 1, 0, T, 1, 1},
                                        {24, 1, 1}));
}

// The same for the vertex width: a child without new vertices whose box spans some 2^20 steps on
// every axis (within 2^24 each, but 60 bits a vertex) keeps the cluster out of the ranges.
TEST(ClusterCodec, RangesKeepEveryChildWithin52Bits) {
  const uint32_t T = 1u << 20;
  EXPECT_FALSE(ranges_of_three_children(
      {0, 0, 0, 1, 0, 0, 0, 1, 0, T, T, T, T - 1, T, T, T, T - 1, T}, {21, 21, 21}));
}

// The AVX2 decoder's mixed-radix digits are the integer quotients and remainders for any vertex
// of up to kMaxRangeVertexBits bits (the division in doubles), or of up to kFloatRadixBits where
// every child's vertices are that narrow (in floats), the widest included: three children, the
// widest with radices whose product is just below 2^52 (2^23), vertices from 0 to 2^w - 1
// (numbers at or above the product too: a damaged block's digit beyond its radix decodes alike).
TEST(ClusterCodec, MixedRadixDigitsAtTheWidestVertices) {
#if defined(SLIM_SIMD_AVX2)
  auto run = [](const uint32_t(&radix)[3][3], uint32_t widest) {
    cluster::ChildRanges r{};
    std::mt19937_64 rng(7);
    std::vector<uint64_t> m;
    std::vector<uint8_t> bits(1024, 0);
    uint64_t pos = 0;
    for (uint32_t c = 0; c < 8; ++c) {
      r.first[c] = c < 3 ? 8 * c : cluster::kNoChildVertex;
      r.w[c] = c < 3 ? cluster::radix_bits(radix[c][0], radix[c][1], radix[c][2]) : 0;
      r.wmax = std::max(r.wmax, r.w[c]);
      for (int a = 0; a < 3; ++a) {
        r.radix[a][c] = c < 3 ? radix[c][a] : 1;
        r.base[a][c] = 1000 * (c + 1) + uint32_t(a);
      }
      if (c >= 3) continue;
      r.pos[c] = uint32_t(pos - uint64_t(r.first[c]) * r.w[c]);
      for (int i = 0; i < 8; ++i) {
        const uint64_t top = (uint64_t(1) << r.w[c]) - 1;
        // 0, the largest, numbers one below a multiple of R_x and of R_x R_y (a quotient's
        // boundary), random ones.
        const uint64_t px = radix[c][0], pxy = px * radix[c][1], k = rng() & top;
        const uint64_t below_x = k / px * px, below_xy = k / pxy * pxy;
        const uint64_t v = i == 0   ? 0
                           : i == 1 ? top
                           : i == 2 ? (below_x ? below_x - 1 : top)
                           : i == 3 ? (below_xy ? below_xy - 1 : top)
                                    : k;
        m.push_back(v);
        for (uint32_t b = 0; b < r.w[c]; ++b, ++pos)
          if ((v >> b) & 1) bits[pos >> 3] |= uint8_t(1u << (pos & 7));
      }
    }
    ASSERT_EQ(r.wmax, widest);
    ClusterLattice lat;
    for (int a = 0; a < 3; ++a) lat.step[a] = 0.25f;
    for (int t0 = 0; t0 < 24; t0 += 8) {
      alignas(32) uint32_t tri[8];
      for (int l = 0; l < 8; ++l) {
        const uint32_t v0 = uint32_t(t0 + l), v1 = uint32_t((t0 + l + 9) % 24),
                       v2 = uint32_t((t0 + 5 * l + 17) % 24);
        tri[l] = v0 | v1 << 8 | v2 << 16;
      }
      cluster::Decoded8 d;
      d.n = 8;
      cluster::decode_vertices_ranges_avx2(lat, bits.data(), r, tri, d);
      for (int l = 0; l < 8; ++l)
        for (int k = 0; k < 3; ++k) {
          const uint32_t v = (tri[l] >> (8 * k)) & 0xff, c = v / 8;
          const uint64_t x = m[v], t = x / radix[c][0], z = t / radix[c][1];
          const uint64_t o[3] = {x % radix[c][0], t % radix[c][1], z};
          for (int a = 0; a < 3; ++a)
            ASSERT_EQ(bits_of(d.v[k][a][l]),
                      bits_of(cluster::lattice_coord(lat, a, r.base[a][c] + uint32_t(o[a]))))
                << "vertex " << v << " axis " << a;
        }
    }
  };
  const uint32_t wide[3][3] = {{100003, 77777, 500009}, {1, 1, 1}, {4097, 3, 65536}};
  run(wide, cluster::kMaxRangeVertexBits);
  const uint32_t powers[3][3] = {{1u << 24, 1u << 24, 16}, {2, 3, 1u << 24}, {1, 1, 1}};
  run(powers, cluster::kMaxRangeVertexBits);
  const uint32_t narrow[3][3] = {{2047, 4095, 1}, {1, 1, 1}, {3, 5, 7}};
  run(narrow, cluster::kFloatRadixBits);
  const uint32_t narrow_powers[3][3] = {{2048, 4096, 1}, {1, 2, 3}, {1, 1, 1}};
  run(narrow_powers, cluster::kFloatRadixBits);
#else
  GTEST_SKIP() << "AVX2 decoder not built";
#endif
}

// check() of a cluster with per-child vertex ranges: its boxes' scales, its children's radices
// (at most 2^24) and vertex widths (at most kMaxRangeVertexBits) and the order of their first new
// vertices; without boxes (an isolated leaf) it fails.
TEST(ClusterCodec, CheckRejectsMalformedRanges) {
  const SphereSource sp(4);  // kept in place: src points into z
  const cluster::Quantized& z = sp.z;
  const ClusterSource& src = sp.src;
  std::vector<uint32_t> order(64);
  std::iota(order.begin(), order.end(), 0u);
  const uint32_t* prims[8];
  uint32_t counts[8];
  for (int c = 0; c < 8; ++c) {
    prims[c] = &order[8 * size_t(c)];
    counts[c] = 8;
  }
  const std::vector<uint8_t> enc = cluster::encode(src, prims, counts, 8, true, true);
  ClusterHeader h;
  std::memcpy(&h, enc.data(), sizeof(h));
  ASSERT_TRUE(cluster::has_ranges(h));
  uint32_t anchor[3];
  const cluster::Layout L = cluster::layout(h, 8, z.lattice, false);
  cluster::lossy_anchors(cluster::stream_of(enc.data()), L, anchor);
  cluster::MultiLeafPlanes mp;
  ASSERT_TRUE(cluster::multileaf_boxes(src, prims, counts, 8, anchor, mp));
  const cluster::LatticeBoxes8 lb = packed(mp);
  auto checks = [&](const cluster::LatticeBoxes8& b, const std::vector<uint8_t>& data,
                    std::string* why) {
    std::vector<uint8_t> ml(sizeof(b) + data.size());
    std::memcpy(ml.data(), &b, sizeof(b));
    std::memcpy(ml.data() + sizeof(b), data.data(), data.size());
    return cluster::check(ml.data() + sizeof(b), data.size() - kClusterReadSlack, 8, z.lattice,
                          false, why, ml.data());
  };
  std::string why;
  ASSERT_TRUE(checks(lb, enc, &why)) << why;
  EXPECT_FALSE(cluster::check(enc.data(), enc.size() - kClusterReadSlack, 8, z.lattice, false,
                              &why));  // no boxes
  EXPECT_NE(why.find("outside a multi-leaf"), std::string::npos) << why;
  cluster::LatticeBoxes8 b = lb;
  b.scale[1] = uint8_t((cluster::kMaxRangeScaleExp + 1) << 3);  // products could wrap
  EXPECT_FALSE(checks(b, enc, &why));
  EXPECT_NE(why.find("scale exponent"), std::string::npos) << why;
  cluster::MultiLeafPlanes wide = mp;
  wide.scale[0] = uint8_t(cluster::kMaxRangeScaleExp << 3 | 7);  // 255 planes of 2^20 steps
  wide.q[0][3] = 0;
  wide.q[1][3] = 255;
  b = packed(wide);
  EXPECT_FALSE(checks(b, enc, &why));
  EXPECT_NE(why.find("beyond 2^24 steps"), std::string::npos) << why;
  // Each axis within 2^24 steps (255 planes of 2^10 steps: some 2^19), child 3's box spanning all
  // 255 planes on all three: its mixed-radix vertices take some 57 bits.
  wide = mp;
  for (int a = 0; a < 3; ++a) {
    wide.scale[a] = uint8_t(10 << 3 | 7);
    wide.q[2 * a][3] = 0;
    wide.q[2 * a + 1][3] = 255;
  }
  b = packed(wide);
  EXPECT_FALSE(checks(b, enc, &why));
  EXPECT_NE(why.find("bits, beyond 52"), std::string::npos) << why;
  // Child 5's first new vertex past the vertices: the plain table code (vo = 3) and its field
  // all ones.
  std::vector<uint8_t> bad = enc;
  ClusterHeader hb = h;
  hb.tbits = uint16_t((hb.tbits & 0x3fffu) | 3u << 14);
  std::memcpy(bad.data(), &hb, sizeof(hb));
  const cluster::Layout Lb = cluster::layout(hb, 8, z.lattice, false);
  for (uint32_t i = 0; i < Lb.vbw; ++i) {
    const uint64_t bit = 8 * uint64_t(cluster::stream_offset(hb)) + Lb.table +
                         4 * uint64_t(Lb.tb + Lb.vbw) + Lb.tb + i;
    bad[bit >> 3] |= uint8_t(1u << (bit & 7));
  }
  EXPECT_FALSE(checks(lb, bad, &why));
  EXPECT_NE(why.find("out of order"), std::string::npos) << why;
}

TEST(ClusterCodec, CheckRejectsMalformedBlocks) {
  PolyMesh sphere = icosphere(2);
  TriangleMesh tm = triangulate_fan({&sphere});
  const cluster::Quantized z = cluster::quantize(tm.vertices.data(), tm.vertices.size(),
                                                 tm.tris.data(), tm.tri_count(), 1e-5, false);
  ClusterSource src = source_of(tm, z, false);
  std::vector<uint32_t> t(16);
  std::iota(t.begin(), t.end(), 0u);
  const uint32_t* prims[2] = {t.data(), t.data() + 8};
  const uint32_t counts[2] = {8, 8};
  const std::vector<uint8_t> good = cluster::encode(src, prims, counts, 2, false);
  std::string why;
  ASSERT_TRUE(cluster::check(good.data(), good.size(), 2, z.lattice, false, &why)) << why;
  EXPECT_FALSE(
      cluster::check(good.data(), good.size() - 1, 2, z.lattice, false, &why));  // truncated
  EXPECT_FALSE(
      cluster::check(good.data(), good.size(), 3, z.lattice, false, &why));  // a third child
  auto corrupt = [&](size_t off, uint8_t value) {
    std::vector<uint8_t> b = good;
    b[off] = value;
    return cluster::check(b.data(), b.size(), 2, z.lattice, false, &why);
  };
  EXPECT_FALSE(corrupt(offsetof(ClusterHeader, nverts), 1));  // indices beyond the vertices
  EXPECT_FALSE(corrupt(offsetof(ClusterHeader, bits), 25));   // lossy axis wider than 24 bits
  EXPECT_FALSE(corrupt(offsetof(ClusterHeader, ib), 9));      // index wider than 8 bits
  EXPECT_FALSE(corrupt(offsetof(ClusterHeader, ob), 33));     // run offset wider than 32 bits
  // The fine-planes bit outside a multi-leaf (an isolated leaf's cluster: no boxes).
  EXPECT_FALSE(corrupt(offsetof(ClusterHeader, ob), good[offsetof(ClusterHeader, ob)] | 0x40));
  EXPECT_NE(why.find("fine-planes bit outside a lossy multi-leaf"), std::string::npos) << why;
  EXPECT_FALSE(corrupt(offsetof(ClusterHeader, nruns), 0));      // no primID run
  EXPECT_FALSE(corrupt(offsetof(ClusterHeader, nruns), 17));     // more runs than triangles
  ASSERT_EQ(good[offsetof(ClusterHeader, sizes)], 0x3f);         // children of 8 + 8
  EXPECT_FALSE(corrupt(offsetof(ClusterHeader, sizes) + 2, 1));  // a size for a sixth child
  // The packed id widths (pb, gb, bb, hb: 6 bits each in idw): each at most 32.
  ClusterHeader gh;
  std::memcpy(&gh, good.data(), sizeof(gh));
  for (int f = 0; f < 4; ++f)
    for (uint32_t width : {33u, 63u}) {
      uint32_t w[4] = {cluster::run_low_bits(gh), cluster::geom_bits(gh),
                       cluster::prim_base_bits(gh), cluster::geom_base_bits(gh)};
      w[f] = width;
      ClusterHeader h = gh;
      cluster::set_id_widths(h, w[0], w[1], w[2], w[3]);
      std::vector<uint8_t> b = good;
      std::memcpy(b.data(), &h, sizeof(h));
      EXPECT_FALSE(cluster::check(b.data(), b.size(), 2, z.lattice, false, &why)) << f;
      EXPECT_NE(why.find("id width"), std::string::npos) << why;
    }
  // The lattice's anchor widths (the scene's, not the block's): at most 24 bits (lossy).
  ClusterLattice wide = z.lattice;
  wide.anchor_bits[1] = 25;
  EXPECT_FALSE(cluster::check(good.data(), good.size(), 2, wide, false, &why));
  EXPECT_NE(why.find("anchor width"), std::string::npos) << why;
  // The triangle count is the children's sizes: a block with other sizes is another cluster,
  // which check() takes or refuses as any other (no stored count to disagree with); one it takes
  // decodes children of those sizes.
  for (uint8_t sizes : {uint8_t(0x3e), uint8_t(0x07)}) {
    std::vector<uint8_t> b = good;
    b[offsetof(ClusterHeader, sizes)] = sizes;  // children of 7 + 8, of 8 + 1
    if (cluster::check(b.data(), b.size(), 2, z.lattice, false, &why)) {
      b.resize(b.size() + kClusterReadSlack, 0);
      for (int c = 0; c < 2; ++c) {
        cluster::Decoded8 d;
        cluster::decode_child<false>(z.lattice, b.data(), 2, c, d);
        EXPECT_EQ(uint32_t(d.first + d.n), cluster::child_first(sizes, uint32_t(c + 1)));
      }
    }
  }
  EXPECT_FALSE(corrupt(offsetof(ClusterHeader, tbits), 0));  // the strips past the stream
  // The coordinate mode (the top 4 bits of ib): none in a lossy cluster.
  const uint8_t ib = good[offsetof(ClusterHeader, ib)];
  ASSERT_LE(ib, 8);
  EXPECT_FALSE(corrupt(offsetof(ClusterHeader, ib), uint8_t(ib | 1 << 4)));
  EXPECT_NE(why.find("lossy"), std::string::npos) << why;
  // Lossless: float keys or decimals of 0..9 digits (modes 0..10), not more; a decimal mode's box
  // start (the stream's first 3 floats) decimals of the axes' digits: these 4-digit coordinates
  // are decimals of 4 to 9 digits, not of fewer.
  PolyMesh dec = printed(icosphere(2), 4);
  TriangleMesh dtm = triangulate_fan({&dec});
  const cluster::Quantized dz = cluster::quantize(dtm.vertices.data(), dtm.vertices.size(),
                                                  dtm.tris.data(), dtm.tri_count(), 1e-5, true);
  src = source_of(dtm, dz, true);
  const std::vector<uint8_t> lgood = cluster::encode(src, prims, counts, 2, false);
  ClusterHeader lh;
  std::memcpy(&lh, lgood.data(), sizeof(lh));
  ASSERT_EQ(cluster::coord_mode(lh), 1u + 4);  // 4 digits
  ASSERT_TRUE(cluster::check(lgood.data(), lgood.size(), 2, dz.lattice, true, &why)) << why;
  for (uint32_t mode = 0; mode < 16; ++mode) {
    std::vector<uint8_t> b = lgood;
    b[offsetof(ClusterHeader, ib)] = uint8_t(cluster::index_bits(lh) | mode << 4);
    EXPECT_EQ(cluster::check(b.data(), b.size(), 2, dz.lattice, true, &why),
              mode == 0 || (mode >= 5 && mode <= 10))
        << mode;
    if (mode > 10) {
      EXPECT_NE(why.find("decimal mode with"), std::string::npos) << why;
      continue;
    }
    if (mode >= 1 && mode <= 4) {
      EXPECT_NE(why.find("box start"), std::string::npos) << why;
    }
    cluster::Decoded8 d;                        // another mode: other positions, but no failure
    b.resize(b.size() + kClusterReadSlack, 0);  // the decoders' read slack (check() has its size)
    for (int c = 0; c < 2; ++c) cluster::decode_child<true>(dz.lattice, b.data(), 2, c, d);
  }
  // An axis's digits below the cluster's (the top 2 bits of bits[a]): at most k, decimal mode only
  // (and each axis's start a decimal of its digits: axis 1's of 1 digit or more, the others'
  // of 4 or more).
  ASSERT_EQ(lh.bits[1] >> 6, 0);
  for (uint32_t mode : {0u, 1u, 3u, 4u, 5u, 8u}) {
    std::vector<uint8_t> b = lgood;
    b[offsetof(ClusterHeader, ib)] = uint8_t(cluster::index_bits(lh) | mode << 4);
    b[offsetof(ClusterHeader, bits) + 1] = uint8_t(lh.bits[1] | 3 << 6);
    EXPECT_EQ(cluster::check(b.data(), b.size(), 2, dz.lattice, true, &why), mode >= 5) << mode;
    if (mode < 4) {
      EXPECT_NE(why.find("axis 1"), std::string::npos) << why;
    }
    if (mode == 4) {
      EXPECT_NE(why.find("box start"), std::string::npos) << why;
    }
  }
  // A decimal cluster's start beyond the 32-bit codes, or not a number.
  for (float bad : {3e9f, -0.0f, std::numeric_limits<float>::infinity(),
                    std::numeric_limits<float>::quiet_NaN()}) {
    std::vector<uint8_t> b = lgood;
    std::memcpy(b.data() + sizeof(ClusterHeader) + 4, &bad, 4);
    EXPECT_FALSE(cluster::check(b.data(), b.size(), 2, dz.lattice, true, &why)) << bad;
    EXPECT_NE(why.find("axis 1 box start"), std::string::npos) << why;
  }
  // The run highs (the stream's last bits): nruns - 1 one bits inside the data. Ids in pairs far
  // apart: 8 runs.
  TriangleMesh rtm = tm;
  for (size_t i = 0; i < rtm.tri_count(); ++i) rtm.prim_ids[i] = uint32_t(i / 2) * 100000 + i % 2;
  src = source_of(rtm, z, false);
  const std::vector<uint8_t> rgood = cluster::encode(src, prims, counts, 2, false);
  ClusterHeader rh;
  std::memcpy(&rh, rgood.data(), sizeof(rh));
  ASSERT_EQ(cluster::run_count(rh), 8u);
  ASSERT_TRUE(cluster::check(rgood.data(), rgood.size(), 2, z.lattice, false, &why)) << why;
  std::vector<uint8_t> b = rgood;
  b.back() = 0;  // the last run's one bit gone
  EXPECT_FALSE(cluster::check(b.data(), b.size(), 2, z.lattice, false, &why));
  EXPECT_NE(why.find("run highs"), std::string::npos) << why;
  b.resize(b.size() + kMaxRunHighBits / 8 + 1, 0);  // its one bit beyond kMaxRunHighBits bits
  b.back() = 0x80;
  EXPECT_FALSE(cluster::check(b.data(), b.size(), 2, z.lattice, false, &why));
  EXPECT_NE(why.find("run highs beyond"), std::string::npos) << why;
  // The repeat bits (each child's triangles with one primID and one geomID): never on triangle 0.
  for (size_t i = 0; i < rtm.tri_count(); ++i) {
    rtm.prim_ids[i] = uint32_t(i / 8) * 100000;
    rtm.geom_ids[i] = uint32_t(i / 8) * 1000;
  }
  src = source_of(rtm, z, false);
  const std::vector<uint8_t> qgood = cluster::encode(src, prims, counts, 2, false);
  ClusterHeader qh;
  std::memcpy(&qh, qgood.data(), sizeof(qh));
  ASSERT_TRUE(cluster::has_repeats(qh));
  ASSERT_TRUE(cluster::check(qgood.data(), qgood.size(), 2, z.lattice, false, &why)) << why;
  const cluster::Layout ql = cluster::layout(qh, 2, z.lattice, false);
  b = qgood;
  b[sizeof(ClusterHeader) + (ql.ids >> 3)] |= uint8_t(1u << (ql.ids & 7));
  EXPECT_FALSE(cluster::check(b.data(), b.size(), 2, z.lattice, false, &why));
  EXPECT_NE(why.find("repeat or step bit on triangle 0"), std::string::npos) << why;
  // The double steps' plane: never on triangle 0 either. Ids three apart in the strips' order (the
  // order of ids with no neighbours among them, which the strip search does not follow).
  for (size_t i = 0; i < rtm.tri_count(); ++i) {
    rtm.prim_ids[i] = uint32_t(i) * 100000;
    rtm.geom_ids[i] = 0;
  }
  src = source_of(rtm, z, false);
  {
    const std::vector<uint8_t> apart = cluster::encode(src, prims, counts, 2, false);
    const cluster::View v = cluster::view<false>(z.lattice, apart.data(), 2);
    for (uint32_t j = 0; j < 16; ++j) {
      uint32_t geom, prim;
      cluster::decode_ids(v, j, geom, prim);
      rtm.prim_ids[prim / 100000] = 5000 + 3 * j;
    }
  }
  src = source_of(rtm, z, false);
  const std::vector<uint8_t> dgood = cluster::encode(src, prims, counts, 2, false);
  ClusterHeader dh;
  std::memcpy(&dh, dgood.data(), sizeof(dh));
  ASSERT_EQ(cluster::id_flag_planes(dh), 3u);
  ASSERT_TRUE(cluster::check(dgood.data(), dgood.size(), 2, z.lattice, false, &why)) << why;
  const cluster::Layout dl = cluster::layout(dh, 2, z.lattice, false);
  const uint64_t d0 = dl.ids + 2 * uint64_t(dl.ntris);  // the third plane's triangle 0
  b = dgood;
  b[sizeof(ClusterHeader) + (d0 >> 3)] |= uint8_t(1u << (d0 & 7));
  EXPECT_FALSE(cluster::check(b.data(), b.size(), 2, z.lattice, false, &why));
  EXPECT_NE(why.find("repeat or step bit on triangle 0"), std::string::npos) << why;
  EXPECT_FALSE(corrupt(offsetof(ClusterHeader, ob), 0x40));  // fine planes, no boxes
}

// A cluster whose stream takes fewer bits than the multi-leaf frame reads (one triangle on one
// lattice point, anchors of 0 bits) is padded to kMinStreamBytes, and check() rejects less.
TEST(ClusterCodec, ShortStreamsArePadded) {
  PolyMesh m;
  m.positions = {Vec3f(1, 2, 3), Vec3f(1, 2, 3), Vec3f(1, 2, 3)};
  m.face_indices = {0, 1, 2};
  m.face_sizes = {3};
  const TriangleMesh tm = triangulate_fan({&m});
  ASSERT_EQ(tm.tri_count(), 1u);
  const cluster::Quantized z =
      cluster::quantize(tm.vertices.data(), tm.vertices.size(), tm.tris.data(), 1, 1e-5, false);
  for (int a = 0; a < 3; ++a) ASSERT_EQ(z.lattice.anchor_bits[a], 0) << a;
  const ClusterSource src = source_of(tm, z, false);
  const uint32_t prim = 0, count = 1;
  const uint32_t* prims = &prim;
  const std::vector<uint8_t> data = cluster::encode(src, &prims, &count, 1, false);
  EXPECT_EQ(data.size(), sizeof(ClusterHeader) + kMinStreamBytes);
  std::string why;
  EXPECT_TRUE(cluster::check(data.data(), data.size(), 1, z.lattice, false, &why)) << why;
  EXPECT_FALSE(cluster::check(data.data(), data.size() - 1, 1, z.lattice, false, &why));
  EXPECT_NE(why.find("stream shorter"), std::string::npos) << why;
  // The frame as the traversal reads it: the boxes, the cluster, the read slack.
  std::vector<uint8_t> ml(sizeof(cluster::LatticeBoxes8) + data.size() + kClusterReadSlack, 0);
  std::memcpy(ml.data() + sizeof(cluster::LatticeBoxes8), data.data(), data.size());
  float start[4], extent[4];
  cluster::box_frame(cluster::lattice_frame(z.lattice), ml.data(), start, extent);
  for (int a = 0; a < 3; ++a) EXPECT_EQ(start[a], z.decoded[0][a]) << a;
}

struct Built {
  std::vector<PolyMesh> meshes;
  std::vector<const PolyMesh*> ptrs() const {
    std::vector<const PolyMesh*> v;
    for (const PolyMesh& m : meshes) v.push_back(&m);
    return v;
  }
};

Built test_scene() {
  Built b;
  b.meshes.push_back(icosphere(4));
  b.meshes.push_back(random_soup(2000, 21));
  PolyMesh quads = load("torus:24");  // quads: two fan triangles per face
  for (Vec3f& p : quads.positions) p = p * 0.4f + Vec3f(0.5f, 0.5f, 0.5f);
  b.meshes.push_back(std::move(quads));
  return b;
}

// Whether (u, v) and Ng of hit h describe the point p on input triangle t: p = v0 + u (v1 - v0) +
// v (v2 - v0) within `tol` plus a relative 1e-5 of the triangle's size, and Ng parallel to t's
// normal.
bool hit_on_triangle(const RefTri& t, const Hit& h, const double p[3], double tol) {
  double e1[3], e2[3], q[3], n[3], size = 0;
  for (int k = 0; k < 3; ++k) {
    e1[k] = t.v[1][k] - t.v[0][k];
    e2[k] = t.v[2][k] - t.v[0][k];
    q[k] = t.v[0][k] + double(h.u) * e1[k] + double(h.v) * e2[k];
    size = std::max({size, std::fabs(e1[k]), std::fabs(e2[k])});
  }
  n[0] = e1[1] * e2[2] - e1[2] * e2[1];
  n[1] = e1[2] * e2[0] - e1[0] * e2[2];
  n[2] = e1[0] * e2[1] - e1[1] * e2[0];
  const double g[3] = {h.Ng.x, h.Ng.y, h.Ng.z};
  const double dot = n[0] * g[0] + n[1] * g[1] + n[2] * g[2];
  const double nn = std::sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
  const double gg = std::sqrt(g[0] * g[0] + g[1] * g[1] + g[2] * g[2]);
  return dist3(q, p) <= tol + 1e-5 * size && std::fabs(dot) >= 0.999 * nn * gg;
}

// `cad`: the mesh may hold faces in one plane and non-convex polygons (CAD models): their ties
// (coincident faces, overlapping fan triangles of one polygon) are not bounded.
void lossless_hits_equal_tri4v(const Built& b, const char* label, bool cad = false) {
  Scene ref = Scene::build(b.ptrs(), BuildOptions::from_config("bvh8-tri4v"));
  Scene s = Scene::build(b.ptrs(), BuildOptions::from_config("cluster-lossless"));
  std::string why;
  ASSERT_TRUE(s.validate(&why)) << why;
  const std::vector<RefTri> tris = reference_triangles(b.ptrs());
  Rng rng(5);
  int hits = 0, edge_ties = 0, coincident = 0, fan_ties = 0, wrong = 0;
  const int n = 20000;
  for (int i = 0; i < n; ++i) {
    Ray r = random_ray(rng, ref.bounds());
    Hit a = ref.intersect(r), h = s.intersect(r);
    ASSERT_EQ(a.valid(), h.valid()) << "ray " << i;
    EXPECT_EQ(s.occluded(r), h.valid());
    if (!a.valid()) continue;
    hits++;
    ASSERT_EQ(bits_of(a.t), bits_of(h.t)) << "ray " << i;
    // Equal t on two faces: a tie only where the hit point lies on an edge or vertex the two
    // faces share (or on both faces: crossing soup triangles, or faces in one plane), checked on
    // the input triangles.
    if (a.primID != h.primID || a.geomID != h.geomID) {
      RefHit at;
      at.t = a.t;
      at.geom = a.geomID;
      at.prim = a.primID;
      const TieKind k = geometric_tie(tris, r, at, h.geomID, h.primID, tie_delta(r, a.t));
      edge_ties += k == TieKind::Edge;
      coincident += k == TieKind::Coincident;
      if (k == TieKind::None && wrong++ < 3)
        ADD_FAILURE() << "ray " << i << ": face " << h.geomID << "/" << h.primID << " instead of "
                      << a.geomID << "/" << a.primID << " at t " << a.t;
      continue;
    }
    if (bits_of(a.u) != bits_of(h.u) || bits_of(a.v) != bits_of(h.v) ||
        bits_of(a.Ng.x) != bits_of(h.Ng.x) || bits_of(a.Ng.y) != bits_of(h.Ng.y) ||
        bits_of(a.Ng.z) != bits_of(h.Ng.z)) {
      // Another triangle of the same polygon at the same t: on the fan's diagonal, or where the
      // fan triangles of a non-convex polygon overlap. A tie where the point lies on two of them
      // and h's u, v and Ng are those of one of them.
      double p[3];
      point_on_ray(r, a.t, p);
      const double delta = tie_delta(r, a.t);
      int on = 0;
      bool hs = false;
      for (const RefTri& t : tris) {
        if (t.geom != a.geomID || t.prim != a.primID || triangle_distance(t, p) > delta) continue;
        on++;
        hs = hs || hit_on_triangle(t, h, p, delta);
      }
      const bool tie = on >= 2 && hs;
      fan_ties += tie;
      if (!tie && wrong++ < 3)
        ADD_FAILURE() << "ray " << i << ": another triangle of face " << a.geomID << "/" << a.primID
                      << " at t " << a.t << " (u " << a.u << " / " << h.u << ", on " << on
                      << " of its triangles)";
    }
  }
  std::printf(
      "  %s, cluster-lossless: %d hits, %d edge/vertex ties, %d coincident, %d in one face\n",
      label, hits, edge_ties, coincident, fan_ties);
  EXPECT_GT(hits, n / 4);
  EXPECT_EQ(wrong, 0);
  EXPECT_LE(edge_ties, 1 + hits / 1000);
  if (!cad) {
    EXPECT_LE(coincident, 1 + hits / 1000);
    EXPECT_EQ(fan_ties, 0);
  }
}

TEST(ClusterScene, LosslessHitsEqualTri4v) {
  Built b = test_scene();
  lossless_hits_equal_tri4v(b, "synthetic");
  // Computed floats: few clusters in the decimal mode.
  EXPECT_LT(detail_value(Scene::build(b.ptrs(), BuildOptions::from_config("cluster-lossless")),
                         "decimal_cluster_fraction"),
            0.05);
}

// Real meshes: a scan, and two CAD models (open, non-manifold, quads and polygons, faces in one
// plane).
TEST(ClusterScene, LosslessHitsEqualTri4vRealMeshes) {
  const struct {
    const char* name;
    bool cad;
  } meshes[] = {{"stanford_bunny.obj.xz", false},
                {"fg_c172p_aircraft.obj.xz", true},
                {"fg_cg57_cruiser.obj.xz", true}};
  for (const auto& m : meshes) SLIM_REQUIRE_SHARED_FILE(shared_data_dir() + "/" + m.name);
  for (const auto& m : meshes) {
    Built b;
    b.meshes.push_back(load(shared_data_dir() + "/" + m.name));
    SCOPED_TRACE(m.name);
    lossless_hits_equal_tri4v(b, m.name, m.cad);
  }
}

// The same scene with its coordinates printed with 5 decimals and parsed back: its clusters take
// the decimal mode (cluster.h), and the hits stay bvh8-tri4v's bit for bit.
TEST(ClusterScene, LosslessHitsEqualTri4vDecimalCoordinates) {
  Built b = test_scene();
  for (PolyMesh& m : b.meshes) m = printed(std::move(m), 5);
  lossless_hits_equal_tri4v(b, "decimal coordinates");
  const Scene s = Scene::build(b.ptrs(), BuildOptions::from_config("cluster-lossless"));
  EXPECT_GT(detail_value(s, "decimal_cluster_fraction"), 0.9);
}

// The lossy scene against a double-precision brute force over its own decoded triangles
// (cluster_triangles()). Every ray agrees (both miss, or both hit at t within 1e-5 relative on the
// same face) unless the geometry explains the difference, checked on the decoded triangles:
//   graze: the closer of the two hits lies within tie_delta of its face's boundary (the float
//     watertight test and the double test may differ on a ray through an edge: one hits, the
//     other misses that face);
//   tie: equal t on another face, the hit point within tie_delta of that face and of an edge of
//     the reference's face (a shared edge or vertex), or of that face away from the edges
//     (coincident or crossing triangles).
// Each kind is bounded.
TEST(ClusterScene, LossyHitsEqualBruteForceOnDecodedTriangles) {
  Built b = test_scene();
  for (double err : {1e-5, 1e-3}) {
    BuildOptions opt = BuildOptions::from_config("cluster");
    opt.cluster_error = err;
    Scene s = Scene::build(b.ptrs(), opt);
    std::string why;
    ASSERT_TRUE(s.validate(&why)) << why;
    ClusterTriangles ct = cluster_triangles(b.ptrs(), opt);
    const double diag = length(s.bounds().size());
    EXPECT_LE(ct.max_error, err * diag);
    EXPECT_LE(detail_value(s, "max_error_diag_pct"), 100 * err);
    std::vector<RefTri> ref(ct.size());
    for (size_t i = 0; i < ct.size(); ++i) {
      for (int k = 0; k < 3; ++k)
        for (int a = 0; a < 3; ++a) ref[i].v[k][a] = ct.vertices[3 * i + k][a];
      ref[i].geom = ct.geom[i];
      ref[i].prim = ct.face[i];
    }
    Rng rng(6);
    const int n = 3000;
    int same = 0, hits = 0, grazes = 0, edge_ties = 0, coincident = 0, wrong = 0;
    for (int i = 0; i < n; ++i) {
      Ray r = random_ray(rng, s.bounds());
      Hit h = s.intersect(r);
      RefHit rh = reference_intersect(ref, r);
      hits += rh.valid();
      EXPECT_EQ(s.occluded(r), h.valid());
      if (!h.valid() && !rh.valid()) continue;
      const bool on_same = h.valid() && rh.valid() && h.primID == rh.prim && h.geomID == rh.geom;
      if (agrees(h, rh) && on_same) {
        same++;
        continue;
      }
      std::string what;
      if (agrees(h, rh)) {  // equal t, another face
        const TieKind k = geometric_tie(ref, r, rh, h.geomID, h.primID, tie_delta(r, rh.t));
        edge_ties += k == TieKind::Edge;
        coincident += k == TieKind::Coincident;
        if (k == TieKind::None)
          what = "face " + std::to_string(h.geomID) + "/" + std::to_string(h.primID) +
                 " instead of " + std::to_string(rh.geom) + "/" + std::to_string(rh.prim);
      } else {
        // The closer hit: the other test missed its face. Only a ray through that face's edge.
        double p[3], edge;
        if (h.valid() && (!rh.valid() || double(h.t) < rh.t)) {
          point_on_ray(r, h.t, p);
          edge = face_boundary_distance(ref, h.geomID, h.primID, p);
        } else {
          point_on_ray(r, rh.t, p);
          edge = boundary_distance(ref[rh.tri], p);
        }
        if (edge <= tie_delta(r, h.valid() && rh.valid() ? std::min(double(h.t), rh.t)
                                 : h.valid()             ? double(h.t)
                                                         : rh.t))
          grazes++;
        else
          what = "t " + std::to_string(h.t) + " vs reference " + std::to_string(rh.t) +
                 ", the closer hit " + std::to_string(edge) + " from its face's edges";
      }
      if (!what.empty() && wrong++ < 3)
        ADD_FAILURE() << "error bound " << err << ", ray " << i << ": " << what;
    }
    std::printf(
        "  cluster %.0e: %d of %d rays hit, %d same face, %d grazes, %d edge ties, %d "
        "coincident\n",
        err, hits, n, same, grazes, edge_ties, coincident);
    EXPECT_GT(hits, n / 4);
    EXPECT_EQ(wrong, 0) << "error bound " << err;
    EXPECT_LE(grazes, 1 + n / 1000) << "error bound " << err;
    EXPECT_LE(edge_ties, 1 + hits / 1000) << "error bound " << err;
    EXPECT_LE(coincident, 1 + hits / 1000) << "error bound " << err;
  }
}

// Rays from inside a closed mesh cut into many clusters must all hit: a shared vertex decodes to
// the same bits in every cluster, so the watertight test sees a closed surface.
TEST(ClusterScene, WatertightAcrossClusterBorders) {
  PolyMesh sphere = icosphere(6);  // 81920 triangles
  PolyMesh torus = load("torus:256");
  for (const char* config : {"cluster", "cluster-lossless"}) {
    for (double err : {1e-5, 1e-3}) {
      BuildOptions opt = BuildOptions::from_config(config);
      opt.cluster_error = err;
      Scene s = Scene::build(sphere, opt);
      EXPECT_GT(detail_value(s, "clusters"), 1000);
      Rng rng(7);
      int leaks = 0;
      for (int i = 0; i < 100000; ++i) {
        Ray r;
        r.org = Vec3f(rng.uniform() - 0.5f, rng.uniform() - 0.5f, rng.uniform() - 0.5f) * 0.5f;
        r.dir = normalize(Vec3f(rng.uniform() - 0.5f, rng.uniform() - 0.5f, rng.uniform() - 0.5f));
        leaks += !s.intersect(r).valid();
        leaks += !s.occluded(r);
      }
      EXPECT_EQ(leaks, 0) << config << " sphere, error " << err;
      // Torus: origins on the tube's core circle (major radius 1, minor 0.4 displaced by noise).
      Scene st = Scene::build(torus, opt);
      leaks = 0;
      for (int i = 0; i < 100000; ++i) {
        const float a = 6.2831853f * rng.uniform();
        Ray r;
        r.org = Vec3f(std::cos(a), std::sin(a), 0.0f);
        r.dir = normalize(Vec3f(rng.uniform() - 0.5f, rng.uniform() - 0.5f, rng.uniform() - 0.5f));
        leaks += !st.intersect(r).valid();
      }
      EXPECT_EQ(leaks, 0) << config << " torus, error " << err;
    }
  }
}

TEST(ClusterScene, StatisticsAndSizes) {
  PolyMesh torus = load("torus:256");
  Scene s = Scene::build(torus, BuildOptions::from_config("cluster"));
  EXPECT_EQ(s.options().config_name(), "cluster");
  const double tris = double(s.stats().triangles);
  EXPECT_NEAR(detail_value(s, "avg_triangles_per_cluster") * detail_value(s, "clusters"), tris,
              0.5);
  EXPECT_GT(detail_value(s, "avg_triangles_per_cluster"), 16);
  EXPECT_GT(detail_value(s, "position_bits_avg"), 0);
  EXPECT_LE(detail_value(s, "position_bits_avg"), 24);
  EXPECT_NEAR(
      detail_value(s, "geometry_bytes_per_triangle") + detail_value(s, "bvh_bytes_per_triangle"),
      s.memory().bytes_per_triangle(), 1e-9);
  EXPECT_EQ(detail_value(s, "lattice_coarsened"), 0);
  Scene l = Scene::build(torus, BuildOptions::from_config("cluster-lossless"));
  EXPECT_EQ(detail_value(l, "max_error"), 0);
  EXPECT_GT(l.memory().total(), s.memory().total());
  // Multi-leaf headers: the lossy clusters' boxes on the lattice (51 B), the lossless clusters'
  // boxes from their start floats (54 B), a MultiLeaf8 (72 B) for the other compressed-leaf
  // formats.
  EXPECT_GT(detail_value(s, "multileaf_count"), 0);
  EXPECT_EQ(detail_value(s, "multileaf_bytes"),
            double(sizeof(cluster::LatticeBoxes8)) * detail_value(s, "multileaf_count"));
  EXPECT_GT(detail_value(l, "multileaf_count"), 0);
  EXPECT_EQ(detail_value(l, "multileaf_bytes"),
            double(sizeof(cluster::ExactBoxes8)) * detail_value(l, "multileaf_count"));
  // The clusters lie in the leaf arena without padding (ClusterLeaf::kLeafAlign = 1), and the
  // memory counts the arenas as kept: the clusters' data, then the read slack of the leaf arena and
  // of the (here empty) side arena.
  for (const Scene* c : {&s, &l}) {
    ASSERT_EQ(detail_value(*c, "leaf_count"), detail_value(*c, "leaves_in_multileaf"));
    EXPECT_EQ(double(c->memory().geometry_bytes),
              detail_value(*c, "leaf_data_bytes") + 2 * kClusterReadSlack);
  }
  for (const char* config : {"clbvh-tri4v", "clbvh-compact"}) {
    Scene o = Scene::build(torus, BuildOptions::from_config(config));
    EXPECT_GT(detail_value(o, "multileaf_count"), 0) << config;
    EXPECT_EQ(detail_value(o, "multileaf_bytes"), 72.0 * detail_value(o, "multileaf_count"))
        << config;
  }
}

// The clusters come out nearly full (scene_clusters.cpp: the BVH2's small nodes split at counts
// that need no extra cluster, Bvh2BuildConfig::full_blocks_below): on smooth surfaces and on a
// regular grid, whose SAH splits alone give clusters of about 50 triangles of the 64.
TEST(ClusterScene, ClustersAreNearlyFull) {
  for (const char* scene : {"torus:256", "terrain:256", "canyon:256"}) {
    PolyMesh m = load(scene);
    for (const char* config : {"cluster", "cluster-lossless"}) {
      Scene s = Scene::build(m, BuildOptions::from_config(config));
      const double tris = double(s.stats().triangles);
      EXPECT_GE(detail_value(s, "avg_triangles_per_cluster"), 58.0) << scene << " " << config;
      EXPECT_LE(detail_value(s, "avg_triangles_per_cluster"), 64.0) << scene << " " << config;
      EXPECT_GE(detail_value(s, "clusters"), std::ceil(tris / 64)) << scene << " " << config;
    }
  }
}

// The clusters' collapse (the SAH-optimal one with a wide node's memory, kClusterNodeCost) spends
// fewer inner nodes than the slot rule at a lower SAH cost, over the same clusters, and the hits
// are the same: every ray's t bit for bit, the face too unless two faces meet at that t.
TEST(ClusterScene, CollapseSpendsFewerNodesThanSlots) {
  for (const char* scene : {"torus:256", "canyon:256"}) {
    const PolyMesh m = load(scene);
    for (const char* config : {"cluster", "cluster-lossless"}) {
      SCOPED_TRACE(std::string(scene) + " " + config);
      const BuildOptions def = BuildOptions::from_config(config);
      BuildOptions slots = def;
      slots.collapse = Collapse::Slots;
      const Scene a = Scene::build(m, def), b = Scene::build(m, slots);
      EXPECT_LT(detail_value(a, "node8_count") + detail_value(a, "qnode8_count"),
                0.95 * (detail_value(b, "node8_count") + detail_value(b, "qnode8_count")));
      EXPECT_LT(detail_value(a, "sah_cost"), detail_value(b, "sah_cost"));
      EXPECT_EQ(detail_value(a, "leaf_data_bytes"), detail_value(b, "leaf_data_bytes"));
      EXPECT_EQ(detail_value(a, "clusters"), detail_value(b, "clusters"));
      expect_same_t(a, b, 11);
    }
  }
}

// Sibling clusters divided anew (BuildOptions::cluster_redivide) store fewer vertices than the
// SAH's division of the same BVH2 into the same number of clusters, and every triangle once:
// `cluster` decodes the same triangles from its clusters, and for both the rays' hits are the same
// (t bit for bit, the face too unless two faces meet at that t).
TEST(ClusterScene, SiblingsDividedAnewStoreFewerVertices) {
  const PolyMesh m = load("torus:64");
  for (const char* config : {"cluster", "cluster-lossless"}) {
    SCOPED_TRACE(config);
    BuildOptions opt = BuildOptions::from_config(config);
    const Scene sah = Scene::build(m, opt);
    opt.cluster_redivide = true;
    const Scene s = Scene::build(m, opt);
    EXPECT_LT(detail_value(s, "vertices_per_triangle"),
              detail_value(sah, "vertices_per_triangle") - 0.003);
    EXPECT_LT(s.memory().total(), sah.memory().total());
    EXPECT_EQ(detail_value(s, "clusters"), detail_value(sah, "clusters"));
    const std::string path = ::testing::TempDir() + "slimrt_cluster_redivide.slim";
    s.save(path);
    EXPECT_TRUE(Scene::open(path).options().cluster_redivide);  // the scene file keeps it
    std::remove(path.c_str());
    if (std::string(config) == "cluster") {
      const std::optional<DecodedTriangles> a = s.decoded_triangles(), b = sah.decoded_triangles();
      ASSERT_TRUE(a && b);
      EXPECT_EQ(a->size(), s.stats().triangles);
      EXPECT_EQ(rows(*a), rows(*b));
    }
    expect_same_t(s, sah, 5);
  }
}

// The lossy multi-leaf boxes' extent: scale byte e << 3 | m is (8 + m) 2^e lattice steps / 8
// on its axis (an exact product), growing with the byte, for steps of any mantissa check_lattice
// takes.
TEST(ClusterCodec, BoxExtentIsTheScaleInSteps) {
  for (float step : {std::ldexp(1.0f, -20), 1.0f, 0.25f, std::ldexp(1.0f, 40), 1.375f,
                     std::ldexp(1.875f, -20), std::ldexp(1.125f, 101)}) {
    ClusterLattice lat;
    for (int a = 0; a < 3; ++a) lat.step[a] = std::ldexp(step, -a);  // a step of its own per axis
    for (int a = 0; a < 3; ++a) lat.anchor_bits[a] = 20;
    for (int a = 0; a < 3; ++a) {
      float prev = 0;
      for (uint32_t sc = 0; (sc >> 3) <= cluster::kMaxBoxScaleExp; ++sc) {
        const float e = cluster::box_extent(lat, a, sc);
        EXPECT_EQ(double(e), std::ldexp(8.0 + (sc & 7), int(sc >> 3) - 3) * double(lat.step[a]))
            << sc;
        EXPECT_GT(e, prev);
        prev = e;
      }
    }
    EXPECT_EQ(cluster::check_lattice(lat), "");
  }
}

// On a real mesh, every child box of every multi-leaf, decoded as the traversal decodes it (the
// lossy clusters' lattice frames), contains its decoded triangles: validate() walks them all.
TEST(ClusterScene, MultiLeafBoxesContainTheirTrianglesRealMesh) {
  SLIM_REQUIRE_SHARED_DATA();
  const PolyMesh m = load(shared_data_dir() + "/stanford_bunny.obj.xz");
  for (const char* config : {"cluster", "cluster-lossless"}) {
    const Scene s = Scene::build(m, BuildOptions::from_config(config));
    std::string why;
    EXPECT_TRUE(s.validate(&why)) << config << ": " << why;
    EXPECT_GT(detail_value(s, "multileaf_count"), 100) << config;
  }
}

// The lossy anchors take the bits of the largest lattice code per axis (ClusterLattice::
// anchor_bits, from the lattice's box): few for a mesh whose extent spans few steps, more for the
// same mesh on the lattice of a 64 times larger box (BuildOptions::lattice_box, as a chunk of a
// larger scene) with the same origin and step, whose clusters decode to the same triangles: the
// same hits bit for bit, at more header bits. (The sphere sits near -1000 on every axis, so that
// both boxes' largest coordinate, and with it the decode's rounding that fine_lattice_steps
// counts, is the same: the same bound gives the same steps.)
TEST(ClusterScene, AnchorWidthsFollowTheLattice) {
  PolyMesh sphere = icosphere(3);
  for (Vec3f& p : sphere.positions) p = p - Vec3f(1000, 1000, 1000);
  const TriangleMesh tm = triangulate_fan({&sphere});
  Box3f box;
  for (const Vec3f& v : tm.vertices) box.extend(v);
  const double err = 1e-3;
  const Box3f big(box.lo, box.lo + (box.hi - box.lo) * 64.0f);
  const cluster::Quantized z = cluster::quantize(tm.vertices.data(), tm.vertices.size(),
                                                 tm.tris.data(), tm.tri_count(), err, false);
  const cluster::Quantized zb = cluster::quantize(
      tm.vertices.data(), tm.vertices.size(), tm.tris.data(), tm.tri_count(), err / 64, false, big);
  for (int a = 0; a < 3; ++a) ASSERT_EQ(zb.lattice.step[a], z.lattice.step[a]) << a;
  ASSERT_EQ(z.codes, zb.codes);
  for (int a = 0; a < 3; ++a) {
    auto top = [&](const Box3f& b) {
      return cluster::bit_width(
          uint32_t(std::nearbyint((double(b.hi[a]) - double(b.lo[a])) / z.lattice.step[a])));
    };
    EXPECT_EQ(z.lattice.anchor_bits[a], top(box)) << a;
    EXPECT_EQ(zb.lattice.anchor_bits[a], top(big)) << a;
    EXPECT_LE(z.lattice.anchor_bits[a], 12) << a;  // about 1 / (2 x 1e-3 / sqrt(3)) steps
    EXPECT_GE(zb.lattice.anchor_bits[a], z.lattice.anchor_bits[a] + 5) << a;
  }
  BuildOptions opt = BuildOptions::from_config("cluster"), wide = opt;
  opt.cluster_error = err;
  wide.cluster_error = err / 64;
  wide.lattice_box = big;
  const Scene s = Scene::build(sphere, opt), sw = Scene::build(sphere, wide);
  std::string why;
  ASSERT_TRUE(s.validate(&why)) << why;
  ASSERT_TRUE(sw.validate(&why)) << why;
  EXPECT_GT(detail_value(sw, "header_bits_per_triangle"),
            detail_value(s, "header_bits_per_triangle"));
  expect_same_hits(s, sw, 11);
}

// An error bound finer than 24 lattice bits resolve gets a coarser step (reported), not a failure.
TEST(ClusterScene, CoarserStepWhenTheLatticeNeedsMoreBits) {
  PolyMesh sphere = icosphere(3);
  BuildOptions opt = BuildOptions::from_config("cluster");
  opt.cluster_error = 1e-9;
  Scene s = Scene::build(sphere, opt);
  EXPECT_EQ(detail_value(s, "lattice_coarsened"), 1);
  EXPECT_GT(detail_value(s, "max_error_diag_pct"), 1e-7);
  EXPECT_LT(detail_value(s, "max_error_diag_pct"), 1e-5);
  std::string why;
  EXPECT_TRUE(s.validate(&why)) << why;
  opt.cluster_error = 0;
  EXPECT_THROW(Scene::build(sphere, opt), Error);
}

// The lattice's steps: per axis s (the largest power of two with s sqrt(3) / 2 <= the bound) or 2s
// on the widest axes while the largest rounding error, half the steps' diagonal, stays within the
// bound: by the bound's place r = 2 bound / s in [sqrt(3), 2 sqrt(3)), no axis below sqrt(6), one
// below 3, two above. An extent beyond 2^24 - 1 steps coarsens its axis (reported).
TEST(ClusterCodec, LatticeStepsPerAxis) {
  const Box3f box({-1, -2, -0.5f}, {3, 1, 0.5f});  // extents x 4, y 3, z 1: the widest first
  const double s = std::ldexp(1.0, -10);
  for (auto [r, doubled] :
       {std::pair{1.75, 0}, {2.0, 0}, {2.4, 0}, {2.5, 1}, {2.9, 1}, {3.1, 2}, {3.45, 2}}) {
    double step[3];
    ASSERT_TRUE(cluster::lattice_steps(r * s / 2, box, step)) << r;
    double e2 = 0;
    for (int a = 0; a < 3; ++a) {
      EXPECT_EQ(step[a], a < doubled ? 2 * s : s) << r << " axis " << a;
      e2 += step[a] * step[a] / 4;
    }
    EXPECT_LE(std::sqrt(e2), r * s / 2) << r;
  }
  double step[3];
  const Box3f wide({0, 0, 0}, {1e6f, 1, 1});
  EXPECT_FALSE(cluster::lattice_steps(1e-3, wide, step));
  EXPECT_LE(1e6 / step[0], double((1u << 24) - 1));
  EXPECT_EQ(step[1], step[2]);  // only x coarsened
  EXPECT_LT(step[1], step[0]);
  // Steps stay normal floats whose box extents are finite: a bound beyond the box gives the
  // widest extent's power of two, one below the smallest normal float that float (coarsened),
  // a bound beyond 2^102 that step, coordinates beyond 2^126 an error.
  ASSERT_TRUE(cluster::lattice_steps(1e40, box, step));
  for (int a = 0; a < 3; ++a) EXPECT_EQ(step[a], 4.0) << a;
  EXPECT_FALSE(cluster::lattice_steps(1e-45, Box3f({0, 0, 0}, {1e-37f, 1e-37f, 1e-37f}), step));
  for (int a = 0; a < 3; ++a) EXPECT_EQ(step[a], 0x1p-126) << a;
  EXPECT_THROW(cluster::lattice_steps(1e30, Box3f({-3e38f, 0, 0}, {3e38f, 1, 1}), step), Error);
  ASSERT_TRUE(cluster::lattice_steps(1e36, Box3f({-1e33f, 0, 0}, {1e33f, 1, 1}), step));
  EXPECT_EQ(step[0], 0x1p102);  // the largest step a lattice takes, 2^9 of them span the box
  PolyMesh sphere = icosphere(2);
  BuildOptions opt = BuildOptions::from_config("cluster");
  opt.cluster_error = 1e30;
  const Scene coarse = Scene::build(sphere, opt);
  std::string why;
  EXPECT_TRUE(coarse.validate(&why)) << why;
  EXPECT_LE(detail_value(coarse, "lattice_step_x"), 4.0);
}

// The finer steps (8 + m) 2^e / 8: for bounds across an octave, three of them within the bound
// whose product is at least lattice_steps' (and more than 1/4 above it on average), each with a
// mantissa of at most 3 bits that check_lattice accepts. An axis whose extent spans 2^20 - 2 steps
// or more (codes beyond kFineStepCodeBits) takes a power of two; 2^24 - 2 or more, none.
TEST(ClusterCodec, FineLatticeSteps) {
  const Box3f box({-1, -2, -0.5f}, {3, 1, 0.5f});
  double gain = 0;
  int n = 0;
  for (double r = 1.0; r < 2.0; r += 1.0 / 16, ++n) {
    const double bound = r * std::ldexp(1.0, -11);
    double fine[3], pow2[3];
    ASSERT_TRUE(cluster::lattice_steps(bound, box, pow2));
    ASSERT_TRUE(cluster::fine_lattice_steps(bound, box, fine)) << r;
    double e2 = 0;
    ClusterLattice lat;
    for (int a = 0; a < 3; ++a) {
      const double slack = std::max(std::fabs(box.lo[a]), std::fabs(box.hi[a])) * 0x1p-24;
      e2 += (fine[a] / 2 + slack) * (fine[a] / 2 + slack);
      int e;
      const double m = std::frexp(fine[a], &e);  // [1/2, 1)
      EXPECT_EQ(m * 16, std::floor(m * 16)) << r << " axis " << a;
      lat.step[a] = float(fine[a]);
      EXPECT_EQ(double(lat.step[a]), fine[a]);
      lat.anchor_bits[a] = uint8_t(cluster::bit_width(
          uint32_t(std::nearbyint((double(box.hi[a]) - double(box.lo[a])) / fine[a]))));
    }
    EXPECT_LE(std::sqrt(e2), bound) << r;
    EXPECT_EQ(cluster::check_lattice(lat), "") << r;
    const double ratio = fine[0] * fine[1] * fine[2] / (pow2[0] * pow2[1] * pow2[2]);
    EXPECT_GE(ratio, 1.0) << r;
    gain += std::log2(ratio);
  }
  EXPECT_GT(gain / n, std::log2(1.25));
  double step[3];
  auto mantissa = [](double v) {
    int e;
    return std::frexp(v, &e) != 0.5;
  };
  ASSERT_TRUE(cluster::fine_lattice_steps(1e-3, Box3f({0, 0, 0}, {3000, 1, 1}), step));
  EXPECT_FALSE(mantissa(step[0])) << step[0];  // 2.6 M steps of the bound's size
  EXPECT_LT(3000 / step[0], double((1u << 24) - 2));
  ASSERT_TRUE(cluster::fine_lattice_steps(1e-3, Box3f({0, 0, 0}, {1000, 1, 1}), step));
  EXPECT_TRUE(mantissa(step[0])) << step[0];  // 0.87 M steps
  EXPECT_FALSE(cluster::fine_lattice_steps(1e-3, Box3f({0, 0, 0}, {1e5f, 1, 1}), step));
  EXPECT_FALSE(cluster::fine_lattice_steps(0, box, step));
  EXPECT_FALSE(cluster::fine_lattice_steps(1e-3, Box3f(), step));
  // check_lattice: at most 3 mantissa bits; with any, codes of at most 20 bits.
  ClusterLattice lat;
  lat.step[1] = 1.0625f;
  EXPECT_NE(cluster::check_lattice(lat).find("is not (8 + m) 2^e / 8"), std::string::npos);
  lat.step[1] = 1.875f;
  EXPECT_NE(cluster::check_lattice(lat).find("beyond 20 bits"), std::string::npos);  // 24 bits
  lat.anchor_bits[1] = 20;
  EXPECT_EQ(cluster::check_lattice(lat), "");  // 24 bits on the power-of-two axes
}

// A scene takes the finer steps where no axis lies on a coarser grid: on a sphere, for two bounds,
// fine_lattice_steps' of its box; every vertex within the bound, and the larger bound takes fewer
// position bits.
TEST(ClusterScene, FinerStepsWhereTheBoundAllows) {
  PolyMesh sphere = icosphere(5);
  const Box3f box = sphere.bounds();
  const double diag = diagonal(box);
  const double s = std::ldexp(1.0, -10);
  double bits[2];
  for (int i : {0, 1}) {
    BuildOptions opt = BuildOptions::from_config("cluster");
    opt.cluster_error = (i ? 3.2 : 2.2) * s / 2 / diag;
    const Scene sc = Scene::build(sphere, opt);
    std::string why;
    ASSERT_TRUE(sc.validate(&why)) << why;
    double fine[3];
    ASSERT_TRUE(cluster::fine_lattice_steps(opt.cluster_error * diag, box, fine));
    for (int a = 0; a < 3; ++a)
      EXPECT_EQ(detail_value(sc, std::string("lattice_step_") + "xyz"[a]), fine[a]) << a;
    EXPECT_EQ(detail_value(sc, "lattice_coarsened"), 0);
    EXPECT_LE(detail_value(sc, "max_error_diag_pct"), 100 * opt.cluster_error);
    bits[i] = detail_value(sc, "position_bits_avg");
  }
  EXPECT_LT(bits[1], bits[0] - 0.4);  // log2(3.2 / 2.2) = 0.54 bits a coordinate
}

// The lossy multi-leaf boxes' planes: coarse (6 bits, 39 bytes a multi-leaf) on a scan-like
// surface, whose children's boxes grow little with them; fine (8 bits, 12 bytes more) on most of a
// grid terrain's clusters, whose abutting square children would overlap. The scene's bytes count
// both; the hits equal those of a double-precision brute force (LossyHitsEqualBruteForce) either
// way, and the boxes pass validate().
TEST(ClusterScene, CoarsePlanesWhereTheBoxesGrowLittle) {
  const PolyMesh torus = load("torus:256"), grid = load("terrain:128");
  const Scene st = Scene::build(torus, BuildOptions::from_config("cluster"));
  const Scene sg = Scene::build(grid, BuildOptions::from_config("cluster"));
  std::string why;
  ASSERT_TRUE(st.validate(&why)) << why;
  ASSERT_TRUE(sg.validate(&why)) << why;
  EXPECT_LT(detail_value(st, "fine_plane_fraction"), 0.2);
  EXPECT_GT(detail_value(sg, "fine_plane_fraction"), 0.5);
  // A lossless scene has no such figure.
  const Scene sl = Scene::build(torus, BuildOptions::from_config("cluster-lossless"));
  for (const auto& [k, v] : stat_details(sl)) EXPECT_NE(k, "fine_plane_fraction");
}

// A terrain's grid rows lie on a lattice 2^k times coarser than the bound needs: x and y take that
// step (their codes k bits shorter), z keeps the bound's power of two (lattice_steps'). On the
// lattice of a given box (as every piece of a chunked build derives it) the steps are the box's
// alone, fine_lattice_steps': more position bits. Both keep the bound.
TEST(ClusterScene, ExactAxesTakeTheirCoarserLattice) {
  const PolyMesh grid = load("terrain:64");
  BuildOptions own = BuildOptions::from_config("cluster"), boxed = own;
  boxed.lattice_box = grid.bounds();
  const Scene s = Scene::build(grid, own), sb = Scene::build(grid, boxed);
  std::string why;
  ASSERT_TRUE(s.validate(&why)) << why;
  ASSERT_TRUE(sb.validate(&why)) << why;
  const Box3f box = grid.bounds();
  const double bound = own.cluster_error * diagonal(box);
  double pow2[3], fine[3];
  ASSERT_TRUE(cluster::lattice_steps(bound, box, pow2));
  ASSERT_TRUE(cluster::fine_lattice_steps(bound, box, fine));
  EXPECT_EQ(detail_value(s, "lattice_step_z"), pow2[2]);
  for (int a = 0; a < 2; ++a) {
    const double ratio = detail_value(s, std::string("lattice_step_") + "xy"[a]) / pow2[a];
    EXPECT_GE(ratio, 16) << a;
    EXPECT_EQ(ratio, std::exp2(std::round(std::log2(ratio)))) << a;  // a power of two
  }
  for (int a = 0; a < 3; ++a)
    EXPECT_EQ(detail_value(sb, std::string("lattice_step_") + "xyz"[a]), fine[a]) << a;
  EXPECT_LT(detail_value(s, "position_bits_avg"), detail_value(sb, "position_bits_avg") - 2);
  EXPECT_LT(s.memory().total(), sb.memory().total());
  for (const Scene* x : {&s, &sb}) EXPECT_LE(detail_value(*x, "max_error"), bound);
}

TEST(ClusterScene, BadInput) {
  PolyMesh m;
  m.positions = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {NAN, 0, 0}, {1, 1, 0}, {1, 0, 0}};
  m.face_indices = {0, 1, 2, /*NaN*/ 0, 3, 1, /*degenerate*/ 0, 0, 1, /*duplicate vertex*/ 5, 4, 2};
  m.face_sizes = {3, 3, 3, 3};
  for (const char* config : {"cluster", "cluster-lossless"}) {
    Scene s = Scene::build(m, BuildOptions::from_config(config));
    EXPECT_EQ(s.stats().skipped_faces, 1u);
    std::string why;
    EXPECT_TRUE(s.validate(&why)) << why;
    Ray r;
    r.org = Vec3f(0.2f, 0.2f, 1.0f);
    r.dir = Vec3f(0, 0, -1);
    Hit h = s.intersect(r);
    ASSERT_TRUE(h.valid());
    EXPECT_EQ(h.primID, 0u);
    r.org = Vec3f(0.8f, 0.6f, 1.0f);
    EXPECT_EQ(s.intersect(r).primID, 3u);
  }
  PolyMesh empty;
  Scene e = Scene::build(empty, BuildOptions::from_config("cluster"));
  Ray r;
  r.dir = Vec3f(0, 0, 1);
  EXPECT_FALSE(e.intersect(r).valid());
}

}  // namespace

// The lossy scene decodes its triangles from its clusters (Scene::decoded_triangles): on a real
// mesh, those of the rebuild from the input (decoded_triangles(meshes, options)), bit for bit and
// corners in the input order, with the same mesh and face, in the clusters' order (compared
// sorted).
TEST(ClusterScene, DecodesItsOwnTrianglesRealMesh) {
  SLIM_REQUIRE_SHARED_DATA();
  const PolyMesh m = load(shared_data_dir() + "/stanford_bunny.obj.xz");
  const BuildOptions opt = BuildOptions::from_config("cluster");
  const Scene s = Scene::build(m, opt);
  const std::optional<DecodedTriangles> mine = s.decoded_triangles();
  ASSERT_TRUE(mine.has_value());
  const std::optional<DecodedTriangles> rebuilt = decoded_triangles({&m}, opt);
  ASSERT_TRUE(rebuilt.has_value());
  EXPECT_EQ(mine->size(), m.face_count());
  EXPECT_EQ(rows(*mine), rows(*rebuilt));
  // cluster-lossless intersects the input triangles: no geometry of its own to give.
  EXPECT_FALSE(Scene::build(m, BuildOptions::from_config("cluster-lossless")).decoded_triangles());
}

// cluster_face_order on a mesh whose faces are shuffled (a sphere's and torus:128's quads): the
// order is a permutation; the reordered mesh's scene holds the same triangles, each face mapped
// through the order, hits the same (t bit for bit, the face through the order unless two faces
// meet at that t), and stores its primIDs in fewer bytes, for both configurations.
TEST(ClusterScene, FacesInClusterOrderTakeFewerBytes) {
  std::vector<PolyMesh> meshes = {icosphere(5), load("torus:128")};
  for (PolyMesh& m : meshes) {
    std::vector<uint32_t> shuffle(m.face_count());
    std::iota(shuffle.begin(), shuffle.end(), 0u);
    std::mt19937 rng(5);
    std::shuffle(shuffle.begin(), shuffle.end(), rng);
    m = reorder_faces(m, shuffle);
  }
  for (const PolyMesh& m : meshes)
    for (const char* config : {"cluster", "cluster-lossless"}) {
      SCOPED_TRACE(m.name + " " + config);
      const BuildOptions opt = BuildOptions::from_config(config);
      const std::vector<uint32_t> order = cluster_face_order(m, opt);
      ASSERT_EQ(order.size(), m.face_count());
      std::vector<uint32_t> sorted = order;
      std::sort(sorted.begin(), sorted.end());
      for (uint32_t i = 0; i < sorted.size(); ++i) ASSERT_EQ(sorted[i], i);
      const PolyMesh r = reorder_faces(m, order);
      const Scene a = Scene::build(m, opt), b = Scene::build(r, opt);
      std::string why;
      ASSERT_TRUE(b.validate(&why)) << why;
      // Random order: about log2(faces) bits a face for the ids (the sphere's 20480 triangles
      // 14.3; torus:128's 8192 quads 13, 6.5 a triangle), the clusters' order: a few. Measured:
      // torus:128 6.42 -> 5.76 B/tri (`cluster`), 10.39 -> 9.73 (`cluster-lossless`).
      const double tris = double(m.fan_triangle_count());
      EXPECT_LT(double(b.memory().total()) / tris, double(a.memory().total()) / tris - 0.5)
          << a.memory().total() << " -> " << b.memory().total();
      if (std::string(config) == "cluster") {
        DecodedTriangles tb = *b.decoded_triangles();
        for (uint32_t& f : tb.face) f = order[f];
        EXPECT_EQ(rows(*a.decoded_triangles()), rows(tb));
      }
      expect_same_t(a, b, 11, &order);
    }
  EXPECT_THROW(cluster_face_order(meshes[0], BuildOptions::from_config("bvh8-tri4v")), Error);
}

// The four meshes of ../shared/data over 6 B/tri in `cluster` come within it with their faces in
// the clusters' order (docs/results.md, "Faces in the clusters' order"): stanford_bunny here.
TEST(ClusterScene, FacesInClusterOrderRealMesh) {
  const std::string path = shared_data_dir() + "/stanford_bunny.obj.xz";
  SLIM_REQUIRE_SHARED_FILE(path);
  const PolyMesh m = load(path);
  const BuildOptions opt = BuildOptions::from_config("cluster");
  const PolyMesh r = reorder_faces(m, cluster_face_order(m, opt));
  const double before = Scene::build(m, opt).memory().bytes_per_triangle();
  const double after = Scene::build(r, opt).memory().bytes_per_triangle();
  EXPECT_GT(before, 6.0);
  EXPECT_LT(after, 6.0);
}

// The per-thread decode cache (cluster::DecodeCache) is keyed by the scene's tag as well as by the
// child's address, and so are its clusters' views: a cluster at the address of one a thread traced
// before, in another scene (a scene built or opened where a destroyed one was), is decoded, not
// taken from the cache. Either key without the tag fails: the entries' in both halves, the views'
// in the lossless half (its anchors hold the depth; the lossy clusters' bytes and views are the
// same, their depth being in the lattice's origin).
TEST(ClusterScene, DecodeCacheNeverAnswersForAnotherScene) {
  // One triangle across the ray's path at z = depth.
  auto one_triangle = [](float depth) {
    PolyMesh m;
    m.positions = {Vec3f(-1, -1, depth), Vec3f(1, -1, depth), Vec3f(0, 1, depth)};
    m.face_indices = {0, 1, 2};
    m.face_sizes = {3};
    return triangulate_fan({&m});
  };
  for (const bool lossless : {false, true}) {
    SCOPED_TRACE(lossless ? "lossless" : "lossy");
    std::vector<uint8_t> at;  // one address for both scenes' cluster
    std::vector<float> t;
    for (const float depth : {1.0f, 2.0f}) {
      const TriangleMesh tm = one_triangle(depth);
      const cluster::Quantized z = cluster::quantize(tm.vertices.data(), tm.vertices.size(),
                                                     tm.tris.data(), 1, 1e-5, lossless);
      ClusterSource src = source_of(tm, z, lossless);
      const uint32_t prim = 0, count = 1;
      const uint32_t* prims = &prim;
      const std::vector<uint8_t> data = cluster::encode(src, &prims, &count, 1, true);
      if (at.empty()) at.resize(data.size() + 64);
      ASSERT_LE(data.size(), at.size());
      std::copy(data.begin(), data.end(), at.begin());
      Ray r;
      r.org = Vec3f(0, 0, -1);
      r.dir = Vec3f(0, 0, 1);
      TravRay tr;
      ASSERT_TRUE(make_trav_ray(r, RaySetupBounds(Box3f(Vec3f(-1, -1, -1), Vec3f(1, 1, 2))), tr));
      Hit h;
      NoStats st;
      bool hit;
      if (lossless) {
        ClusterLeaf<true>::Context ctx;
        hit = ClusterLeaf<true>::intersect_in_multileaf<false>(ctx, at.data(), 1, 0, tr, h, st);
      } else {
        ClusterLeaf<false>::Context ctx;
        ctx.lattice = z.lattice;
        ctx.frame = cluster::lattice_frame(z.lattice);
        hit = ClusterLeaf<false>::intersect_in_multileaf<false>(ctx, at.data(), 1, 0, tr, h, st);
      }
      ASSERT_TRUE(hit);
      t.push_back(h.t);
    }
    EXPECT_NEAR(t[0], 2.0f, 1e-4f);
    EXPECT_NEAR(t[1], 3.0f, 1e-4f);  // not the first scene's triangle at the same address
  }
}

// The views of the cluster at `data` as the traversal gets them for 1 and then 8 children (one
// scene: one tag), against views made afresh.
template <bool kLossless>
void expect_views_follow_the_count(const typename ClusterLeaf<kLossless>::Context& ctx,
                                   const uint8_t* data) {
  for (const uint32_t k : {1u, 8u}) {
    const auto mv = ClusterLeaf<kLossless>::multileaf_view(ctx, data, k);
    const cluster::View& got = mv.get(ctx);
    const cluster::View fresh = cluster::view<kLossless>(ctx.lattice, data, k);
    EXPECT_EQ(got.L.ntris, k);
    EXPECT_EQ(got.L.ntris, fresh.L.ntris) << k;
    EXPECT_EQ(got.L.table, fresh.L.table) << k;
    EXPECT_EQ(got.L.verts, fresh.L.verts) << k;
    EXPECT_EQ(got.L.topo, fresh.L.topo) << k;
    EXPECT_EQ(got.L.end, fresh.L.end) << k;
  }
}

// The views are keyed by the child count too: a crafted scene file's references could give one
// cluster two counts (the structure check takes each reference's on its own), and a view made for
// one count has another layout (another triangle count, child table and topology start). The
// view a visit of the whole cluster gets, after a visit of its first child alone, is the whole
// cluster's.
TEST(ClusterScene, DecodeCacheViewsFollowTheChildCount) {
  PolyMesh m;
  for (int j = 0; j < 8; ++j) {  // 8 separate triangles
    const float x = 3.0f * float(j);
    const uint32_t b = uint32_t(m.positions.size());
    m.positions.insert(m.positions.end(),
                       {Vec3f(x - 1, -1, 1), Vec3f(x + 1, -1, 1), Vec3f(x, 1, 2)});
    m.face_indices.insert(m.face_indices.end(), {b, b + 1, b + 2});
    m.face_sizes.push_back(3);
  }
  const TriangleMesh tm = triangulate_fan({&m});
  for (const bool lossless : {false, true}) {
    SCOPED_TRACE(lossless ? "lossless" : "lossy");
    const cluster::Quantized z = cluster::quantize(tm.vertices.data(), tm.vertices.size(),
                                                   tm.tris.data(), tm.tri_count(), 1e-5, lossless);
    ClusterSource src = source_of(tm, z, lossless);
    uint32_t ids[8], counts[8];
    const uint32_t* prims[8];
    for (uint32_t c = 0; c < 8; ++c) {
      ids[c] = c;
      counts[c] = 1;
      prims[c] = &ids[c];
    }
    const std::vector<uint8_t> data = cluster::encode(src, prims, counts, 8, true);
    std::string why;
    ASSERT_TRUE(
        cluster::check(data.data(), data.size() - kClusterReadSlack, 8, z.lattice, lossless, &why))
        << why;
    if (lossless) {
      ClusterLeaf<true>::Context ctx;
      expect_views_follow_the_count<true>(ctx, data.data());
    } else {
      ClusterLeaf<false>::Context ctx;
      ctx.lattice = z.lattice;
      ctx.frame = cluster::lattice_frame(z.lattice);
      expect_views_follow_the_count<false>(ctx, data.data());
    }
  }
}

// The scene's sections (its file past the header, which holds the options and the build time)
// do not depend on the build's threads: the isolated one-triangle clusters' records go into the
// side arena in cluster order, not in the order the collapse's tasks reach them.
TEST(ClusterScene, SameBytesWithAnyThreadCount) {
  // Four tori far apart (subtrees large enough for the collapse's parallel tasks), each with
  // small triangles scattered around it: one-triangle clusters inside each torus's subtree.
  const PolyMesh torus = load("torus:128");
  Box3f tb;
  for (const Vec3f& p : torus.positions) tb.extend(p);
  const float r = std::max({tb.hi.x - tb.lo.x, tb.hi.y - tb.lo.y, tb.hi.z - tb.lo.z});
  PolyMesh m;
  std::mt19937 rng(7);
  std::normal_distribution<float> g(0.0f, 1.0f);
  for (int copy = 0; copy < 4; ++copy) {
    const Vec3f shift(10.0f * r * float(copy), 0, 0);
    uint32_t base = uint32_t(m.positions.size());
    for (const Vec3f& p : torus.positions) m.positions.push_back(p + shift);
    for (uint32_t i : torus.face_indices) m.face_indices.push_back(base + i);
    m.face_sizes.insert(m.face_sizes.end(), torus.face_sizes.begin(), torus.face_sizes.end());
    for (int t = 0; t < 12; ++t) {
      Vec3f d(g(rng), g(rng), g(rng));
      const float len = std::sqrt(d.x * d.x + d.y * d.y + d.z * d.z);
      const float k = 2.0f * r / std::max(len, 1e-3f);
      const Vec3f c = shift + Vec3f(d.x * k, d.y * k, d.z * k);
      base = uint32_t(m.positions.size());
      m.positions.push_back(c);
      m.positions.push_back(c + Vec3f(0.001f * r, 0, 0));
      m.positions.push_back(c + Vec3f(0, 0.001f * r, 0));
      m.face_indices.insert(m.face_indices.end(), {base, base + 1, base + 2});
      m.face_sizes.push_back(3);
    }
  }
  auto sections = [&](const char* config, int threads) {
    BuildOptions opt = BuildOptions::from_config(config);
    opt.threads = threads;
    const std::string path = ::testing::TempDir() + "slimrt_cluster_threads.slim";
    Scene::build(m, opt).save(path);
    std::FILE* f = std::fopen(path.c_str(), "rb");
    EXPECT_NE(f, nullptr);
    std::vector<uint8_t> bytes;
    uint8_t buf[1 << 16];
    for (size_t n; f && (n = std::fread(buf, 1, sizeof buf, f)) > 0;)
      bytes.insert(bytes.end(), buf, buf + n);
    if (f) std::fclose(f);
    std::remove(path.c_str());
    uint64_t header_bytes = 0;  // FileHeader::header_bytes (api/scene_file.cpp), at byte 24
    if (bytes.size() >= 32) std::memcpy(&header_bytes, bytes.data() + 24, 8);
    EXPECT_LT(header_bytes, bytes.size());
    return std::vector<uint8_t>(bytes.begin() + std::min<size_t>(header_bytes, bytes.size()),
                                bytes.end());
  };
  for (const char* config : {"cluster", "cluster-lossless"}) {
    const std::vector<uint8_t> one = sections(config, 1);
    EXPECT_FALSE(one.empty());
    for (int run = 0; run < 4; ++run) EXPECT_EQ(sections(config, 2), one) << config;
  }
}
