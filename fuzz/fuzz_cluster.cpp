// libFuzzer target: the compressed triangle cluster block (src/prim/cluster.h).
//
// Input bytes:
//   [0]      bits 0-2: children - 1 (1..8); bit 3: lossless; bits 4-7: round-trip triangles / 4
//   [1..]    a cluster block, any bits (the decoder's input), as long as the rest of the input
// Checks:
//   1. cluster::check() either rejects the block or accepts one that the decoders read only
//      inside its bytes plus kClusterReadSlack (ASan: the block is copied to an exact-size
//      buffer), for every child, with ids of every triangle (lossy: with anchors of 24 bits per
//      axis, and of the input size's widths);
//   2. round trip: the input bytes as vertex codes (lossless: float keys, or the keys of decimals
//      q x 10^-k, cluster.h's decimal mode) and a topology of up to 64 triangles in up to 8
//      children (each triangle's primID the input's 32 bits, or within 3 of the previous
//      triangle's where its geomID byte has bit 7): encode(), check() accepts it, and every child
//      decodes to its triangles (in the encoder's strip order), the codes' positions and the ids
//      bit for bit;
//   3. lossy: the frame of the multi-leaf boxes on the lattice (cluster::LatticeBoxes8) made for
//      that cluster decodes as the builder made it and encloses every child's decoded triangles;
//   4. lossy: the input's first 39 bytes as a multi-leaf's boxes and the rest as the cluster behind
//      them (per-child vertex ranges come from the boxes' 6-bit planes and, with the fine-planes
//      bit, their low bits in the cluster): as 1., the decoders reading only inside the boxes and
//      the block plus the read slack (in 1. and 4. the vector vertex decode and planes equal the
//      scalar ones bit for bit); the round trip of 2. encodes a multi-leaf's
//      cluster (with ranges where they are smaller) and decodes it behind the boxes the builder
//      makes (cluster::multileaf_boxes).
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <string>
#include <vector>

#include "fuzz_common.h"
#include "prim/cluster.h"

