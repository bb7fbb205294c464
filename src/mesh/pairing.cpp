// Triangle pairing: A. Aman, S. Fenney, "Fast Triangle Pairing for Ray Tracing", Imagination
// Technologies. See pairing.h.
//
// Stages (paper, "Edge bbox surface area heuristic"):
//   1. half-edge table: (BBSA, smaller vertex, larger vertex, triangle) per non-degenerate
//      half-edge;
//   2. (optional) edge key compression: midpoint + BBSA as 24-bit fields (coordinate keys);
//   3. sort descending by (BBSA, smaller vertex, larger vertex) with an LSD radix sort;
//   4. greedy scan: runs of equal keys are twins; pair two of them when both triangles are free.
//
// Two implementations of stages 1-4, with the same order:
//   - coordinate keys: the full table, 16 B records with the packed key (BBSA24 : midpoint
//     3 x 24), LSD radix sort over all key bits, linear scan (coordinate_table);
//   - index keys, TwinSort: a counting sort of the half-edges by their smaller vertex brings
//     twins together (buckets hold ~3 edges); each run of >= 2 twins becomes one 8 B edge record,
//     emitted in ascending (smaller, larger) vertex order, so a stable radix sort by the 31 BBSA
//     bits alone (sort_edges: one MSD pass, two LSD passes in cache) read backwards gives exactly
//     the paper's descending (BBSA, smaller, larger) order; boundary edges never enter the sort.
//     The records and the sort's second buffer live in the counting sort's buckets (83 MB of
//     scratch on fg_terrain_hawaii instead of 119 with 12 B records in an array of their own).
// tests/pairing_orders.cpp applies the index-key order two more ways through the internals of
// mesh/pairing_internal.h (the full table with index keys, and a local order without any global
// sort), and tests/test_pairing.cpp checks all of them against a std::stable_sort of the explicit
// table. On fg_terrain_hawaii (2M triangles, one thread) TwinSort pairs 7.3 M triangles/s, the
// local order 6.5 and the index-key full table 2.4, so the library keeps TwinSort.
#include "mesh/pairing.h"
#include "mesh/pairing_internal.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <limits>
#include <memory>
#include <string>

#include "core/large_array.h"
#include "core/simd_ext.h"
#include "mesh/triangulate.h"
#include "prim/pairs.h"
#include "slimrt/error.h"
#include "slimrt/scene.h"

