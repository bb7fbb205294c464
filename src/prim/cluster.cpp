// Cluster encoder and checker (prim/cluster.h).
#include "prim/cluster.h"

#include <algorithm>
#include <array>
#include <atomic>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <iterator>
#include <memory>
#include <stdexcept>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include "bvh/bvh8.h"
#include "core/large_array.h"

namespace slim::cluster {

namespace {

// Writes LSB-first fields of up to 32 bits; `out` holds 8 bytes beyond the last field's byte.
struct BitWriter {
  std::vector<uint8_t>& out;
  size_t base;
  uint64_t pos = 0;
  void put(uint32_t v, uint32_t w) {
    if (w == 0) return;
    uint64_t x;
    uint8_t* p = out.data() + base + (pos >> 3);
    std::memcpy(&x, p, 8);
    x |= (uint64_t(v) & ((uint64_t(1) << w) - 1)) << (pos & 7);
    std::memcpy(p, &x, 8);
    pos += w;
  }
};

// The decimal code of f with k digits: q = round(f x 10^k) (two's complement), or kNoDecimal when
// q is beyond 32 bits or decimal_coord(q, k) is not f bit for bit (f = -0, not finite, or more
// digits than k).
constexpr uint32_t kNoDecimal = 0x80000000u;  // -2^31: never a valid code (|q| < 2^31 below)
uint32_t decimal_code(float f, uint32_t k) {
  const double q = decimal_q(f, k);
  if (!(std::fabs(q) < 2147483648.0)) return kNoDecimal;
  const uint32_t code = uint32_t(int32_t(q));
  const float g = decimal_coord(code, k);
  return std::memcmp(&g, &f, 4) == 0 ? code : kNoDecimal;
}

// The smallest k >= start, k <= kMaxDecimalDigits, for which every coordinate of axis a (float
// keys, 3 per vertex, nv vertices) has a decimal code, else kMaxDecimalDigits + 1. A coordinate
// with k digits nearly always has k + 1 too (the same real value), so one pass raises k past each
// coordinate that fails; a last pass checks every coordinate at the final k (and raises it again
// in the rare other case).
uint32_t decimal_digits(const uint32_t* keys, uint32_t nv, int a, uint32_t start) {
  uint32_t k = start;
  for (;;) {
    for (uint32_t i = 0; i < nv; ++i)
      while (decimal_code(key_float(keys[3 * i + a]), k) == kNoDecimal)
        if (++k > kMaxDecimalDigits) return k;
    bool all = true;
    for (uint32_t i = 0; i < nv && all; ++i)
      all = decimal_code(key_float(keys[3 * i + a]), k) != kNoDecimal;
    if (all) return k;
    if (++k > kMaxDecimalDigits) return k;
  }
}

// The digits of the decimal mode: per axis the smallest k_a that gives back every coordinate of
// the axis, at least k - 3 (the header's 2 bits per axis), k the largest; false if an axis has
// none.
bool decimal_axes(const uint32_t* keys, uint32_t nv, uint32_t& k, uint32_t (&ka)[3]) {
  k = 0;
  for (int a = 0; a < 3; ++a) {
    ka[a] = decimal_digits(keys, nv, a, 0);
    if (ka[a] > kMaxDecimalDigits) return false;
    k = std::max(k, ka[a]);
  }
  for (bool changed = true; changed;) {
    changed = false;
    for (int a = 0; a < 3; ++a) {
      ka[a] = decimal_digits(keys, nv, a, std::max(ka[a], k >= 3 ? k - 3 : 0u));
      if (ka[a] > kMaxDecimalDigits) return false;
      if (ka[a] > k) {
        k = ka[a];
        changed = true;
      }
    }
  }
  return true;
}

}  // namespace

DecodeCache* allocate_decode_cache() {
  // Owns the thread's cache; at thread exit frees it and clears the pointer.
  struct Owner {
    std::unique_ptr<DecodeCache> cache;
    ~Owner() { t_decode_cache = nullptr; }
  };
  static thread_local Owner owner;
  if (!owner.cache) owner.cache = std::make_unique<DecodeCache>();
  t_decode_cache = owner.cache.get();
  return t_decode_cache;
}
uint64_t next_cache_tag() {
  static std::atomic<uint64_t> next{1};
  return next.fetch_add(1, std::memory_order_relaxed);
}

// Whether the k children's 8-bit planes q (in a frame of these extents) stay fine: their coarse
// planes (LatticeBoxes8: rounded outward to multiples of 4) would grow the children's boxes by
// more than kCoarsePlaneGrowth in surface area.
static bool fine_planes(const uint8_t (*q)[8], const float* extent, int k) {
  double area = 0.0, coarse_area = 0.0;
  for (int c = 0; c < k; ++c) {
    double d[3], dc[3];
    for (int a = 0; a < 3; ++a) {
      const int lo = q[2 * a][c], hi = q[2 * a + 1][c];
      d[a] = double(hi - lo) * extent[a];
      dc[a] = double(coarse_plane(2 * a + 1, uint8_t(hi)) - coarse_plane(2 * a, uint8_t(lo))) *
              extent[a];
    }
    area += d[0] * d[1] + d[1] * d[2] + d[2] * d[0];
    coarse_area += dc[0] * dc[1] + dc[1] * dc[2] + dc[2] * dc[0];
  }
  return coarse_area > (1.0 + kCoarsePlaneGrowth) * area;
}

bool multileaf_boxes(const ClusterSource& s, const uint32_t* const* prims, const uint32_t* counts,
                     int k, const uint32_t* anchor, MultiLeafPlanes& out) {
  Box3f boxes[8], all;
  for (int c = 0; c < k; ++c) {
    for (uint32_t j = 0; j < counts[c]; ++j)
      for (int q = 0; q < 3; ++q) boxes[c].extend(s.vertices[s.tris[3 * size_t(prims[c][j]) + q]]);
    all.extend(boxes[c]);
  }
  // The anchors as the stream's start holds them (write_box_frame reads them there); a thread's
  // own buffer, kept between calls.
  thread_local std::vector<uint8_t> head;
  head.assign(sizeof(ClusterHeader) + 24, 0);
  BitWriter aw{head, sizeof(ClusterHeader)};
  for (int a = 0; a < 3; ++a) aw.put(anchor[a], s.lattice.anchor_bits[a]);
  float start[4], extent[4];
  LatticeBoxes8 lb{};
  if (!write_box_frame(s.lattice, head.data(), all, lb, start, extent)) return false;
  std::memcpy(out.scale, lb.scale, 3);
  quantize_planes(start, extent, boxes, k, out.q);
  out.fine = fine_planes(out.q, extent, k);
  if (!out.fine)
    for (int p = 0; p < 6; ++p)
      for (int c = 0; c < 8; ++c) out.q[p][c] = coarse_plane(uint32_t(p), out.q[p][c]);
  return true;
}

bool write_multileaf_boxes(const ClusterLattice& lat, bool lossless, const uint8_t* data, int k,
                           const Box3f* boxes, uint8_t* header) {
  Box3f all;
  for (int c = 0; c < k; ++c) all.extend(boxes[c]);
  float start[4], extent[4];
  uint8_t q[6][8];
  if (lossless) {
    ExactBoxes8 b;
    std::memcpy(&b, header, sizeof(b));
    if (!write_exact_box_frame(data, all, b, start, extent)) return false;
    quantize_planes(start, extent, boxes, k, b.q);
    std::memcpy(header, &b, sizeof(b));
    return true;
  }
  LatticeBoxes8 b;
  std::memcpy(&b, header, sizeof(b));
  if (!write_box_frame(lat, data, all, b, start, extent)) return false;
  quantize_planes(start, extent, boxes, k, q);
  uint8_t lows[kPlaneLowBytes];
  pack_planes(q, &b, lows);
  ClusterHeader h;
  std::memcpy(&h, data, sizeof(h));
  // The encoder's planes: fine ones are these (their low bits in the cluster), coarse ones these
  // rounded outward, which the coarse values are.
  if (has_fine_planes(h) != fine_planes(q, extent, k) ||
      (has_fine_planes(h) && std::memcmp(lows, data + sizeof(ClusterHeader), sizeof(lows)) != 0))
    throw std::logic_error("cluster: multi-leaf planes differ from the encoder's");
  std::memcpy(header, &b, sizeof(b));
  return true;
}

std::vector<uint8_t> encode(const ClusterSource& s, const uint32_t* const* prims,
                            const uint32_t* counts, int k, bool slack, bool ranges) {
  if (k < 1 || k > 8) throw std::logic_error("cluster: 1..8 children");
  ClusterHeader h{};
  uint32_t sizes = 0, ntris = 0;
  for (int c = 0; c < k; ++c) {
    if (counts[c] < 1 || counts[c] > 8) throw std::logic_error("cluster: 1..8 triangles a child");
    sizes |= (counts[c] - 1) << (3 * c);
    ntris += counts[c];
  }
  static_assert(kMaxTriangles == 8 * 8, "the checks above keep ntris within kMaxTriangles");
  for (int i = 0; i < 3; ++i) h.sizes[i] = uint8_t(sizes >> (8 * i));
  // The triangles' corners as provisional vertex numbers (distinct codes in order of first
  // sight), in child order.
  // Per triangle and per corner, arrays of the cluster's size (ntris <= kMaxTriangles, above); the
  // vectors further on are a thread's own, kept between calls: no allocation but the first.
  std::array<uint8_t, 3> corners[kMaxTriangles];
  uint32_t tris[kMaxTriangles];  // input triangles in child order
  uint32_t nt = 0;               // triangles read
  static_assert(3 * kMaxTriangles <= CodeNumbering::kMaxVertices, "at most one vertex a corner");
  CodeNumbering pv;
  for (int c = 0; c < k; ++c)
    for (uint32_t j = 0; j < counts[c]; ++j) {
      const uint32_t t = prims[c][j];
      tris[nt] = t;
      std::array<uint8_t, 3> tc{};
      for (int q = 0; q < 3; ++q)
        tc[q] = uint8_t(pv.number(&s.codes[3 * size_t(s.tris[3 * size_t(t) + q])]));
      corners[nt++] = tc;
    }
  const uint32_t nv = pv.size();
  if (nv > 255) throw std::logic_error("cluster: more than 255 vertices");
  h.nverts = uint8_t(nv);

  // Strips: per child, two greedy strips from each start triangle (the next triangle is the first
  // left that continues the last one, else the first left as a restart; the second strip takes
  // first a triangle whose ids follow the last one's, `near` below, and runs only where it would
  // take another triangle and the first strip has no more restarts than the best so far); the one
  // with the fewest restarts wins, of those the one with the most triangles whose ids follow their
  // predecessor's (the ids' repeat and step bits can take those without an entry).
  // steps: (index into `tris`, p, e) in decode order; p = 3 for a strip's first triangle. A step
  // after a step with p = q may not take the previous step's edge q + 1 (the one it came in by:
  // its 1-bit edge names q or q + 2).
  struct Step {
    uint32_t i;
    uint8_t p, e;
  };
  // The edges e of prev over which t continues it (bit e of the result), with the corner p of t
  // in p[e]: t's corners p + 1 and p + 2 are prev's e + 1 and e (every pair of corners tested: a
  // degenerate triangle, two corners on one lattice point, may continue over several).
  auto continues = [&](uint32_t prev, uint32_t t, uint8_t(&p)[3]) {
    const auto& P = corners[prev];
    const auto& T = corners[t];
    uint32_t edges = 0;
    for (int ee = 0; ee < 3; ++ee)
      for (int pp = 0; pp < 3; ++pp)
        if (T[(pp + 1) % 3] == P[(ee + 1) % 3] && T[(pp + 2) % 3] == P[ee]) {
          p[ee] = uint8_t(pp);
          edges |= 1u << ee;
          break;
        }
    return edges;
  };
  Step steps[kMaxTriangles];
  uint32_t nsteps = 0;
  uint32_t child_step[9] = {};  // first step of each child (k <= 8)
  for (int c = 0, first = 0; c < k; first += int(counts[c]), ++c) {
    const uint32_t n = counts[c];
    // How triangle b of the child continues triangle a: over a's edges cont_e[a][b] (a bit each),
    // with p in cont_p[a][b][e]; bit b of cont[x][a] if over an edge other than x (x = 3: any
    // edge), a step entered by edge x then taking the lowest such edge. Every start tries the
    // same pairs, so each pair is tested once here (8 x 8 tests, not up to 8 x 8 x 8), and the
    // search takes the lowest unused triangle that continues (else the lowest unused; the second
    // strip first the lowest of them whose ids follow) as a bit scan.
    // A pair shares an edge only if two corners of one are corners of the other. With each corner
    // as bit (vertex mod 64) of a mask, where one of the two has three distinct bits they share
    // two corners only if their masks have two bits in common: other pairs skip the test.
    uint64_t mask[8];
    bool three[8];  // the three bits differ
    for (uint32_t a = 0; a < n; ++a) {
      const auto& T = corners[uint32_t(first) + a];
      mask[a] = (uint64_t(1) << (T[0] & 63)) | (uint64_t(1) << (T[1] & 63)) |
                (uint64_t(1) << (T[2] & 63));
      three[a] = __builtin_popcountll(mask[a]) == 3;
    }
    uint32_t cont[4][8] = {};
    uint8_t cont_p[8][8][3], cont_e[8][8];
    auto link = [&](uint32_t a, uint32_t b, uint32_t edges) {
      cont_e[a][b] = uint8_t(edges);
      for (int x = 0; x < 4; ++x)
        if (edges & ~(1u << x)) cont[x][a] |= 1u << b;
    };
    // Between two triangles of three distinct corners the test runs once: b continues a over a's
    // edge e with its corner p exactly when a continues b over b's edge p + 1 with its corner
    // e + 2 (the shared edge reversed; distinct corners match each edge at most once).
    for (uint32_t a = 0; a < n; ++a)
      for (uint32_t b = a + 1; b < n; ++b) {
        const bool both = three[a] && three[b];
        if ((three[a] || three[b]) && __builtin_popcountll(mask[a] & mask[b]) < 2) continue;
        const uint32_t ab = continues(uint32_t(first) + a, uint32_t(first) + b, cont_p[a][b]);
        link(a, b, ab);
        uint32_t ba = 0;
        if (both) {
          for (uint32_t e = 0; e < 3; ++e)
            if ((ab >> e) & 1) {
              const uint32_t f = (cont_p[a][b][e] + 1u) % 3;
              cont_p[b][a][f] = uint8_t((e + 2) % 3);
              ba |= 1u << f;
            }
        } else {
          ba = continues(uint32_t(first) + b, uint32_t(first) + a, cont_p[b][a]);
        }
        link(b, a, ba);
      }
    // Bit b of near[a]: triangle b's ids follow a's, its primID a's or one above or below with
    // the same geomID: after a in decode order, the ids' repeat and step bits (cluster.h) can take
    // b without an entry. near_prev: the same after the previous child's last triangle.
    // Lanes past n are zeros, cleared from the masks (a fixed 8 lanes: the compiler vectorizes).
    uint32_t pid[8] = {}, gid[8] = {};
    for (uint32_t a = 0; a < n; ++a) {
      pid[a] = s.prim_ids[tris[uint32_t(first) + a]];
      gid[a] = s.geom_ids[tris[uint32_t(first) + a]];
    }
    const uint32_t all = (1u << n) - 1;
    auto near_of = [&](uint32_t p, uint32_t g) {  // primID p - 1, p or p + 1 and geomID g
      uint32_t m = 0;
      for (uint32_t b = 0; b < 8; ++b) m |= uint32_t((pid[b] - p + 1 <= 2) & (gid[b] == g)) << b;
      return m & all;
    };
    uint32_t near[8], near_prev = 0;
    for (uint32_t a = 0; a < n; ++a) near[a] = near_of(pid[a], gid[a]) & ~(1u << a);
    if (nsteps) {
      const uint32_t t = tris[steps[nsteps - 1].i];
      near_prev = near_of(s.prim_ids[t], s.geom_ids[t]);
    }
    Step best[8], cur[8];
    // The strip from `start` into cur, returning its restarts; the first strip sets `differs` if
    // the second would take another triangle somewhere.
    auto walk = [&]<bool kPrefer>(uint32_t start, bool& differs) {
      uint32_t used = 1u << start;
      uint32_t restarts = 0;
      uint32_t last = start;  // the child's index of cur[j - 1]
      uint32_t x = 3;         // the edge cur[j - 1] came in by (3: none)
      cur[0] = {uint32_t(first) + start, 3, 0};
      for (uint32_t j = 1; j < n; ++j) {
        // The triangles that continue the strip, else all left (a restart): the first of them,
        // or the first whose ids follow the last triangle's.
        const uint32_t go = cont[x][last] & ~used, opts = go ? go : all & ~used;
        const uint32_t w = opts & near[last];
        uint32_t b;
        if constexpr (kPrefer) {
          b = uint32_t(__builtin_ctz(w ? w : opts));
        } else {
          b = uint32_t(__builtin_ctz(opts));
          differs |= w && !((w >> b) & 1);
        }
        if (go) {
          const uint32_t ee = uint32_t(__builtin_ctz(cont_e[last][b] & ~(1u << x)));
          const uint8_t pp = cont_p[last][b][ee];
          cur[j] = {uint32_t(first) + b, pp, uint8_t(ee)};
          x = pp == 2 ? 0 : pp + 1u;
        } else {
          cur[j] = {uint32_t(first) + b, 3, 0};
          x = 3;
          restarts++;
        }
        last = b;
        used |= 1u << last;
      }
      return restarts;
    };
    // The triangles of cur whose ids follow their predecessor's.
    auto near_count = [&] {
      uint32_t m = (near_prev >> (cur[0].i - uint32_t(first))) & 1;
      for (uint32_t j = 1; j < n; ++j)
        m += (near[cur[j - 1].i - uint32_t(first)] >> (cur[j].i - uint32_t(first))) & 1;
      return m;
    };
    uint32_t best_restarts = ~0u, best_near = 0;
    auto keep = [&](uint32_t restarts) {
      if (restarts > best_restarts) return;
      const uint32_t m = near_count();
      if (restarts == best_restarts && m <= best_near) return;
      best_restarts = restarts;
      best_near = m;
      std::copy(cur, cur + n, best);
    };
    for (uint32_t start = 0; start < n; ++start) {
      bool differs = false;
      const uint32_t restarts = walk.template operator()<false>(start, differs);
      keep(restarts);
      if (differs && restarts <= best_restarts)
        keep(walk.template operator()<true>(start, differs));
    }
    child_step[c] = nsteps;
    std::copy(best, best + n, steps + nsteps);
    nsteps += n;
  }
  child_step[k] = nsteps;

  // Vertex numbers in order of first reference; each reference new or a distance back.
  int number[255];  // nv <= 255
  std::fill(number, number + nv, -1);
  thread_local std::vector<uint32_t> codes;  // 3 per vertex, final numbering
  codes.resize(3 * size_t(nv));
  // Per reference (at most 3 a triangle): -1 new, else the distance back.
  int32_t refs[3 * kMaxTriangles];
  uint32_t nrefs = 0;
  uint32_t child_cnt[8] = {}, child_refs[9] = {};
  uint32_t cnt = 0, max_back = 0;
  auto reference = [&](uint8_t v) {
    if (number[v] < 0) {
      number[v] = int(cnt);
      std::copy(pv.codes(v), pv.codes(v) + 3, codes.data() + 3 * cnt++);
      refs[nrefs++] = -1;
    } else {
      const uint32_t d = cnt - 1 - uint32_t(number[v]);
      max_back = std::max(max_back, d);
      refs[nrefs++] = int32_t(d);
    }
  };
  for (int c = 0; c < k; ++c) {
    child_cnt[c] = cnt;
    child_refs[c] = nrefs;
    for (uint32_t j = child_step[c]; j < child_step[c + 1]; ++j) {
      const Step& st = steps[j];
      if (st.p == 3)
        for (int q = 0; q < 3; ++q) reference(corners[st.i][q]);
      else
        reference(corners[st.i][st.p]);
    }
  }
  child_refs[k] = nrefs;
  if (cnt != nv) throw std::logic_error("cluster: a vertex outside the strips");
  const uint32_t ib = bit_width(max_back);
  h.ib = uint8_t(ib);
  // The control bits of step j (not a child's first): 2 a restart, 4 a strip step after a
  // restart or a first triangle, 3 after a strip step.
  auto control_bits = [&](uint32_t j) {
    return steps[j].p == 3 ? 2u : steps[j - 1].p == 3 ? 4u : 3u;
  };
  // Topology bits per child: the control bits, 1 or 1 + ib a reference.
  uint32_t child_off[9] = {};
  for (int c = 0; c < k; ++c) {
    uint32_t b = 0;
    for (uint32_t j = child_step[c] + 1; j < child_step[c + 1]; ++j) b += control_bits(j);
    for (uint32_t r = child_refs[c]; r < child_refs[c + 1]; ++r) b += refs[r] < 0 ? 1 : 1 + ib;
    child_off[c + 1] = child_off[c] + b;
  }
  if (child_off[k] > 0x7ff) throw std::logic_error("cluster: topology beyond 2047 bits");
  // The child table: per field the narrowest residual width of the linear prediction (12 bits
  // hold any offset residual; the first new vertex plain if 5 bits do not hold its residuals),
  // with Layout's slopes and biases.
  {
    const uint32_t inv = kInvTris.v[ntris];
    const uint32_t ts = (child_off[k] * inv) >> 4, vs = (nv * inv) >> 4;
    int32_t tlo = 0, thi = 0, vlo = 0, vhi = 0;
    for (int c = 1, first = 0; c < k; ++c) {
      first += int(counts[c - 1]);
      const int32_t tr = int32_t(child_off[c]) - int32_t((uint32_t(first) * ts) >> 12);
      const int32_t vr = int32_t(child_cnt[c]) - int32_t((uint32_t(first) * vs) >> 12);
      tlo = std::min(tlo, tr);
      thi = std::max(thi, tr);
      vlo = std::min(vlo, vr);
      vhi = std::max(vhi, vr);
    }
    // The residuals lo..hi fit w bits with bias 2^(w - 1).
    auto fits = [](int32_t lo, int32_t hi, uint32_t w) {
      const int32_t b = int32_t(1u << (w - 1));
      return lo >= -b && hi <= int32_t((1u << w) - 1) - b;
    };
    uint32_t to = 0, vo = 0;
    while (to < 7 && !fits(tlo, thi, to + 5)) ++to;
    if (!fits(tlo, thi, to + 5))  // |residual| <= child_off[k] < 2^11: 12 bits hold it
      throw std::logic_error("cluster: child table offset beyond 12 bits");
    while (vo < kPlainVertexCode && !fits(vlo, vhi, vo + 3)) ++vo;
    h.tbits = uint16_t(child_off[k] | to << 11 | vo << 14);
  }

  uint32_t anchor[3];
  for (int a = 0; a < 3; ++a) {
    uint32_t lo = codes[a], hi = codes[a];
    for (uint32_t i = 0; i < nv; ++i) {
      lo = std::min(lo, codes[3 * i + a]);
      hi = std::max(hi, codes[3 * i + a]);
    }
    anchor[a] = lo;
    h.bits[a] = uint8_t(bit_width(hi - lo));
  }
  if (!s.lossless)
    for (int a = 0; a < 3; ++a)
      if (anchor[a] >> s.lattice.anchor_bits[a])
        throw std::logic_error("cluster: lattice code beyond the lattice's anchor bits");
  // Lossy, 2..8 children: per-child vertex ranges (cluster.h) when every vertex lies in its
  // child's range and they take fewer bits. The multi-leaf boxes are those the build writes
  // (write_box_frame and quantize_planes of the children's boxes, which are the BVH2 leaves':
  // the union of their triangles' decoded boxes), so the decoder derives the same ranges.
  uint32_t range_lo[8][3] = {}, radix[8][3] = {}, range_w[8] = {};
  uint64_t vertex_bits = kPlainVertexBits;
  // A lossy multi-leaf's planes: fine or coarse (its boxes, LatticeBoxes8).
  MultiLeafPlanes lb{};
  const bool planes = !s.lossless && ranges && multileaf_boxes(s, prims, counts, k, anchor, lb);
  if (planes && k >= 2) {
    bool ok = true;
    for (int a = 0; a < 3 && ok; ++a) ok = uint32_t(lb.scale[a] >> 3) <= kMaxRangeScaleExp;
    if (ok) {
      uint64_t bits = 0;
      for (int c = 0; c < k && ok; ++c) {
        // Every child's radices at most 2^24 and vertices at most kMaxRangeVertexBits (check()),
        // a child without new vertices too.
        for (int a = 0; a < 3; ++a) {
          plane_range(lb.q[2 * a][c], lb.q[2 * a + 1][c], lb.scale[a], range_lo[c][a], radix[c][a]);
          ok &= radix[c][a] - 1 < 1u << 24;
        }
        range_w[c] = radix_bits(radix[c][0], radix[c][1], radix[c][2]);
        ok &= range_w[c] <= kMaxRangeVertexBits;
        const uint32_t end = c + 1 < k ? child_cnt[c + 1] : nv;
        for (uint32_t i = child_cnt[c]; i < end && ok; ++i)
          for (int a = 0; a < 3; ++a) {
            const uint32_t off = codes[3 * i + a] - anchor[a] - range_lo[c][a];
            ok &= codes[3 * i + a] >= anchor[a] + range_lo[c][a] && off < radix[c][a];
          }
        bits += uint64_t(end - child_cnt[c]) * range_w[c];
      }
      if (ok && bits < uint64_t(nv) * (h.bits[0] + h.bits[1] + h.bits[2])) {
        vertex_bits = bits;
        h.bits[0] |= 0x80;
      }
    }
  }
  // Lossless: the decimal mode when its codes take fewer vertex bits than the float keys.
  uint32_t digits = 0, ka[3];
  if (s.lossless && decimal_axes(codes.data(), nv, digits, ka)) {
    int32_t lo[3], hi[3];
    thread_local std::vector<uint32_t> qs;
    qs.resize(3 * size_t(nv));
    for (uint32_t i = 0; i < nv; ++i)
      for (int a = 0; a < 3; ++a) qs[3 * i + a] = decimal_code(key_float(codes[3 * i + a]), ka[a]);
    uint32_t dec_bits = 0, key_bits = 0;
    for (int a = 0; a < 3; ++a) {
      lo[a] = hi[a] = int32_t(qs[a]);
      for (uint32_t i = 0; i < nv; ++i) {
        lo[a] = std::min(lo[a], int32_t(qs[3 * i + a]));
        hi[a] = std::max(hi[a], int32_t(qs[3 * i + a]));
      }
      dec_bits += bit_width(uint32_t(hi[a]) - uint32_t(lo[a]));
      key_bits += h.bits[a];
    }
    if (dec_bits < key_bits) {
      codes.swap(qs);
      for (int a = 0; a < 3; ++a) {
        anchor[a] = uint32_t(lo[a]);
        h.bits[a] = uint8_t(bit_width(uint32_t(hi[a]) - uint32_t(lo[a])) | (digits - ka[a]) << 6);
      }
      h.ib = uint8_t(ib | (1 + digits) << 4);
    }
  }
  // Triangles in decode order, their ids.
  thread_local std::vector<uint32_t> order;
  order.clear();
  order.reserve(ntris);
  for (uint32_t j = 0; j < nsteps; ++j) order.push_back(tris[steps[j].i]);
  uint32_t glo = ~0u, ghi = 0;
  thread_local std::vector<uint32_t> ids;
  ids.clear();
  ids.reserve(ntris);
  for (uint32_t t : order) {
    ids.push_back(s.prim_ids[t]);
    glo = std::min(glo, s.geom_ids[t]);
    ghi = std::max(ghi, s.geom_ids[t]);
  }
  std::sort(ids.begin(), ids.end());
  uint32_t prim_base = ids[0];  // with step bits: the smallest id with an entry (below)
  const uint32_t gb = bit_width(ghi - glo), hb = bit_width(glo);
  // PrimID runs: a run starts at the first sorted id that is 2^ob or more past the current start;
  // run i >= 1 stores e_i = start_i - prim_base - i x 2^ob (Elias-Fano: pb low bits, the high
  // part in unary). ob and pb are the widths with the fewest bits (run lows and highs + per
  // triangle run index and offset). The widest ob gives one run: the plain base + offset, for
  // meshes whose ids are in random order.
  auto runs_of = [&](const std::vector<uint32_t>& set, uint32_t ob, std::vector<uint32_t>& starts) {
    starts.clear();
    for (uint32_t id : set)
      if (starts.empty() || uint64_t(id - starts.back()) >= (uint64_t(1) << ob))
        starts.push_back(id);
  };
  // The Elias-Fano bits of m = nruns - 1 values of largest e_max at low width pb (~0: the highs
  // do not fit kMaxRunHighBits).
  auto ef_bits = [](uint64_t m, uint64_t e_max, uint32_t pb) {
    if (m == 0) return uint64_t(0);
    const uint64_t highs = m + (e_max >> pb);
    return highs > kMaxRunHighBits ? ~uint64_t(0) : m * pb + highs;
  };
  // Repeats: bit i of rep_mask if triangle i (decode order) has triangle i - 1's ids (the ids'
  // entries needed: ntris less them). (Local pointers: the thread_local vectors cost a TLS
  // look-up at each use.)
  const uint32_t* ord = order.data();
  // Step bits (cluster.h): triangle i with triangle i - 1's geomID and a primID one above or one
  // below it takes no entry either; with the double steps, two or three above or below.
  // up[m] / down[m]: bit i if triangle i's primID is its predecessor's plus / minus m.
  uint64_t rep_mask = 0, up[4] = {}, down[4] = {};
  for (uint32_t i = 1; i < ntris; ++i) {
    if (s.geom_ids[ord[i]] != s.geom_ids[ord[i - 1]]) continue;
    const uint32_t d = s.prim_ids[ord[i]] - s.prim_ids[ord[i - 1]];  // mod 2^32
    const uint64_t bit = uint64_t(1) << i;
    if (d == 0)
      rep_mask |= bit;
    else if (d <= 3)
      up[d] |= bit;
    else if (0u - d <= 3)
      down[0u - d] |= bit;
  }
  const uint32_t nrep = uint32_t(__builtin_popcountll(rep_mask));
  // Triangles without an entry with the step bits (mode 1) and with the double steps (mode 2).
  const uint64_t step_mask[3] = {rep_mask, rep_mask | up[1] | down[1],
                                 rep_mask | up[1] | down[1] | up[2] | down[2] | up[3] | down[3]};
  const uint32_t nstep[3] = {nrep, uint32_t(__builtin_popcountll(step_mask[1])),
                             uint32_t(__builtin_popcountll(step_mask[2]))};
  // The entries' ids in each step mode (the triangles without a step), sorted.
  thread_local std::vector<uint32_t> step_ids[3];
  for (int mode = 1; mode < 3; ++mode) {
    step_ids[mode].clear();
    if (nstep[mode] <= nstep[mode - 1]) continue;  // not tried (below)
    for (uint32_t i = 0; i < ntris; ++i)
      if (!((step_mask[mode] >> i) & 1)) step_ids[mode].push_back(s.prim_ids[ord[i]]);
    std::sort(step_ids[mode].begin(), step_ids[mode].end());
  }
  // Bits of the ids' entries at `entry` bits each, and whether the repeat bits make them fewer
  // (all ids; the step bits' runs are those of step_ids, below).
  auto entry_bits = [&](uint64_t entry, bool& repeats) {
    const uint64_t plain = ntris * entry, with = ntris + (ntris - nrep) * entry;
    repeats = with < plain;
    return repeats ? with : plain;
  };
  // The sizing pass counts the runs and finds the last start without storing them. Once one run
  // takes every id, a wider ob costs more bits each entry and cannot win: the search stops there.
  uint64_t best_bits = ~uint64_t(0);
  uint32_t best_ob = 0, best_pb = 0;
  bool repeats = false;
  int id_mode = 0;  // 0: no step bits (repeat bits or none); 1: step bits; 2: double steps
  // A mode that takes no more triangles than the one before only adds a plane: not tried. The
  // modes with fewer entries first: their sizes end the other modes' searches sooner (below).
  for (int mode = 2; mode >= 0; --mode) {
    if (mode && nstep[mode] <= nstep[mode - 1]) continue;
    const std::vector<uint32_t>& set = mode ? step_ids[mode] : ids;
    const uint64_t nmin = ntris - nstep[mode];  // entries at least
    for (uint32_t ob = 0; ob <= 32; ++ob) {
      // Every entry takes at least ob + gb bits (entry_bits, with or without the repeat bits), and
      // a step mode its planes: once that alone exceeds the best, no wider ob can take as few bits
      // (a tie goes on: a mode with fewer planes takes it).
      if (uint64_t(mode ? 1 + mode : 0) * ntris + nmin * (ob + gb) > best_bits) break;
      // The first id starts the first run (neither set is empty: the first triangle has no step).
      const uint32_t* ids_of = set.data();
      const size_t nids = set.size();
      const uint64_t width = uint64_t(1) << ob;
      uint64_t nstarts = 1;
      uint32_t last = ids_of[0];
      for (size_t i = 1; i < nids; ++i) {
        const bool start = uint64_t(ids_of[i] - last) >= width;
        last = start ? ids_of[i] : last;
        nstarts += start;
      }
      const uint64_t m = nstarts - 1;
      const uint64_t e_max = uint64_t(last - set[0]) - (m << ob);
      // ef_bits falls with pb while a wider pb takes more than m bits off the highs: that gain,
      // (e_max >> pb) - (e_max >> (pb + 1)), falls with pb, so the fewest bits are at the first pb
      // (from where the highs fit) that gains no more. At pb <= bit_width(e_max) - bit_width(m) -
      // 2, e_max >> pb >= 2^(bit_width(m) + 1) > 2m, so the gain is more than m: the search starts
      // there.
      uint32_t pb = 0;
      if (m) {
        pb = uint32_t(
            std::max(0, int(bit_width(uint32_t(e_max))) - int(bit_width(uint32_t(m))) - 2));
        while (pb < 32 &&
               (m + (e_max >> pb) > kMaxRunHighBits || (e_max >> pb) - (e_max >> (pb + 1)) > m))
          ++pb;
      }
      const uint64_t ef = ef_bits(m, e_max, pb);
      bool with_repeats = true;
      const uint64_t entry = bit_width(uint32_t(m)) + ob + gb;
      const uint64_t bits =
          bit_width(set[0]) + ef +
          (mode ? (1 + uint64_t(mode)) * ntris + nmin * entry : entry_bits(entry, with_repeats));
      if (bits < best_bits || (bits == best_bits && mode < id_mode)) {  // ties: fewer planes
        best_bits = bits;
        best_ob = ob;
        best_pb = pb;
        repeats = mode == 1 || (mode == 0 && with_repeats);
        id_mode = mode;
      }
      if (nstarts == 1) break;
    }
  }
  thread_local std::vector<uint32_t> starts;
  starts.reserve(ntris);
  runs_of(id_mode ? step_ids[id_mode] : ids, best_ob, starts);
  prim_base = starts[0];
  const uint32_t bb = bit_width(prim_base);
  h.nruns = uint8_t(starts.size() | (id_mode ? 0x80 : 0));
  h.ob = uint8_t(best_ob | (planes && lb.fine ? 0x40 : 0) | (repeats ? 0x80 : 0));
  set_id_widths(h, best_pb, gb, bb, hb);
  // e_i of run i (i >= 1) and the run highs' length.
  const uint32_t* st = starts.data();
  const size_t nst = starts.size();
  auto run_e = [&](size_t i) { return uint64_t(st[i] - prim_base) - (uint64_t(i) << best_ob); };
  const uint64_t highs = nst > 1 ? (nst - 1) + (run_e(nst - 1) >> best_pb) : 0;
  const uint32_t nentries = id_mode || repeats ? ntris - nstep[id_mode] : ntris;

  const Layout L = layout(h, uint32_t(k), s.lattice, s.lossless, vertex_bits);
  if (L.ntris != ntris) throw std::logic_error("cluster: child sizes do not give the triangles");
  const uint64_t entries = uint64_t(nentries) * L.idbits;  // bits
  const uint64_t bytes = std::max<uint64_t>(
      data_bytes(h, uint32_t(k), s.lattice, s.lossless, entries + highs, vertex_bits),
      stream_offset(h) + kMinStreamBytes);
  std::vector<uint8_t> out(bytes + 8, 0);  // 8: 64-bit stores
  std::memcpy(out.data(), &h, sizeof(h));
  if (has_fine_planes(h)) pack_planes(lb.q, nullptr, out.data() + sizeof(ClusterHeader));
  BitWriter w{out, stream_offset(h)};
  for (int a = 0; a < 3; ++a) {
    if (s.lossless) {
      // The smallest coordinate's float, from which the decoder derives the anchor: decimal codes
      // are decimal_q of their floats and strictly increase with them, so the smallest
      // coordinate's code is the anchor (checked).
      const float f = decode_coord<true>(s.lattice, a, anchor[a], axis_mode(h, a));
      uint32_t fb;
      std::memcpy(&fb, &f, 4);
      if (lossless_anchor(fb, coord_mode(h), axis_digits(h, a)) != anchor[a])
        throw std::logic_error("cluster: lossless anchor not recovered from its coordinate");
      w.put(fb, 32);
    } else {
      w.put(anchor[a], L.aw[a]);
    }
  }
  w.put(prim_base, bb);
  w.put(glo, hb);
  for (int c = 1; c < k; ++c) {
    const uint32_t first = child_first(sizes, uint32_t(c));
    w.put(child_off[c] - predicted_offset(L, first), L.tb);
    w.put(child_cnt[c] - predicted_vertex(L, first), L.vbw);
  }
  if (vertex_bits != kPlainVertexBits)
    for (int c = 0; c < k; ++c)
      for (uint32_t i = child_cnt[c], end = c + 1 < k ? child_cnt[c + 1] : nv; i < end; ++i) {
        uint64_t o[3];
        for (int a = 0; a < 3; ++a) o[a] = codes[3 * i + a] - anchor[a] - range_lo[c][a];
        const uint64_t m = o[0] + radix[c][0] * (o[1] + radix[c][1] * o[2]);  // < 2^52
        w.put(uint32_t(m), std::min(range_w[c], 32u));
        if (range_w[c] > 32) w.put(uint32_t(m >> 32), range_w[c] - 32);
      }
  else
    for (uint32_t i = 0; i < nv; ++i)
      for (int a = 0; a < 3; ++a) w.put(codes[3 * i + a] - anchor[a], axis_bits(h, a));
  if (w.pos != L.runs) throw std::logic_error("cluster: vertex section size mismatch");
  for (size_t i = 1; i < nst; ++i) w.put(uint32_t(run_e(i)), best_pb);
  // The flag planes (cluster.h): the repeat bits, then with step bits the second plane: (repeat,
  // step) = (1, 0) repeat, (0, 1) one above, (1, 1) one below; with double steps (r, s, d) a step
  // of r ? -(s + 2d) : s + 2d, (1, 0, 0) a repeat.
  auto repeated = [&](uint32_t i) {
    return (id_mode || repeats) && ((step_mask[id_mode] >> i) & 1);
  };
  const uint64_t planes_of[3] = {rep_mask | down[1] | down[2] | down[3],  // r: repeats, steps down
                                 up[1] | down[1] | up[3] | down[3],       // s: steps of 1 and 3
                                 up[2] | down[2] | up[3] | down[3]};      // d: steps of 2 and 3
  for (uint32_t plane = 0; plane < id_flag_planes(h); ++plane)
    for (uint32_t i = 0; i < ntris; ++i)
      w.put(uint32_t((planes_of[plane] & step_mask[id_mode]) >> i) & 1, 1);
  size_t r = 0;
  auto put_ref = [&] {
    const int32_t d = refs[r++];
    if (d < 0)
      w.put(1, 1);
    else
      w.put(uint32_t(d) << 1, 1 + ib);
  };
  for (int c = 0; c < k; ++c)
    for (uint32_t j = child_step[c]; j < child_step[c + 1]; ++j) {
      const Step& st = steps[j];
      if (j > child_step[c]) {
        const uint32_t q = steps[j - 1].p;  // the edge after a step: q (b = 0) or q + 2 (b = 1)
        const uint32_t e = st.p == 3 || q == 3 ? st.e : uint32_t(st.e) != q;
        w.put(uint32_t(st.p) | e << 2, control_bits(j));
      }
      for (int q = 0; q < (st.p == 3 ? 3 : 1); ++q) put_ref();
    }
  if (w.pos != L.end || r != nrefs) throw std::logic_error("cluster: stream size mismatch");
  for (uint32_t i = 0; i < ntris; ++i) {
    if (repeated(i)) continue;
    const uint32_t id = s.prim_ids[ord[i]];
    const uint32_t run = uint32_t(std::upper_bound(st, st + nst, id) - st) - 1;
    w.put(run, L.rb);
    w.put(id - st[run], best_ob);
    w.put(s.geom_ids[ord[i]] - glo, gb);
  }
  if (w.pos != L.end + entries) throw std::logic_error("cluster: id entries size mismatch");
  // Run highs: run i's one bit at (e_i >> pb) + i - 1.
  for (size_t i = 1; i < nst; ++i) {
    const uint64_t pos = 8 * uint64_t(stream_offset(h)) + w.pos + (run_e(i) >> best_pb) + i - 1;
    out[pos >> 3] |= uint8_t(1u << (pos & 7));
  }
  out.resize(bytes + (slack ? kClusterReadSlack : 0));
  if (s.stats) {
    std::lock_guard<std::mutex> lock(s.stats->m);
    EncodeStats& st = *s.stats;
    st.clusters++;
    st.triangles += ntris;
    st.vertices += nv;
    st.position_bits += L.runs - L.verts;
    st.topology_bits +=
        topology_bits(h) + (L.verts - L.table) + 8 * (sizeof(h.sizes) + sizeof(h.tbits));
    // Run lows, repeat and step bits, entries, run highs, the bases, and idw (pb, gb, bb, hb),
    // nruns, ob.
    st.id_bits += (L.topo - L.runs) + entries + highs + bb + hb +
                  8 * (sizeof(h.idw) + sizeof(h.nruns) + sizeof(h.ob));
    // nverts, bits, ib; the fine planes' low bits; the anchors (lossless: the start floats).
    st.header_bits += 8 * (sizeof(h.nverts) + sizeof(h.bits) + sizeof(h.ib)) + L.bases +
                      8 * (stream_offset(h) - sizeof(ClusterHeader));
    st.decimal_clusters += coord_mode(h) != 0;
    st.plane_clusters += planes;
    st.fine_plane_clusters += has_fine_planes(h);
  }
  return out;
}

// The frames' extent per axis: the smallest code in [first, last] (extents grow with the code)
// whose extent, a positive finite float, puts the q = 255 plane (start + 255 x extent with the
// traversal's one fma) at or above the box's top. False if the start lies above the box or no code
// reaches it.
template <class Extent>
bool reaching_extents(const float* start, const Box3f& box, uint32_t (&first)[3], uint32_t last,
                      Extent&& extent_of, uint32_t (&code)[3]) {
  for (int a = 0; a < 3; ++a) {
    if (!(start[a] <= box.lo[a])) return false;
    for (code[a] = first[a];; ++code[a]) {
      if (code[a] > last) return false;
      const float e = extent_of(a, code[a]);
      if (e > 0.0f && std::isfinite(e) && std::fma(255.0f, e, start[a]) >= box.hi[a]) break;
    }
  }
  return true;
}

bool write_box_frame(const ClusterLattice& lat, const uint8_t* data, const Box3f& box,
                     LatticeBoxes8& boxes, float* start, float* extent) {
  // The anchors in a padded copy: box_start reads 16 bytes (the traversal has the read slack).
  const LatticeFrame f = lattice_frame(lat);
  uint8_t anchors[16] = {};
  std::memcpy(anchors, stream_of(data), (f.first[2] + f.width[2] + 7) / 8);
  box_start(f, anchors, start);
  // Scale bytes e << 3 | m, e <= kMaxBoxScaleExp. The search per axis starts at e = ilogb(need /
  // step) - 1, need = the span / 255: that extent, at most need / 2, cannot reach the top.
  uint32_t first[3] = {0, 0, 0}, sc[3];
  for (int a = 0; a < 3; ++a) {
    const float need = (box.hi[a] - start[a]) / 255.0f / lat.step[a];
    if (need >= 4.0f && std::isfinite(need))
      first[a] = std::min<uint32_t>(uint32_t(std::ilogb(need) - 1), kMaxBoxScaleExp) << 3;
  }
  if (!reaching_extents(
          start, box, first, ((kMaxBoxScaleExp + 1) << 3) - 1,
          [&](int a, uint32_t c) { return box_extent(lat, a, c); }, sc))
    return false;
  for (int a = 0; a < 3; ++a) {
    boxes.scale[a] = uint8_t(sc[a]);
    extent[a] = box_extent(lat, a, sc[a]);
  }
  extent[3] = 0.0f;
  return true;
}

bool write_exact_box_frame(const uint8_t* data, const Box3f& box, ExactBoxes8& boxes, float* start,
                           float* extent) {
  // The header and start floats in a padded copy: exact_box_start reads 16 bytes of the stream
  // (the traversal has the start floats, more stream and the read slack behind them).
  uint8_t head[sizeof(ClusterHeader) + 16] = {};
  std::memcpy(head, data, sizeof(ClusterHeader) + 12);
  exact_box_start(head, start);
  // Normal bfloat16s, from the one just below the exact 1/255 of the span.
  uint32_t first[3], b[3];
  for (int a = 0; a < 3; ++a) {
    const float need = (box.hi[a] - start[a]) / 255.0f;
    uint32_t u;
    std::memcpy(&u, &need, 4);
    first[a] = std::max<uint32_t>(u >> 16, 0x0080);
  }
  if (!reaching_extents(
          start, box, first, 0x7f7f, [](int, uint32_t c) { return bfloat16_float(uint16_t(c)); },
          b))
    return false;
  for (int a = 0; a < 3; ++a) {
    boxes.extent[a] = uint16_t(b[a]);
    extent[a] = bfloat16_float(uint16_t(b[a]));
  }
  extent[3] = 0.0f;
  return true;
}

std::string check_lattice(const ClusterLattice& lat, size_t* offset) {
  for (int a = 0; a < 3; ++a) {
    if (offset) *offset = offsetof(ClusterLattice, anchor_bits) + size_t(a);
    if (lat.anchor_bits[a] > 24)
      return "lattice anchor width " + std::to_string(lat.anchor_bits[a]) + " of axis " +
             std::to_string(a) + " beyond 24 bits";
    // (8 + m) 2^e / 8, m < 2^kStepMantissaBits, in [kMinLatticeStep, kMaxLatticeStep], so that
    // box_extent's products are exact and its largest scale stays finite.
    if (offset) *offset = offsetof(ClusterLattice, step) + 4 * size_t(a);
    const float st = lat.step[a];
    uint32_t u;
    std::memcpy(&u, &st, 4);
    const uint32_t mantissa = u & ((1u << 23) - 1);
    if (!(st >= float(kMinLatticeStep) && st <= float(kMaxLatticeStep)) ||
        (mantissa & ((1u << (23 - kStepMantissaBits)) - 1)) != 0) {
      char bits[16];
      std::snprintf(bits, sizeof bits, "0x%08x", u);
      return "lattice step of axis " + std::to_string(a) + " (float bits " + bits +
             ") is not (8 + m) 2^e / 8 (m < 8) in [2^-126, 2^102]";
    }
    // With m > 0 the codes stay below 2^kFineStepCodeBits: float(q) x step exact.
    if (offset) *offset = offsetof(ClusterLattice, anchor_bits) + size_t(a);
    if (mantissa && lat.anchor_bits[a] > kFineStepCodeBits)
      return "lattice anchor width " + std::to_string(lat.anchor_bits[a]) + " of axis " +
             std::to_string(a) + " beyond " + std::to_string(kFineStepCodeBits) +
             " bits with a step that is not a power of two";
  }
  return {};
}

bool check(const uint8_t* data, uint64_t size, uint32_t children, const ClusterLattice& lat,
           bool lossless, std::string* why, const uint8_t* boxes) {
  auto fail = [&](const std::string& m) {
    if (why) *why = "cluster: " + m;
    return false;
  };
  if (size < sizeof(ClusterHeader))
    return fail("shorter than its " + std::to_string(sizeof(ClusterHeader)) + "-byte header");
  if (children < 1 || children > 8) return fail("children must be 1..8");
  ClusterHeader h;
  std::memcpy(&h, data, sizeof(h));
  if (has_fine_planes(h) && (lossless || !boxes))
    return fail("fine-planes bit outside a lossy multi-leaf");
  if (size < stream_offset(h) + kMinStreamBytes)
    return fail("stream shorter than " + std::to_string(kMinStreamBytes) + " bytes");
  if (h.nverts < 1) return fail("no vertex");
  if (!lossless) {
    const std::string bad = check_lattice(lat);
    if (!bad.empty()) return fail(bad);
  }
  const uint32_t max_bits = lossless ? 32 : 24;
  const bool ranges = !lossless && has_ranges(h);
  for (int a = 0; a < 3; ++a)
    if (axis_bits(h, a) > max_bits || (!lossless && (h.bits[a] & (a ? 0xff : 0x7f)) > max_bits))
      return fail("axis width beyond " + std::to_string(max_bits) + " bits");
  if (index_bits(h) > 8 || run_low_bits(h) > 32 || geom_bits(h) > 32 || offset_bits(h) > 32 ||
      prim_base_bits(h) > 32 || geom_base_bits(h) > 32)
    return fail("index or id width beyond its limit");
  if (const uint32_t mode = coord_mode(h)) {
    if (!lossless) return fail("coordinate mode " + std::to_string(mode) + " in a lossy cluster");
    if (mode - 1 > kMaxDecimalDigits)
      return fail("decimal mode with " + std::to_string(mode - 1) + " digits (at most " +
                  std::to_string(kMaxDecimalDigits) + ")");
  }
  for (int a = 0; a < 3 && lossless; ++a) {
    const uint32_t below = uint32_t(h.bits[a]) >> 6;
    if (below && !coord_mode(h))
      return fail("axis " + std::to_string(a) + " digit offset outside the decimal mode");
    if (below && below > coord_mode(h) - 1)
      return fail("axis " + std::to_string(a) + " has " + std::to_string(below) +
                  " digits fewer than the cluster's " + std::to_string(coord_mode(h) - 1));
  }
  // The triangles are the children's sizes (1..64 for 1..8 children): no count to disagree with.
  const uint32_t sizes = child_sizes(h), ntris = tri_count(h, children);
  if (run_count(h) < 1 || run_count(h) > ntris)
    return fail("run count must be 1..the triangle count");
  if (children < 8 && (sizes >> (3 * children)) != 0)
    return fail("sizes given for children beyond the child count");
  Layout L = layout(h, children, lat, lossless);  // the plain vertex section, moved below
  if (stream_offset(h) + (L.verts + 7) / 8 > size)
    return fail("stream runs past the data (child table)");
  if (!ranges && data_bytes(h, children, lat, lossless, 0) > size)
    return fail("stream runs past the data");
  const uint8_t* bits = data + stream_offset(h);
  // Per-child vertex ranges: a multi-leaf's cluster of 2..8 children (its boxes right before it),
  // scales that keep the ranges' products in 32 bits, ascending firsts up to nverts, radices of at
  // most 2^24, vertices of at most kMaxRangeVertexBits.
  uint64_t vertex_bits = kPlainVertexBits;
  if (ranges) {
    if (children < 2 || !boxes)
      return fail("per-child vertex ranges outside a multi-leaf of 2..8 children");
    LatticeBoxes8 b;
    std::memcpy(&b, boxes, sizeof(b));
    for (int a = 0; a < 3; ++a)
      if (uint32_t(b.scale[a] >> 3) > kMaxRangeScaleExp)
        return fail("box scale exponent " + std::to_string(b.scale[a] >> 3) +
                    " beyond the vertex ranges' " + std::to_string(kMaxRangeScaleExp));
    uint32_t anchor[3];
    lossy_anchors(bits, L, anchor);
    uint8_t q[6][8];
    lattice_planes(boxes, plane_lows(data), q);
    ChildRanges r;
    child_ranges(h, L, bits, anchor, q, b.scale, children, r);
    for (uint32_t c = 0; c < children; ++c) {
      const uint32_t next = c + 1 < children ? r.first[c + 1] : h.nverts;
      if (r.first[c] > next || next > h.nverts)
        return fail("child " + std::to_string(c) + "'s first new vertex out of order");
      for (int a = 0; a < 3; ++a)
        if (r.radix[a][c] - 1 >= 1u << max_bits)
          return fail("child " + std::to_string(c) + "'s vertex range on axis " +
                      std::to_string(a) + " beyond 2^" + std::to_string(max_bits) + " steps");
      if (r.w[c] > kMaxRangeVertexBits)
        return fail("child " + std::to_string(c) + "'s vertices of " + std::to_string(r.w[c]) +
                    " bits, beyond " + std::to_string(kMaxRangeVertexBits));
    }
    vertex_bits = r.total;
    if (data_bytes(h, children, lat, lossless, 0, vertex_bits) > size)
      return fail("stream runs past the data (vertex ranges)");
  }
  if (ranges) with_vertex_bits(L, h, vertex_bits);
  // A decimal cluster's box start: per axis a float that is a decimal of the axis's digits (so
  // that the boxes start at the coordinate the anchor decodes to).
  if (lossless && coord_mode(h))
    for (int a = 0; a < 3; ++a) {
      float f;
      std::memcpy(&f, bits + 4 * a, 4);
      const uint32_t k = axis_digits(h, a);
      if (decimal_code(f, k) == kNoDecimal)  // lossless_anchor's code, and it decodes to f
        return fail("axis " + std::to_string(a) + " box start " + std::to_string(f) +
                    " is no decimal of " + std::to_string(k) + " digits");
    }
  // Readers of w <= 32 bits at pos to which bits at or beyond `limit` read as 0: the strips' and
  // repeat bits' (limit L.end, inside `size` or not: the decoders may read beyond it, with the
  // slack, but use none of those bits on a block this accepts) and the id entries' and run highs'
  // (limit: the data's end).
  auto reader = [&](uint64_t limit) {
    return [bits, limit](uint64_t pos, uint32_t w) {
      uint32_t v = 0;
      for (uint32_t b = 0; b < w && pos + b < limit; ++b)
        v |= uint32_t((bits[(pos + b) >> 3] >> ((pos + b) & 7)) & 1) << b;
      return v;
    };
  };
  const auto get = reader(L.end);
  for (uint32_t c = 0; c < children; ++c) {
    const uint32_t n = child_size(sizes, c);
    uint32_t idx[3][8];
    uint64_t end = 0;
    if (!decode_strip<true>(h, L, get, c, n, idx, &end)) return fail("malformed strip step");
    if (end > L.end) return fail("strip runs past the topology stream");
    for (uint32_t j = 0; j < n; ++j)
      for (int q = 0; q < 3; ++q)
        if (idx[q][j] >= h.nverts)
          return fail("vertex index " + std::to_string(idx[q][j]) + " >= vertex count");
  }
  // The flag planes (none set on triangle 0), the ids' entries inside the data, their run indices.
  uint32_t entries = ntris;
  const uint32_t planes = id_flag_planes(h);
  for (uint32_t plane = 0; plane < planes; ++plane)
    if (get(L.ids + uint64_t(plane) * ntris, 1)) return fail("repeat or step bit on triangle 0");
  if (planes)
    for (uint32_t t = 1; t < ntris; ++t) {
      uint32_t none = 0;
      for (uint32_t plane = 0; plane < planes; ++plane)
        none |= get(L.ids + uint64_t(plane) * ntris + t, 1);
      entries -= none;
    }
  if (data_bytes(h, children, lat, lossless, uint64_t(entries) * L.idbits, vertex_bits) > size)
    return fail("stream runs past the data (id entries)");
  const uint64_t avail = 8 * (size - stream_offset(h));
  const auto get_data = reader(avail);
  for (uint32_t e = 0; e < entries; ++e) {
    const uint32_t run = get_data(L.end + uint64_t(e) * L.idbits, L.rb);
    if (run >= run_count(h)) return fail("run index " + std::to_string(run) + " >= run count");
  }
  // The run highs: nruns - 1 one bits within kMaxRunHighBits bits and `size` (the stream's end).
  const uint64_t highs = L.end + uint64_t(entries) * L.idbits;
  uint64_t pos = highs;
  for (uint32_t ones = 0; ones + 1 < run_count(h); ++pos) {
    if (pos >= avail) return fail("stream runs past the data (run highs)");
    if (pos - highs >= kMaxRunHighBits)
      return fail("run highs beyond " + std::to_string(kMaxRunHighBits) + " bits");
    ones += get_data(pos, 1);
  }
  return true;
}

constexpr uint32_t kLatticeMax = (1u << 24) - 1;  // the largest lattice code

// The lattice code of coordinate x: the nearest lattice point, clamped to [0, kLatticeMax].
static uint32_t nearest_code(float x, float origin, double step) {
  return uint32_t(
      std::clamp(std::nearbyint((double(x) - double(origin)) / step), 0.0, double(kLatticeMax)));
}

// Per axis of `box` its extent and the decode's rounding: half an ulp (at most) of a decoded
// coordinate, origin + float(q) x step rounding once (0 on an empty axis).
static void axis_extents(const Box3f& box, double (&extent)[3], double (&slack)[3]) {
  for (int a = 0; a < 3; ++a) {
    const bool empty = !(box.lo[a] <= box.hi[a]);
    extent[a] = empty ? 0.0 : double(box.hi[a]) - double(box.lo[a]);
    slack[a] = empty ? 0.0 : std::max(std::fabs(box.lo[a]), std::fabs(box.hi[a])) * 0x1p-24;
  }
}

bool lattice_steps(double bound, const Box3f& box, double* step) {
  double extent[3], slack[3];
  axis_extents(box, extent, slack);
  // s: the largest power of two with s sqrt(3) / 2 <= bound, within the steps a lattice may take
  // (kMinLatticeStep..kMaxLatticeStep) and no more than the widest extent needs; per axis the
  // extent must span fewer than kLatticeMax - 1 steps (else the step doubles: coarsened).
  const double widest = std::max({extent[0], extent[1], extent[2]});
  const double cap = widest > 0 ? std::exp2(std::ceil(std::log2(widest))) : 1.0;
  double s = bound > 0 ? std::exp2(std::floor(std::log2(bound * 2.0 / std::sqrt(3.0)))) : 1.0;
  s = std::min({s, cap, kMaxLatticeStep});
  bool within = s >= kMinLatticeStep;
  s = std::max(s, kMinLatticeStep);
  for (int a = 0; a < 3; ++a)
    for (step[a] = s; extent[a] / step[a] > double(kLatticeMax) - 1; step[a] *= 2) within = false;
  for (int a = 0; a < 3; ++a)
    if (step[a] > kMaxLatticeStep)
      throw Error("cluster: the box's extent " + std::to_string(extent[a]) + " on axis " +
                  std::to_string(a) + " needs a lattice step above 2^102 (coordinates beyond " +
                  "about 1e37 are out of the lossy clusters' range)");
  // Then 2s on an axis, the widest first, while the largest error (half a step and the decode's
  // rounding per axis) stays within the bound: at most two axes (2s on all three would be a
  // larger s).
  int order[3] = {0, 1, 2};
  std::stable_sort(order, order + 3, [&](int a, int b) { return extent[a] > extent[b]; });
  for (int a : order) {
    double e2 = 0;
    for (int b = 0; b < 3; ++b) {
      const double e = (b == a ? step[b] : step[b] / 2) + slack[b];
      e2 += e * e;
    }
    if (bound > 0 && std::sqrt(e2) <= bound && 2 * step[a] <= std::min(cap, kMaxLatticeStep))
      step[a] *= 2;
  }
  return within;
}

bool fine_lattice_steps(double bound, const Box3f& box, double* step) {
  if (!(bound > 0) || !std::isfinite(bound) || box.empty()) return false;
  double extent[3], slack[3];
  axis_extents(box, extent, slack);
  const double widest = std::max({extent[0], extent[1], extent[2]});
  const double cap = widest > 0 ? std::exp2(std::ceil(std::log2(widest))) : 1.0;
  // Per axis the candidates (8 + m) 2^e / 8 from above s / 64 to below 3.75 s, s the equal steps'
  // with s sqrt(3) / 2 = bound. No axis can take more than 2 bound = sqrt(3) s. Without the
  // rounding, an axis below s / 4 would leave a product below 0.375 s^3 where equal steps reach
  // 0.70 s^3; the lower end leaves room for the rounding of coordinates up to some hundred box
  // diagonals from the origin. A step with a mantissa keeps its axis' codes below
  // 2^kFineStepCodeBits, a power of two below kLatticeMax (lattice_steps').
  constexpr uint32_t kMantissas = 1u << kStepMantissaBits;
  constexpr int kExponents = 7;
  const int e0 = int(std::floor(std::log2(bound * 2.0 / std::sqrt(3.0)))) - 5;
  double cand[3][kExponents * kMantissas], sq[3][kExponents * kMantissas];  // sq: its error^2
  uint32_t n[3] = {0, 0, 0};
  for (int a = 0; a < 3; ++a)
    for (int e = e0; e < e0 + kExponents; ++e)
      for (uint32_t m = 0; m < kMantissas; ++m) {
        const double v = std::ldexp(double(kMantissas + m) / kMantissas, e);
        const double codes = m ? double(1u << kFineStepCodeBits) - 2 : double(kLatticeMax) - 1;
        if (v >= kMinLatticeStep && v <= kMaxLatticeStep && v <= cap && extent[a] / v < codes) {
          sq[a][n[a]] = (v / 2 + slack[a]) * (v / 2 + slack[a]);
          cand[a][n[a]++] = v;
        }
      }
  // The largest product within the bound (products of such steps are exact in doubles), of equal
  // products the smallest error, then the first in this order.
  double best = 0, best_e2 = 0;
  for (uint32_t i = 0; i < n[0]; ++i)
    for (uint32_t j = 0; j < n[1]; ++j)
      for (uint32_t k = 0; k < n[2]; ++k) {
        const double v[3] = {cand[0][i], cand[1][j], cand[2][k]};
        const double p = v[0] * v[1] * v[2];
        const double e2 = sq[0][i] + sq[1][j] + sq[2][k];
        if (std::sqrt(e2) <= bound && (p > best || (p == best && e2 < best_e2))) {
          best = p;
          best_e2 = e2;
          std::copy(v, v + 3, step);
        }
      }
  return best > 0;
}

Quantized quantize(const Vec3f* vertices, size_t nv, const uint32_t* tris, size_t ntris,
                   double rel_error, bool lossless, const Box3f& lattice_box) {
  constexpr size_t kGrain = 4096;  // vertices or corners a task
  Quantized z;
  // The marks, the codes and each vertex's error are computed in parallel; the box and the error
  // sums run in vertex order, as serial loops would give them (bit-identical figures).
  std::vector<uint8_t> used(nv, 0);
  tbb::parallel_for(tbb::blocked_range<size_t>(0, 3 * ntris, kGrain),
                    [&](const tbb::blocked_range<size_t>& r) {
                      for (size_t i = r.begin(); i < r.end(); ++i)
                        std::atomic_ref<uint8_t>(used[tris[i]]).store(1, std::memory_order_relaxed);
                    });
  const bool given = !lattice_box.empty();
  Box3f box = lattice_box;
  if (!given)
    for (size_t i = 0; i < nv; ++i)
      if (used[i]) box.extend(vertices[i]);
  double d2 = 0;
  if (ntris || given)
    for (int a = 0; a < 3; ++a) {
      const double e = double(box.hi[a]) - double(box.lo[a]);
      d2 += e * e;
    }
  z.diag = std::sqrt(d2);
  z.codes.assign(3 * nv, 0);
  z.decoded.assign(vertices, vertices + nv);
  double step[3] = {1.0, 1.0, 1.0};
  if (!lossless) {
    if (!(rel_error > 0.0) || !std::isfinite(rel_error))
      throw Error(
          "cluster: the error bound (BuildOptions::cluster_error) must be positive and finite");
    const Box3f lbox = ntris || given ? box : Box3f();
    z.coarsened = !lattice_steps(rel_error * z.diag, lbox, step);
    double fine[3];
    if (!z.coarsened && fine_lattice_steps(rel_error * z.diag, lbox, fine)) {
      // lattice_steps' codes, or-ed per axis: an axis whose codes all end in a zero bit lies on a
      // coarser power-of-two lattice (quantize's shift, below), which those steps keep.
      bool grid = false;
      if (!given) {
        std::atomic<uint32_t> any[3] = {0, 0, 0};
        tbb::parallel_for(tbb::blocked_range<size_t>(0, nv, kGrain),
                          [&](const tbb::blocked_range<size_t>& r) {
                            uint32_t o[3] = {0, 0, 0};
                            for (size_t i = r.begin(); i < r.end(); ++i)
                              if (used[i])
                                for (int a = 0; a < 3; ++a)
                                  o[a] |= nearest_code(vertices[i][a], box.lo[a], step[a]);
                            for (int a = 0; a < 3; ++a)
                              any[a].fetch_or(o[a], std::memory_order_relaxed);
                          });
        for (int a = 0; a < 3; ++a) grid |= any[a] && (any[a] & 1) == 0;
      }
      if (!grid) std::copy(fine, fine + 3, step);
    }
    for (int a = 0; a < 3; ++a) {
      z.lattice.step[a] = float(step[a]);
      z.lattice.origin[a] = ntris || given ? box.lo[a] : 0.0f;
    }
  }
  // Per used vertex: its distance to its input position, and that squared.
  LargeArray<double> err(2 * nv);  // huge pages: the first touch of 4 KB pages is slow here
  tbb::parallel_for(
      tbb::blocked_range<size_t>(0, nv, kGrain), [&](const tbb::blocked_range<size_t>& r) {
        for (size_t i = r.begin(); i < r.end(); ++i) {
          if (!used[i]) continue;
          for (int a = 0; a < 3; ++a) {
            if (lossless) {
              z.codes[3 * i + a] = float_key(vertices[i][a]);
              continue;
            }
            const uint32_t qi = nearest_code(vertices[i][a], z.lattice.origin[a], step[a]);
            z.codes[3 * i + a] = qi;
            z.decoded[i][a] = lattice_coord(z.lattice, a, qi);
          }
          double e2 = 0;
          for (int a = 0; a < 3; ++a) {
            const double d = double(z.decoded[i][a]) - double(vertices[i][a]);
            e2 += d * d;
          }
          err[2 * i] = std::sqrt(e2);
          err[2 * i + 1] = e2;
        }
      });
  // The anchors' widths: the largest code the lattice's box takes per axis (its top corner's; a
  // chunk of a larger mesh gets the whole box's widths, as the other chunks), or a used vertex
  // takes (one a given box holds up to rounding).
  uint32_t top[3] = {0, 0, 0};
  if (!lossless && (ntris || given))
    for (int a = 0; a < 3; ++a) top[a] = nearest_code(box.hi[a], z.lattice.origin[a], step[a]);
  double sum_sq = 0, sum = 0;
  uint64_t n = 0;
  uint32_t any[3] = {0, 0, 0};  // the codes' bits, or-ed
  for (size_t i = 0; i < nv; ++i) {
    if (!used[i]) continue;
    for (int a = 0; a < 3; ++a) {
      top[a] = std::max(top[a], z.codes[3 * i + a]);
      any[a] |= z.codes[3 * i + a];
    }
    z.max_error = std::max(z.max_error, err[2 * i]);
    sum += err[2 * i];
    sum_sq += err[2 * i + 1];
    n++;
  }
  // An axis whose codes all end in k zero bits (every vertex on a 2^k times coarser lattice, as
  // the rows of a terrain's grid) takes the step 2^k step and the codes q >> k: float(q >> k) x
  // (2^k step) is the product float(q) x step (both exact, check_lattice: 2^k step keeps the
  // step's mantissa), so every vertex decodes to the same bits, in k bits less. Only on the
  // vertices' own box: with a given box the steps depend on the box alone
  // (BuildOptions::lattice_box), so that pieces quantized on it (the chunks of a chunked build)
  // have one lattice.
  uint32_t shift[3] = {0, 0, 0};
  if (!lossless && !given)
    for (int a = 0; a < 3; ++a) {
      // (an axis of codes 0 alone, a flat one, keeps its step)
      while (any[a] && ((any[a] >> shift[a]) & 1) == 0 &&
             2.0 * z.lattice.step[a] <= kMaxLatticeStep) {
        z.lattice.step[a] *= 2.0f;
        ++shift[a];
      }
      top[a] >>= shift[a];
    }
  if (shift[0] | shift[1] | shift[2]) {
    std::atomic<bool> moved{false};
    tbb::parallel_for(
        tbb::blocked_range<size_t>(0, nv, kGrain), [&](const tbb::blocked_range<size_t>& r) {
          for (size_t i = r.begin(); i < r.end(); ++i)
            for (int a = 0; a < 3; ++a) {
              z.codes[3 * i + a] >>= shift[a];
              if (used[i] && lattice_coord(z.lattice, a, z.codes[3 * i + a]) != z.decoded[i][a])
                moved = true;
            }
        });
    if (moved) throw std::logic_error("cluster: a coarser exact axis moved a vertex");
  }
  if (!lossless) {
    for (int a = 0; a < 3; ++a) z.lattice.anchor_bits[a] = uint8_t(bit_width(top[a]));
    if (const std::string bad = check_lattice(z.lattice); !bad.empty())
      throw std::logic_error("cluster: " + bad);
  }
  z.rms_error = n ? std::sqrt(sum_sq / double(n)) : 0.0;
  z.mean_error = n ? sum / double(n) : 0.0;
  return z;
}

}  // namespace slim::cluster