namespace {

using namespace slim;
using fuzz::Reader;

template <bool kLossless>
void decode_all(const ClusterLattice& lat, const uint8_t* block, uint32_t children) {
  const cluster::View view = cluster::view<kLossless>(lat, block, children);
  if constexpr (kLossless) {
    // The box start the traversal loads is the coordinate its derived anchor decodes to.
    alignas(16) float start[4];
    cluster::exact_box_start(block, start);
    for (int a = 0; a < 3; ++a) {
      const float x =
          cluster::decode_coord<true>(lat, a, view.anchor[a], cluster::axis_mode(view.h, a));
      SLIM_FUZZ_CHECK(std::memcmp(&x, &start[a], 4) == 0,
                      "box start is not the anchor's coordinate");
    }
  }
  if constexpr (!kLossless) {
    if (view.ranges) {
      // The traversal's ranges (AVX2 where built) are the structure check's (scalar) field for
      // field: the float or double division path and every vertex's bits follow from them.
      uint8_t q[6][8];
      const uint8_t* boxes = block - sizeof(cluster::LatticeBoxes8);
      cluster::lattice_planes(boxes, cluster::plane_lows(block), q);
      cluster::ChildRanges rs;
      cluster::child_ranges(view.h, cluster::layout(view.h, children, lat, false), view.bits,
                            view.anchor, q, boxes + offsetof(cluster::LatticeBoxes8, scale),
                            children, rs);
      SLIM_FUZZ_CHECK(rs == view.r, "vector and scalar child ranges differ");
    }
  }
  for (uint32_t c = 0; c < children; ++c) {
    cluster::Decoded8 d;
    cluster::decode_child<kLossless>(lat, block, children, int(c), d);
    SLIM_FUZZ_CHECK(d.n >= 1 && d.n <= 8, "child size");
    if constexpr (!kLossless) {
      // The traversal's vertex decode (AVX2 where built, per-child ranges or not) gives the
      // scalar decode's bits.
      cluster::Decoded8 ds;
      cluster::decode_child<false, true>(lat, view, int(c), ds);
      SLIM_FUZZ_CHECK(std::memcmp(d.v, ds.v, sizeof(d.v)) == 0,
                      "vector and scalar vertex decodes differ");
    }
    const cluster::ChildIds ids = cluster::child_ids(view, uint32_t(d.first));
    for (int l = 0; l < d.n; ++l) {
      uint32_t g, p, gc, pc;
      cluster::decode_ids<kLossless>(lat, block, children, uint32_t(d.first + l), g, p);
      // The traversal's path (the child's ids kept in the decode cache) gives the same ids.
      cluster::decode_ids(view.bits, ids, uint32_t(l), gc, pc);
      SLIM_FUZZ_CHECK(g == gc && p == pc, "ids differ between the decode paths");
    }
  }
}

// 3. Lossy: the frame of the multi-leaf boxes (cluster::LatticeBoxes8) the builder writes ahead of
// the cluster: box_frame (the traversal's decode) gives the builder's frame bit for bit, and its
// q = 0 and q = 255 planes (one fma, as the traversal decodes them) enclose every decoded vertex of
// every child, so the child boxes quantized in it (bvh8.cpp quantize_planes, not linked here)
// can be conservative.
void multileaf_boxes(const ClusterLattice& lat, const std::vector<uint8_t>& ml,
                     const std::vector<Vec3f>& decoded, const std::vector<uint32_t>& tris,
                     const uint32_t* const* prims, const uint32_t* counts, int k) {
  Box3f all;
  for (int c = 0; c < k; ++c)
    for (uint32_t j = 0; j < counts[c]; ++j)
      for (int q = 0; q < 3; ++q) all.extend(decoded[tris[3 * size_t(prims[c][j]) + q]]);
  const uint8_t* block = ml.data() + sizeof(cluster::LatticeBoxes8);
  cluster::LatticeBoxes8 lb;
  float start[4], extent[4], s2[4], e2[4];
  SLIM_FUZZ_CHECK(cluster::write_box_frame(lat, block, all, lb, start, extent), "no box frame");
  SLIM_FUZZ_CHECK(
      std::memcmp(lb.scale, ml.data() + offsetof(cluster::LatticeBoxes8, scale), 3) == 0,
      "the boxes' scales differ from the builder's frame");
  cluster::box_frame(cluster::lattice_frame(lat), ml.data(), s2, e2);
  SLIM_FUZZ_CHECK(std::memcmp(start, s2, 3 * sizeof(float)) == 0 &&
                      std::memcmp(extent, e2, 3 * sizeof(float)) == 0,
                  "box frame decodes differently from the builder's");
  for (int c = 0; c < k; ++c) {
    cluster::Decoded8 d;
    cluster::decode_child<false>(lat, block, uint32_t(k), c, d);
    for (int l = 0; l < 8; ++l)
      for (int q = 0; q < 3; ++q)
        for (int a = 0; a < 3; ++a)
          SLIM_FUZZ_CHECK(s2[a] <= d.v[q][a][l] && std::fma(255.0f, e2[a], s2[a]) >= d.v[q][a][l],
                          "box frame misses a decoded vertex");
  }
}

void round_trip(Reader& in, uint32_t ntris, bool lossless) {
  // Up to 64 distinct vertices with codes from the input (lossy: below 2^24). Lossless, flavour
  // bit 0: the coordinates are decimals q x 10^-k (k = bits 1-4 mod 10, q the input's 32 bits
  // shifted right by bits 5-7 x 4), the float keys of decimal_coord(q, k), so that the encoder
  // may take the decimal mode; an input word with its top 3 bits set keeps its key (a vertex
  // that breaks the mode).
  const uint32_t nv = 1 + in.byte() % 64;
  const uint8_t flavour = lossless ? in.byte() : 0;
  const uint32_t digits = ((flavour >> 1) & 15) % 10, shift = 4 * (flavour >> 5);
  std::vector<uint32_t> codes(3 * nv);
  std::vector<Vec3f> decoded(nv);
  ClusterLattice lat;
  lat.origin[1] = -3.0f;
  // A step of its own per axis: powers of two with codes of 24 bits, or with an odd vertex count
  // steps (8 + m) 2^e / 8 with codes of 20 bits (check_lattice).
  const bool stepped = !lossless && (nv & 1);
  for (int a = 0; a < 3; ++a) lat.step[a] = std::ldexp(stepped ? 1.375f : 0.5f, -a);
  for (uint32_t i = 0; i < nv; ++i)
    for (int a = 0; a < 3; ++a) {
      uint32_t c = 0;
      in.bytes(&c, 4);
      if (!lossless) c &= (1u << (stepped ? cluster::kFineStepCodeBits : 24)) - 1;
      if ((flavour & 1) && (c >> 29) != 7)
        c = cluster::float_key(cluster::decimal_coord(uint32_t(int32_t(c) >> shift), digits));
      codes[3 * i + a] = c;
      decoded[i][a] = lossless ? cluster::key_float(c) : cluster::lattice_coord(lat, a, c);
    }
  // Lossy: the anchors at the codes' widths (the lattice's largest code per axis, as quantize).
  if (!lossless)
    for (int a = 0; a < 3; ++a) {
      uint32_t top = 0;
      for (uint32_t i = 0; i < nv; ++i) top = std::max(top, codes[3 * i + a]);
      lat.anchor_bits[a] = uint8_t(cluster::bit_width(top));
    }
  std::vector<uint32_t> tris(3 * ntris), geom(ntris), prim(ntris), order(ntris);
  for (uint32_t t = 0; t < ntris; ++t) {
    for (int k = 0; k < 3; ++k) tris[3 * t + k] = in.byte() % nv;
    in.bytes(&prim[t], 4);
    const uint8_t g = in.byte();
    geom[t] = g & 3;
    // Bit 7 of that byte: the primID within 3 of the previous triangle's (the ids' steps).
    if (t && (g & 0x80)) prim[t] = prim[t - 1] + prim[t] % 7 - 3;
    order[t] = t;
  }
  ClusterSource src;
  src.vertices = decoded.data();
  src.codes = codes.data();
  src.tris = tris.data();
  src.geom_ids = geom.data();
  src.prim_ids = prim.data();
  src.lossless = lossless;
  src.lattice = lat;
  const uint32_t* prims[8];
  uint32_t counts[8];
  int k = 0;
  for (uint32_t pos = 0; pos < ntris && k < 8; ++k) {
    counts[k] = std::min<uint32_t>(1 + in.byte() % 8, ntris - pos);
    prims[k] = &order[pos];
    pos += counts[k];
  }
  const std::vector<uint8_t> enc = cluster::encode(src, prims, counts, k, true, true);
  // Lossy: behind the multi-leaf boxes the builder writes (the anchors are the stream's first
  // fields); `block` points at the cluster, `ml` holds both.
  std::vector<uint8_t> ml;
  const uint8_t* block_ptr = nullptr;
  if (!lossless) {
    cluster::MultiLeafPlanes mp;
    uint32_t anchor[3];
    ClusterHeader h0;
    std::memcpy(&h0, enc.data(), sizeof(h0));
    cluster::lossy_anchors(cluster::stream_of(enc.data()),
                           cluster::layout(h0, uint32_t(k), lat, false), anchor);
    SLIM_FUZZ_CHECK(cluster::multileaf_boxes(src, prims, counts, k, anchor, mp), "no box frame");
    SLIM_FUZZ_CHECK(cluster::has_fine_planes(h0) == mp.fine, "fine-planes bit differs");
    cluster::LatticeBoxes8 lb{};
    cluster::pack_planes(mp.q, &lb, nullptr);
    std::memcpy(lb.scale, mp.scale, 3);
    ml.resize(sizeof(lb) + enc.size());
    std::memcpy(ml.data(), &lb, sizeof(lb));
    std::memcpy(ml.data() + sizeof(lb), enc.data(), enc.size());
    block_ptr = ml.data() + sizeof(lb);
  } else {
    ml = enc;
    block_ptr = ml.data();
  }
  const std::vector<uint8_t>& block = enc;
  std::string why;
  SLIM_FUZZ_CHECK(cluster::check(block_ptr, block.size() - kClusterReadSlack, uint32_t(k), lat,
                                 lossless, &why, lossless ? nullptr : ml.data()),
                  why);
  for (int c = 0; c < k; ++c) {
    cluster::Decoded8 d;
    if (lossless)
      cluster::decode_child<true>(lat, block_ptr, uint32_t(k), c, d);
    else
      cluster::decode_child<false>(lat, block_ptr, uint32_t(k), c, d);
    SLIM_FUZZ_CHECK(d.n == int(counts[c]), "child size");
    // The child's triangles in the encoder's strip order: each decoded triangle (ids and corner
    // bits) matches one of the child's source triangles not matched yet.
    bool used[8] = {};
    for (int l = 0; l < d.n; ++l) {
      uint32_t g, p;
      if (lossless)
        cluster::decode_ids<true>(lat, block_ptr, uint32_t(k), uint32_t(d.first + l), g, p);
      else
        cluster::decode_ids<false>(lat, block_ptr, uint32_t(k), uint32_t(d.first + l), g, p);
      bool found = false;
      for (int m = 0; m < d.n && !found; ++m) {
        const uint32_t t = prims[c][m];
        if (used[m] || g != geom[t] || p != prim[t]) continue;
        bool same = true;
        for (int j = 0; j < 3; ++j)
          for (int a = 0; a < 3; ++a)
            same &= fuzz::same_bits(d.v[j][a][l], decoded[tris[3 * t + j]][a]);
        used[m] = found = same;
      }
      SLIM_FUZZ_CHECK(found, "decoded triangle (vertex bits and ids) not in its child");
    }
  }
  if (!lossless) multileaf_boxes(lat, ml, decoded, tris, prims, counts, k);
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  if (size < 1) return 0;
  const uint8_t mode = data[0];
  const uint32_t children = 1 + (mode & 7);
  const bool lossless = mode & 8;
  // 1. The rest of the input as a block, in a buffer of exactly its size plus the read slack.
  std::vector<uint8_t> block(data + 1, data + size);
  const size_t n = block.size();
  block.resize(n + kClusterReadSlack, 0);
  block.shrink_to_fit();
  // Lossy, twice: on a lattice of 24-bit anchors and power-of-two steps (the seeds') and on one of
  // narrower anchors (0..20 bits per axis, from the input's size) and steps (8 + m) 2^e / 8.
  ClusterLattice lat;
  lat.origin[0] = 1.0f;
  for (int a = 0; a < 3; ++a) lat.step[a] = std::ldexp(0.25f, a);
  for (int pass = 0; pass < (lossless ? 1 : 2); ++pass) {
    if (pass == 1)
      for (int a = 0; a < 3; ++a) {
        lat.anchor_bits[a] = uint8_t((size >> (5 * a)) % (cluster::kFineStepCodeBits + 1));
        lat.step[a] = std::ldexp(1.25f, a - 2);
      }
    if (!cluster::check(block.data(), n, children, lat, lossless, nullptr)) continue;
    if (lossless)
      decode_all<true>(lat, block.data(), children);
    else
      decode_all<false>(lat, block.data(), children);
  }
  // 4. Lossy: the first 39 bytes as the multi-leaf's boxes, the rest as the cluster behind them,
  // in a buffer of exactly their size plus the read slack.
  constexpr size_t kBoxes = sizeof(cluster::LatticeBoxes8);
  if (!lossless && n > kBoxes) {
    std::vector<uint8_t> ml(data + 1, data + size);
    ml.resize(n + kClusterReadSlack, 0);
    ml.shrink_to_fit();
    if (cluster::check(ml.data() + kBoxes, n - kBoxes, children, lat, false, nullptr, ml.data())) {
      decode_all<false>(lat, ml.data() + kBoxes, children);
      uint8_t q[6][8];
      const uint8_t* lows = cluster::plane_lows(ml.data() + kBoxes);
      cluster::lattice_planes(ml.data(), lows, q);
#if defined(SLIM_SIMD_AVX2)
      __m256i planes[6];
      cluster::lattice_planes_avx2(ml.data(), lows, planes);
      for (uint32_t p = 0; p < 6; ++p) {
        alignas(32) uint32_t v[8];
        _mm256_store_si256(reinterpret_cast<__m256i*>(v), planes[p]);
        for (int i = 0; i < 8; ++i)
          SLIM_FUZZ_CHECK(v[i] == q[p][i], "the vector planes differ from the scalar ones");
      }
#endif
    }
  }
  // 2. Round trip.
  Reader in{data + 1, size - 1};
  const uint32_t ntris = 1 + std::min<uint32_t>(63, 4 * (mode >> 4) + in.byte() % 4);
  round_trip(in, ntris, lossless);
  return 0;
}