namespace slim {

using namespace pairing_detail;

namespace {

using Clock = std::chrono::steady_clock;
double seconds_since(Clock::time_point t0) {
  return std::chrono::duration<double>(Clock::now() - t0).count();
}

// Digits of <= 11 bits (2048 buckets: the histograms of all passes stay in L1/L2) covering key
// bits [from, to) evenly.
struct Digit {
  int shift, bits;
};
int cut_digits(int from, int to, Digit* out) {
  constexpr int kMaxDigit = 11;
  int w = to - from;
  if (w <= 0) return 0;
  int k = (w + kMaxDigit - 1) / kMaxDigit;
  int s = from;
  for (int i = 0; i < k; ++i) {
    int bits = w / k + (i < w % k ? 1 : 0);
    out[i] = {s, bits};
    s += bits;
  }
  return k;
}

// Stable LSD radix sort of `a` (n records) by the digits key_of(record, digit) ascending. One
// histogram pass for all digits; digits equal in every key are skipped. Returns the buffer that
// holds the result (a or tmp).
template <class Rec, class KeyOf>
Rec* radix_sort(Rec* a, Rec* tmp, size_t n, const Digit* digits, int nd, KeyOf key_of) {
  if (n < 2 || nd == 0) return a;
  std::vector<uint32_t> hist(size_t(nd) << 11, 0);
  for (size_t i = 0; i < n; ++i)
    for (int d = 0; d < nd; ++d) hist[(size_t(d) << 11) + key_of(a[i], digits[d])]++;
  Rec* src = a;
  Rec* dst = tmp;
  for (int d = 0; d < nd; ++d) {
    uint32_t* h = &hist[size_t(d) << 11];
    const uint32_t buckets = 1u << digits[d].bits;
    bool constant = false;
    uint32_t sum = 0;
    for (uint32_t b = 0; b < buckets; ++b) {
      if (h[b] == n) constant = true;
      uint32_t c = h[b];
      h[b] = sum;
      sum += c;
    }
    if (constant) continue;
    const Digit dg = digits[d];
    for (size_t i = 0; i < n; ++i) dst[h[key_of(src[i], dg)]++] = src[i];
    std::swap(src, dst);
  }
  return src;
}

// Quantizer of edge midpoints to 24 bits per axis over the mesh box (coordinate keys).
struct MidpointQuantizer {
  Vec3f lo;
  float scale[3];
  explicit MidpointQuantizer(const Box3f& box) : lo(box.lo) {
    for (int a = 0; a < 3; ++a) {
      float ext = box.hi[a] - box.lo[a];
      scale[a] = ext > 0.0f && std::isfinite(ext) ? 16777215.0f / ext : 0.0f;
    }
  }
  SLIM_INLINE uint64_t q(float m, int a) const {
    float t = (m - lo[a]) * scale[a];
    if (!(t > 0.0f)) return 0;
    if (t >= 16777215.0f) return 16777215;
    return uint64_t(t);
  }
};

// Pairs of `mate` (npairs of them), ascending by a; the unpaired triangles; the figures. Without
// branches (whether t starts a pair is a coin toss): every entry is written at the next free
// position (one spare entry at the end), and the position moves on only if the entry is kept; the
// random reads of the partner's mate are prefetched.
void collect(const PairingInput& in, const uint32_t* mate, uint64_t npairs, PairingResult& r) {
  const uint64_t T = in.tri_count;
  r.pairs.assign(npairs + 1, TrianglePair{});
  r.unpaired.assign(T - 2 * npairs + 1, 0u);
  TrianglePair* pairs = r.pairs.data();
  uint32_t* unpaired = r.unpaired.data();
  size_t np = 0, nu = 0;
  constexpr uint64_t kAhead = 32;
  for (uint64_t t = 0; t < T; ++t) {
    if (t + kAhead < T) {
      const uint32_t m = mate[t + kAhead];
      __builtin_prefetch(&mate[m != kNone ? m / 3 : t]);
    }
    const uint32_t m = mate[t];
    unpaired[nu] = uint32_t(t);
    nu += m == kNone;
    const bool first = m != kNone && m / 3 > t;
    const uint32_t b = first ? m / 3 : uint32_t(t);
    pairs[np] = {uint32_t(t), b, uint8_t(mate[b] % 3), uint8_t(m % 3)};
    np += first;
  }
  r.pairs.resize(np);
  r.unpaired.resize(nu);
  PairingStats& s = r.stats;
  s.triangles = in.tri_count;
  s.pairs = r.pairs.size();
  s.unpaired = r.unpaired.size();
  s.paired_fraction = in.tri_count ? double(2 * s.pairs) / double(in.tri_count) : 0.0;
}

// Index keys without the full table: twins found by a counting sort on the smaller vertex.
// Edge record (8 B): BBSA bits (31 bits) << 32 | first half-edge of the edge (smallest id). Its
// twin is link[first]; a record whose first half-edge has no link is a run of 3+ twins (found
// through Twins::run_of). 8 B instead of 12 (key, a, b) so that the records and the radix sort's
// second buffer both fit in the counting sort's buckets (8 B per half-edge, at most one record
// per 2 half-edges): no array of its own.
SLIM_INLINE uint32_t rec_key(uint64_t r) { return uint32_t(r >> 32); }
SLIM_INLINE uint32_t rec_half_edge(uint64_t r) { return uint32_t(r); }

}  // namespace

namespace pairing_detail {

// Builds the twins (and, if `emit`, one record per run of >= 2 twins into tw.slots[0, ne), in
// ascending (smaller, larger) vertex order: the input of the area-only radix sort, with the
// histogram of its top 11 key bits in top_hist). The buckets are visited in ascending smaller
// vertex, so the records written so far (at most half the entries read) never reach a bucket
// not yet read; each bucket is read from a copy.
void find_twins(const PairingInput& in, Greedy& g, Twins& tw, bool emit, size_t* edge_count,
                uint32_t* top_hist, PairingStats& st) {
  const uint64_t T = in.tri_count, V = in.vertex_count;
  const uint32_t* tris = in.tris;
  // Counting sort of the half-edges by smaller vertex: start[v] .. start[v+1].
  LargeArray<uint32_t> start(V + 1, 0u);
  for (uint64_t i = 0; i < 3 * T; i += 3) {
    uint32_t a = tris[i], b = tris[i + 1], c = tris[i + 2];
    start[std::min(a, b)] += a != b;
    start[std::min(b, c)] += b != c;
    start[std::min(c, a)] += c != a;
  }
  uint32_t sum = 0;
  for (uint64_t v = 0; v <= V; ++v) {
    uint32_t c = start[v];
    start[v] = sum;
    sum += c;
  }
  const size_t n = sum;
  st.half_edges = n;
  // Entry: larger vertex << 32 | half-edge id; filled through start[] as cursors (shifted back
  // by one bucket afterwards). Filled in half-edge order, so each bucket is sorted by id.
  tw.slots = LargeArray<uint64_t>(n);  // no fill: every entry is written
  uint64_t* slots = tw.slots.data();
  for (uint64_t i = 0; i < 3 * T; i += 3)
    for (int k = 0; k < 3; ++k) {
      uint32_t i0 = tris[i + k], i1 = tris[i + next3(k)];
      if (i0 == i1) continue;  // degenerate: in no bucket
      uint32_t v0 = std::min(i0, i1);
      slots[start[v0]++] = uint64_t(std::max(i0, i1)) << 32 | uint32_t(i + k);
    }
  for (uint64_t v = V; v > 0; --v) start[v] = start[v - 1];
  start[0] = 0;

  // kNone everywhere first (a memset), then only the twins are written: degenerate, boundary and
  // non-manifold half-edges cost no random write.
  tw.link = LargeArray<uint32_t>(3 * T);
  fill_none(tw.link.data(), tw.link.size());
  uint32_t* link = tw.link.data();
  tw.in_run.assign((T + 63) / 64, 0);
  size_t ne = 0;              // at most one record per 2 half-edges
  std::vector<uint64_t> big;  // copy of a bucket of more than 16 entries
  for (uint64_t v0 = 0; v0 < V; ++v0) {
    const size_t k = start[v0 + 1] - start[v0];
    if (k < 2) continue;  // boundary edge (or none)
    // Sorted by (larger vertex, half-edge id). Buckets hold ~6 entries (about the vertex valence)
    // and rarely more than 16: those are ranked without branches on the data (an insertion sort
    // mispredicted about once per entry, ~half of this loop on fg_terrain_hawaii), the others
    // take an insertion sort of a copy.
    uint64_t ranked[16];
    const uint64_t* e = ranked;
    if (k <= 16) {
      simd::rank_sort16(slots + start[v0], k, ranked);
    } else {
      big.assign(slots + start[v0], slots + start[v0] + k);
      for (size_t i = 1; i < k; ++i) {
        uint64_t x = big[i];
        size_t j = i;
        for (; j > 0 && big[j - 1] > x; --j) big[j] = big[j - 1];
        big[j] = x;
      }
      e = big.data();
    }
    for (size_t lo = 0; lo < k;) {
      const uint32_t v1 = uint32_t(e[lo] >> 32);
      size_t hi = lo + 1;
      while (hi < k && uint32_t(e[hi] >> 32) == v1) ++hi;
      const size_t cnt = hi - lo, first = lo;
      lo = hi;
      if (cnt < 2) continue;  // boundary edge
      const uint32_t ha = uint32_t(e[first]), hb = uint32_t(e[first + 1]);
      if (cnt == 2 && !g.compatible(ha, hb)) continue;
      // Checked here, in vertex order (cache friendly): the later scans only touch the "paired"
      // bits.
      const uint32_t key =
          float_bits(edge_box_area(in.vertices[v0], in.vertices[v1])) & 0x7fffffffu;
      if (cnt == 2) {
        link[ha] = hb;
        link[hb] = ha;
      } else {
        const uint32_t off = uint32_t(tw.runs.size());
        tw.runs.push_back(uint32_t(cnt));
        for (size_t x = first; x < first + cnt; ++x) {
          const uint32_t h = uint32_t(e[x]);
          tw.runs.push_back(h);
          tw.run_of.push_back({h, off});
          tw.in_run[h / 3 / 64] |= uint64_t(1) << (h / 3 % 64);
        }
      }
      if (emit) {
        slots[ne++] = uint64_t(key) << 32 | ha;
        top_hist[key >> 20]++;
      }
    }
  }
  std::sort(tw.run_of.begin(), tw.run_of.end());
  if (edge_count) *edge_count = ne;
}

}  // namespace pairing_detail

namespace {

// The paper's order by a stable radix sort of the edge records on the BBSA bits alone: one MSD
// pass on the top 11 bits (its histogram counted while the records were emitted), then 2 LSD
// passes of 10 bits inside each bucket, which mostly fits in L2; buckets of a few records take
// an insertion sort instead (on small meshes the 2 x 1024-entry histograms of the ~2048 buckets
// cost more than the records). Stable all the way, so equal keys keep the emission order. One
// pass over memory instead of three: 30% faster than a plain 3-pass LSD on 3M records. `a` holds
// ne records, `t` room for ne more; the result is in t.
const uint64_t* sort_edges(uint64_t* a, uint64_t* t, size_t ne, const uint32_t* top_hist) {
  constexpr int kTop = 11, top_shift = 31 - kTop;
  const uint32_t* start = top_hist;
  std::vector<uint32_t> cur(size_t(1) << kTop);
  uint32_t sum = 0;
  for (size_t b = 0; b < cur.size(); ++b) {
    cur[b] = sum;
    sum += start[b];
  }
  for (size_t i = 0; i < ne; ++i) t[cur[rec_key(a[i]) >> top_shift]++] = a[i];
  // Now bucket b is t[cur[b] - start[b], cur[b]); its keys differ in bits [0, top_shift) only.
  const Digit low[2] = {{0, top_shift / 2}, {top_shift / 2, top_shift - top_shift / 2}};
  uint32_t h[1u << 10];
  for (size_t b = 0; b < cur.size(); ++b) {
    const uint32_t m = start[b], lo = cur[b] - m;
    if (m < 2) continue;
    if (m <= 32) {
      uint64_t* r = t + lo;
      for (uint32_t i = 1; i < m; ++i) {
        const uint64_t x = r[i];
        uint32_t j = i;
        for (; j > 0 && rec_key(r[j - 1]) > rec_key(x); --j) r[j] = r[j - 1];
        r[j] = x;
      }
      continue;
    }
    uint64_t* src = t + lo;
    uint64_t* dst = a + lo;
    for (const Digit& d : low) {
      if (d.bits == 0) continue;
      const uint32_t mask = (1u << d.bits) - 1;
      std::fill(h, h + (size_t(1) << d.bits), 0u);
      for (uint32_t i = 0; i < m; ++i) h[(rec_key(src[i]) >> d.shift) & mask]++;
      uint32_t s2 = 0;
      for (uint32_t x = 0; x <= mask; ++x) {
        uint32_t c = h[x];
        h[x] = s2;
        s2 += c;
      }
      for (uint32_t i = 0; i < m; ++i) dst[h[(rec_key(src[i]) >> d.shift) & mask]++] = src[i];
      std::swap(src, dst);
    }
    if (src != t + lo) std::memcpy(t + lo, src, m * sizeof(uint64_t));
  }
  return t;
}

// Sort, then the greedy scan. The records are sorted ascending by (BBSA, smaller vertex, larger
// vertex) (ascending emission, stable sort), so the paper's descending order is the sorted array
// read backwards; zero-area edges come last. For a pair record, accepting is "neither triangle
// paired yet": done without a branch (half of them are accepted, unpredictably), the accepted
// twins compacted in place at the back of the sorted records (never ahead of the read position)
// and written to mate[] afterwards. The twin link[a] of a record is a random read, prefetched.
void sorted_scan(Greedy& g, Twins& tw, size_t ne, const uint32_t* top_hist, PairingStats& st) {
  auto t0 = Clock::now();
  if (ne == 0) return;
  uint64_t* s =
      const_cast<uint64_t*>(sort_edges(tw.slots.data(), tw.slots.data() + ne, ne, top_hist));
  st.sort_s = seconds_since(t0);
  t0 = Clock::now();
  constexpr size_t kAhead = 64;  // records between the prefetch of a twin and its use
  const uint32_t* link = tw.link.data();
  uint64_t* used = g.used.data();
  size_t w = ne;  // accepted pairs, compacted into s[w, ne) as (b << 32 | a)
  for (size_t i = ne; i-- > 0;) {
    if (i >= kAhead) __builtin_prefetch(&link[rec_half_edge(s[i - kAhead])]);
    const uint32_t ha = rec_half_edge(s[i]);
    const uint32_t hb = link[ha];
    if (hb != kNone) {
      const uint32_t ta = ha / 3, tb = hb / 3;
      const uint64_t free = ~((used[ta >> 6] >> (ta & 63)) | (used[tb >> 6] >> (tb & 63))) & 1;
      used[ta >> 6] |= free << (ta & 63);
      used[tb >> 6] |= free << (tb & 63);
      s[w - 1] = uint64_t(hb) << 32 | ha;  // w - 1 >= i: only records already read
      w -= free;
    } else {
      const uint32_t off = tw.run_offset(ha);
      g.run(&tw.runs[off + 1], tw.runs[off]);
    }
  }
  uint32_t* mate = g.mate.data();
  for (size_t i = w; i < ne; ++i) {
    const uint32_t a = uint32_t(s[i]), b = uint32_t(s[i] >> 32);
    mate[a / 3] = b;
    mate[b / 3] = a;
  }
  g.pairs += ne - w;
  st.scan_s = seconds_since(t0);
}

// Augmenting paths of length 3 (see PairingOptions::augment): free t, pair (n, p), free u with
// t-n and p-u manifold edges becomes (t, n) + (p, u), the candidate with the largest sum of edge
// box areas first. Sweeps over the free triangles until nothing changes (at most 4). twin[h] is
// the twin half-edge of h (kNone: no manifold twin); the areas are recomputed from the corners
// (only for the few candidate edges). Returns the pairs gained.
uint64_t augment(const PairingInput& in, const uint32_t* twin, uint32_t* mate) {
  constexpr size_t kAugmentAhead = 8;  // free triangles per prefetch step (hawaii: 32 -> 25 ms)
  auto area = [&](uint32_t h) {
    const uint32_t t = h / 3;
    const int k = int(h % 3);
    return edge_box_area(corner(in, t, k), corner(in, t, next3(k)));
  };
  std::vector<uint32_t> free_tris;
  for (uint64_t t = 0; t < in.tri_count; ++t)
    if (mate[t] == kNone) free_tris.push_back(uint32_t(t));
  uint64_t gained = 0;
  for (int sweep = 0; sweep < 4 && !free_tris.empty(); ++sweep) {
    const uint64_t before = gained;
    size_t kept = 0;
    const size_t nf = free_tris.size();
    for (size_t f = 0; f < nf; ++f) {
      // The free triangles are scattered over the mesh, and each look-up below depends on the
      // one before (twin, then the neighbour's mate, then the mate's twins): prefetch them as a
      // pipeline, 3 steps ahead, from values that may still change (only a hint).
      if (f + 3 * kAugmentAhead < nf)
        __builtin_prefetch(&twin[3 * size_t(free_tris[f + 3 * kAugmentAhead])]);
      if (f + 2 * kAugmentAhead < nf) {
        const uint32_t* tw = &twin[3 * size_t(free_tris[f + 2 * kAugmentAhead])];
        for (int k = 0; k < 3; ++k)
          if (tw[k] != kNone) __builtin_prefetch(&mate[tw[k] / 3]);
      }
      if (f + kAugmentAhead < nf) {
        const uint32_t t1 = free_tris[f + kAugmentAhead];
        __builtin_prefetch(&in.tris[3 * size_t(t1)]);
        for (int k = 0; k < 3; ++k) {
          const uint32_t o = twin[3 * size_t(t1) + k];
          if (o == kNone) continue;
          const uint32_t m = mate[o / 3];
          if (m != kNone) __builtin_prefetch(&twin[3 * size_t(m / 3)]);
        }
      }
      const uint32_t t = free_tris[f];
      if (mate[t] != kNone) continue;  // became a u earlier in this sweep
      float best = -1.0f;
      uint32_t bh = kNone, bo = kNone, bh2 = kNone, bo2 = kNone;
      for (int k = 0; k < 3; ++k) {
        const uint32_t h = 3 * t + k;
        const uint32_t o = twin[h];  // manifold edges only
        if (o == kNone) continue;
        const uint32_t n = o / 3;
        if (mate[n] == kNone) continue;
        const uint32_t p = mate[n] / 3;
        float a1 = -1.0f;  // area(h), once needed
        for (int m = 0; m < 3; ++m) {
          const uint32_t h2 = 3 * p + m;
          const uint32_t o2 = twin[h2];
          if (o2 == kNone) continue;
          const uint32_t u = o2 / 3;
          if (u == n || u == t || mate[u] != kNone) continue;
          if (a1 < 0.0f) a1 = area(h);
          const float score = a1 + area(h2);
          if (score > best) {
            best = score;
            bh = h, bo = o, bh2 = h2, bo2 = o2;
          }
        }
      }
      if (bh == kNone) {
        free_tris[kept++] = t;
        continue;
      }
      mate[t] = bo;
      mate[bo / 3] = bh;
      mate[bh2 / 3] = bo2;
      mate[bo2 / 3] = bh2;
      gained++;
    }
    free_tris.resize(kept);
    if (gained == before) break;
  }
  return gained;
}

// The first shared edge of triangles a and b by position (pair_shares_edge's order: a's edge
// i, then b's edge j). Index keys use the shared-edge table below.
bool find_shared_edge_by_position(const PairingInput& in, uint32_t a, uint32_t b, TrianglePair& p) {
  p.a = std::min(a, b);
  p.b = std::max(a, b);
  if (in.groups && in.groups[a] != in.groups[b]) return false;
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) {
      p.ea = uint8_t(i);
      p.eb = uint8_t(j);
      if (pair_shares_edge(in, p, true)) return true;
    }
  return false;
}

// Paper, "Edge key representation & compression": the full table with coordinate keys, BBSA (its
// float bits 30..7, order kept) and the edge midpoint quantized to 24 bits per axis: 96 key bits +
// the half-edge id = 16 B per record, sorted over all key bits.
void coordinate_table(const PairingInput& in, Greedy& g, PairingStats& st) {
  const uint64_t T = in.tri_count;
  auto t0 = Clock::now();
  LargeArray<HalfEdgeRec> table(3 * T);
  size_t n = 0;
  Box3f box;
  for (uint64_t t = 0; t < T; ++t)
    for (int k = 0; k < 3; ++k) box.extend(corner(in, uint32_t(t), k));
  MidpointQuantizer mq(box);
  for (uint64_t t = 0; t < T; ++t) {
    for (int k = 0; k < 3; ++k) {
      const Vec3f& p = corner(in, uint32_t(t), k);
      const Vec3f& q = corner(in, uint32_t(t), next3(k));
      if (same_bits(p, q)) continue;
      uint64_t area24 = float_bits(edge_box_area(p, q)) >> 7;
      Vec3f m = (p + q) * 0.5f;  // + is commutative bit for bit: twins agree
      uint64_t mx = mq.q(m.x, 0), my = mq.q(m.y, 1), mz = mq.q(m.z, 2);
      // 96-bit key area24 : mx : my : mz, complemented.
      uint32_t hi = ~uint32_t((area24 << 8) | (mx >> 16));
      uint64_t lo = ~(((mx & 0xffff) << 48) | (my << 24) | mz);
      table[n++] = {lo, hi, uint32_t(3 * t + k)};
    }
  }
  st.half_edges = n;
  st.table_s = seconds_since(t0);
  sort_and_scan_table(table.data(), n, 96, g, st);
}

// The paper's pairing: index keys by TwinSort (find_twins + sorted_scan), coordinate keys by the
// full table; then (aug) the augmenting pass.
PairingResult heuristic(const PairingInput& in_arg, bool coordinate_keys, bool aug) {
  const PairingInput in = prepare(in_arg);
  PairingResult r;
  Greedy g(in, coordinate_keys, aug && coordinate_keys);
  Twins tw;
  if (coordinate_keys) {
    coordinate_table(in, g, r.stats);
  } else {
    auto t0 = Clock::now();
    size_t ne = 0;
    std::vector<uint32_t> top_hist(2048, 0);
    find_twins(in, g, tw, true, &ne, top_hist.data(), r.stats);
    r.stats.table_s = seconds_since(t0);
    sorted_scan(g, tw, ne, top_hist.data(), r.stats);
  }
  tw.slots = {};
  finish(in, g, !aug ? nullptr : coordinate_keys ? g.twin.data() : tw.link.data(), r);
  return r;
}

// Shared edge of two index triangles a, b as one look-up: bit 3i+j of the index is a_i == b_j,
// bit 9+i is "a's edge i is degenerate"; the entry is 3i+j of the first (i, j) in the order
// a's edge i, then b's edge j, with a's edge i = b's edge j (either direction), 0xff if none.
struct SharedEdgeTable {
  uint8_t code[4096];
  constexpr SharedEdgeTable() : code() {
    for (int m = 0; m < 4096; ++m) {
      code[m] = 0xff;
      auto eq = [m](int i, int j) { return (m >> (3 * i + j)) & 1; };
      for (int i = 0; i < 3 && code[m] == 0xff; ++i) {
        if ((m >> (9 + i)) & 1) continue;
        const int i1 = (i + 1) % 3;
        for (int j = 0; j < 3; ++j) {
          const int j1 = (j + 1) % 3;
          if ((eq(i, j) && eq(i1, j1)) || (eq(i, j1) && eq(i1, j))) {
            code[m] = uint8_t(3 * i + j);
            break;
          }
        }
      }
    }
  }
};
constexpr SharedEdgeTable kSharedEdge;

SLIM_INLINE uint8_t shared_edge_code(const uint32_t* a, const uint32_t* b) {
  uint32_t m = 0;
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) m |= uint32_t(a[i] == b[j]) << (3 * i + j);
  m |= uint32_t(a[0] == a[1]) << 9 | uint32_t(a[1] == a[2]) << 10 | uint32_t(a[2] == a[0]) << 11;
  return kSharedEdge.code[m];
}

// The window-2 pairs (the pre-scan; paper, "Results": "a pre-scan to decide if pairing
// optimisation is needed"): returns their number, and in `pairs` the pairs themselves if
// 2 * count / T >= keep_threshold (empty otherwise: they are no longer stored once the threshold
// is out of reach). With `decide_only`, the scan stops as soon as the threshold is out of reach
// (the pre-scan's decision is made; on an irregular mesh after a few % of the triangles) and
// *complete is false: the count is then a partial one. Index keys: the shared edge of each
// (i, i+1) by a table look-up (no branch), in blocks, then the in-order greedy choice
// s_i = f_i && !s_(i-1) as a short dependency chain.
uint64_t window_scan(const PairingInput& in, bool by_position, double keep_threshold,
                     std::vector<TrianglePair>& pairs, bool decide_only = false,
                     bool* complete = nullptr) {
  bool stopped = false;  // decide_only and the threshold is out of reach
  const uint64_t T = in.tri_count;
  pairs.clear();
  bool keep = T > 0 && 1.0 >= keep_threshold;
  if (keep) pairs.reserve(T / 2);  // pages are touched only as far as the pairs are written
  uint64_t count = 0;
  if (by_position) {
    for (uint64_t i = 0; i + 1 < T;) {
      TrianglePair p;
      if (find_shared_edge_by_position(in, uint32_t(i), uint32_t(i + 1), p)) {
        if (keep) pairs.push_back(p);
        count++;
        i += 2;
      } else {
        i += 1;
      }
      if (keep && double(T + 2 * count - i) / double(T) < keep_threshold) keep = false;
      if ((stopped = !keep && decide_only)) break;
    }
  } else {
    constexpr uint64_t kBlock = 256;
    uint8_t code[kBlock];
    bool prev = false;  // (i-1, i) is a pair
    for (uint64_t b = 0; b + 1 < T; b += kBlock) {
      const uint64_t e = std::min(b + kBlock, T - 1);
      for (uint64_t i = b; i < e; ++i) {
        uint8_t c = shared_edge_code(&in.tris[3 * i], &in.tris[3 * i + 3]);
        if (in.groups && in.groups[i] != in.groups[i + 1]) c = 0xff;
        code[i - b] = c;
      }
      for (uint64_t i = b; i < e; ++i) {
        const uint8_t c = code[i - b];
        const bool s = c != 0xff && !prev;
        count += s;
        prev = s;
        if (s && keep)
          pairs.push_back({uint32_t(i), uint32_t(i + 1), uint8_t(c / 3), uint8_t(c % 3)});
      }
      // The triangles of [0, e) in no pair so far stay unpaired: give up storing the pairs once
      // the threshold is out of reach.
      if (keep && double(T + 2 * count - e) / double(T) < keep_threshold) keep = false;
      if ((stopped = !keep && decide_only)) break;
    }
  }
  if (complete) *complete = !stopped;
  if (!keep) pairs = {};
  return count;
}

// The result of window pairs: pairs are (i, i+1) in order, so the unpaired triangles are the
// gaps between them.
PairingResult window_result(const PairingInput& in, std::vector<TrianglePair>&& pairs) {
  PairingResult r;
  r.pairs.assign(pairs.begin(), pairs.end());
  uint64_t next = 0;
  for (const TrianglePair& p : r.pairs) {
    for (; next < p.a; ++next) r.unpaired.push_back(uint32_t(next));
    next = uint64_t(p.b) + 1;
  }
  for (; next < in.tri_count; ++next) r.unpaired.push_back(uint32_t(next));
  PairingStats& s = r.stats;
  s.triangles = in.tri_count;
  s.pairs = r.pairs.size();
  s.unpaired = r.unpaired.size();
  s.paired_fraction = in.tri_count ? double(2 * s.pairs) / double(in.tri_count) : 0.0;
  s.window2_paired_fraction = s.paired_fraction;
  return r;
}

}  // namespace

namespace pairing_detail {

PairingInput prepare(const PairingInput& in_arg) {
  const uint64_t T = in_arg.tri_count;
  if (3 * T >= 0xffffffffull)
    throw Error("triangle pairing: " + std::to_string(T) +
                " triangles, at most (2^32 - 1) / 3 can be paired");
  PairingInput in = in_arg;
  if (in.groups &&
      std::all_of(in.groups, in.groups + T, [&](uint32_t x) { return x == in.groups[0]; }))
    in.groups = nullptr;
  return in;
}

void sort_and_scan_table(HalfEdgeRec* table, size_t n, int key_bits, Greedy& g, PairingStats& st) {
  auto t0 = Clock::now();
  LargeArray<HalfEdgeRec> tmp(n);
  Digit digits[12];
  int nd = cut_digits(0, std::min(key_bits, 64), digits);
  nd += cut_digits(64, key_bits, digits + nd);
  const HalfEdgeRec* s =
      radix_sort(table, tmp.data(), n, digits, nd, [](const HalfEdgeRec& r, Digit d) {
        uint64_t v = d.shift >= 64 ? uint64_t(r.hi) >> (d.shift - 64) : r.lo >> d.shift;
        return uint32_t(v) & ((1u << d.bits) - 1);
      });
  st.sort_s = seconds_since(t0);

  t0 = Clock::now();
  std::vector<uint32_t> run;
  for (size_t i = 0; i < n;) {
    size_t j = i + 1;
    while (j < n && s[j].lo == s[i].lo && s[j].hi == s[i].hi) ++j;
    if (j - i == 2) {
      g.two(s[i].he, s[i + 1].he);
    } else if (j - i > 2) {
      run.clear();
      for (size_t x = i; x < j; ++x) run.push_back(s[x].he);
      g.run(run.data(), run.size());
    }
    i = j;
  }
  st.scan_s = seconds_since(t0);
}

void finish(const PairingInput& in, Greedy& g, const uint32_t* twin, PairingResult& r) {
  const uint64_t T = in.tri_count;
  r.stats.heuristic_paired_fraction = T ? double(2 * g.pairs) / double(T) : 0.0;
  if (twin) {
    auto t0 = Clock::now();
    r.stats.augmented_pairs = augment(in, twin, g.mate.data());
    r.stats.augment_s = seconds_since(t0);
  }
  r.stats.nonmanifold_edges = g.nonmanifold;
  collect(in, g.mate.data(), g.pairs + r.stats.augmented_pairs, r);
}

}  // namespace pairing_detail

bool pair_shares_edge(const PairingInput& in, const TrianglePair& p, bool by_position) {
  if (p.a == p.b || p.ea > 2 || p.eb > 2) return false;
  if (in.groups && in.groups[p.a] != in.groups[p.b]) return false;
  const uint32_t* ta = &in.tris[3 * size_t(p.a)];
  const uint32_t* tb = &in.tris[3 * size_t(p.b)];
  uint32_t a0 = ta[p.ea], a1 = ta[next3(p.ea)];
  uint32_t b0 = tb[p.eb], b1 = tb[next3(p.eb)];
  if (!by_position) {
    if (a0 == a1) return false;
    return (a0 == b0 && a1 == b1) || (a0 == b1 && a1 == b0);
  }
  const Vec3f &pa0 = in.vertices[a0], &pa1 = in.vertices[a1];
  const Vec3f &pb0 = in.vertices[b0], &pb1 = in.vertices[b1];
  if (same_bits(pa0, pa1)) return false;
  return (same_bits(pa0, pb0) && same_bits(pa1, pb1)) ||
         (same_bits(pa0, pb1) && same_bits(pa1, pb0));
}

PairingResult window_pairs(const PairingInput& in, bool by_position) {
  const auto t0 = Clock::now();
  std::vector<TrianglePair> pairs;
  window_scan(in, by_position, -1.0, pairs);
  PairingResult r = window_result(in, std::move(pairs));
  r.stats.pairing_s = seconds_since(t0);
  return r;
}

uint64_t weld_positions(const Vec3f* vertices, uint64_t vertex_count,
                        std::vector<uint32_t>& remap) {
  remap.resize(vertex_count);
  // Open addressing over the 12 position bytes; the table holds vertex ids (first occurrence).
  uint64_t cap = 16;
  while (cap < 2 * vertex_count) cap *= 2;
  std::vector<uint32_t> table(cap, kNone);
  const uint64_t mask = cap - 1;
  uint64_t merged = 0;
  for (uint64_t v = 0; v < vertex_count; ++v) {
    const Vec3f& p = vertices[v];
    uint64_t h = float_bits(p.x) * 0x9E3779B97F4A7C15ULL;
    h = (h ^ (h >> 29) ^ float_bits(p.y)) * 0xBF58476D1CE4E5B9ULL;
    h = (h ^ (h >> 32) ^ float_bits(p.z)) * 0x94D049BB133111EBULL;
    h ^= h >> 31;
    for (uint64_t s = h & mask;; s = (s + 1) & mask) {
      uint32_t e = table[s];
      if (e == kNone) {
        table[s] = uint32_t(v);
        remap[v] = uint32_t(v);
        break;
      }
      if (same_bits(vertices[e], p)) {
        remap[v] = e;
        merged++;
        break;
      }
    }
  }
  return merged;
}

PairingResult pair_by_edge_heuristic(const PairingInput& in, bool coordinate_keys) {
  return heuristic(in, coordinate_keys, false);
}

PairingResult pair_triangles(const PairingInput& in_arg, const PairingOptions& opt) {
  auto t_all = Clock::now();
  PairingInput in = in_arg;
  std::vector<uint32_t> welded_tris;
  double weld_s = 0;
  uint64_t welded = 0;
  if (opt.weld) {
    auto t0 = Clock::now();
    std::vector<uint32_t> remap;
    welded = weld_positions(in.vertices, in.vertex_count, remap);
    if (welded) {
      welded_tris.resize(3 * in.tri_count);
      for (uint64_t i = 0; i < 3 * in.tri_count; ++i) welded_tris[i] = remap[in.tris[i]];
      in.tris = welded_tris.data();
    }
    weld_s = seconds_since(t0);
  }

  // Pre-scan: the window-2 pairing, kept if it is good enough.
  auto t0 = Clock::now();
  std::vector<TrianglePair> w;
  bool complete = true;
  const uint64_t nw =
      window_scan(in, opt.coordinate_keys, opt.prescan_threshold, w, true, &complete);
  const double window2 = !complete      ? std::numeric_limits<double>::quiet_NaN()
                         : in.tri_count ? double(2 * nw) / double(in.tri_count)
                                        : 0.0;
  PairingResult r;
  if (in.tri_count > 0 && complete && window2 >= opt.prescan_threshold) {
    r = window_result(in, std::move(w));
    r.stats.prescan_skipped = true;
  }
  double prescan_s = seconds_since(t0);
  if (!r.stats.prescan_skipped) {
    w = {};
    r = heuristic(in, opt.coordinate_keys, opt.augment);
    r.stats.window2_paired_fraction = window2;
  }
  r.stats.weld_s = weld_s;
  r.stats.welded_vertices = welded;
  r.stats.prescan_s = prescan_s;
  r.stats.pairing_s = seconds_since(t_all);
  return r;
}

PairingStats pairing_stats(const PolyMesh& mesh, const PairingOptions& opt) {
  check_mesh(mesh);
  TriangleMesh tm = triangulate_fan({&mesh});
  PairingInput in{tm.vertices.data(), tm.vertices.size(), tm.tris.data(), tm.tri_count(),
                  tm.geom_ids.data()};
  PairingResult r = pair_triangles(in, opt);
  PairingStats s = r.stats;
  if (!s.prescan_skipped && !std::isnan(s.window2_paired_fraction)) return s;
  // The figures the pairing did not need (not part of pairing_s), on the input it paired.
  PairingInput hin = in;
  std::vector<uint32_t> remap, welded_tris;
  if (opt.weld && weld_positions(in.vertices, in.vertex_count, remap)) {
    welded_tris.resize(3 * in.tri_count);
    for (uint64_t i = 0; i < 3 * in.tri_count; ++i) welded_tris[i] = remap[in.tris[i]];
    hin.tris = welded_tris.data();
  }
  if (s.prescan_skipped)
    s.heuristic_paired_fraction =
        heuristic(hin, opt.coordinate_keys, false).stats.heuristic_paired_fraction;
  if (std::isnan(s.window2_paired_fraction)) {
    std::vector<TrianglePair> unused;
    const uint64_t nw = window_scan(hin, opt.coordinate_keys, 2.0, unused);
    s.window2_paired_fraction = in.tri_count ? double(2 * nw) / double(in.tri_count) : 0.0;
  }
  return s;
}

std::vector<PairedQuad> pair_quads(const PolyMesh& mesh, const PairingOptions& opt) {
  check_mesh(mesh);
  TriangleMesh tm = triangulate_fan({&mesh});
  PairingInput in{tm.vertices.data(), tm.vertices.size(), tm.tris.data(), tm.tri_count(),
                  tm.geom_ids.data()};
  const PairingResult r = pair_triangles(in, opt);
  // Fan index of each triangle: a face's fan triangles are consecutive (triangulate_fan).
  const uint64_t T = tm.tri_count();
  std::vector<uint32_t> fan(T);
  for (uint64_t t = 0; t < T; ++t)
    fan[t] = t > 0 && tm.prim_ids[t - 1] == tm.prim_ids[t] ? fan[t - 1] + 1 : 0;
  std::vector<PairedQuad> out;
  out.reserve(r.pairs.size() + r.unpaired.size());
  // Quad corner of each of the triangle's input corners, the triangle's corners being at quad
  // corners q[0..2] in its own order.
  auto set_half = [&](PairedQuad& q, int h, uint32_t t, const int qc[3]) {
    q.face[h] = tm.prim_ids[t];
    q.fan[h] = fan[t];
    for (int k = 0; k < 3; ++k) q.corner[h][k] = uint8_t(qc[k]);
  };
  for (const TrianglePair& p : r.pairs) {
    const uint32_t* ta = &tm.tris[3 * size_t(p.a)];
    const uint32_t* tb = &tm.tris[3 * size_t(p.b)];
    PairedQuad q;
    // Triangle 0 = (v0, v1, v3) = a's corners (ea + 2, ea, ea + 1): its own winding.
    q.v[0] = ta[(p.ea + 2) % 3];
    q.v[1] = ta[p.ea];
    q.v[3] = ta[(p.ea + 1) % 3];
    q.v[2] = tb[(p.eb + 2) % 3];
    int qa[3];
    qa[(p.ea + 2) % 3] = 0;
    qa[p.ea] = 1;
    qa[(p.ea + 1) % 3] = 3;
    set_half(q, 0, p.a, qa);
    // b's shared corners eb, eb + 1 lie on v1 = a's ea and v3 = a's ea + 1.
    const bool b0_is_v1 = shared_edge_same_direction(tm.vertices.data(), ta, p.ea, tb, p.eb);
    int qb[3];
    qb[(p.eb + 2) % 3] = 2;
    qb[p.eb] = b0_is_v1 ? 1 : 3;
    qb[(p.eb + 1) % 3] = b0_is_v1 ? 3 : 1;
    set_half(q, 1, p.b, qb);
    out.push_back(q);
  }
  for (uint32_t t : r.unpaired) {
    const uint32_t* tt = &tm.tris[3 * size_t(t)];
    PairedQuad q;
    q.v[0] = tt[0];
    q.v[1] = tt[1];
    q.v[2] = q.v[3] = tt[2];
    const int qc[3] = {0, 1, 3};
    set_half(q, 0, t, qc);
    q.face[1] = kInvalidID;
    q.fan[1] = 0;
    for (int k = 0; k < 3; ++k) q.corner[1][k] = 0;
    out.push_back(q);
  }
  return out;
}

}  // namespace slim
