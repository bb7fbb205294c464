// The index-key pairing order applied as a full table and locally (see pairing_orders.h), on the
// internals of mesh/pairing_internal.h.
#include "pairing_orders.h"

#include <algorithm>
#include <cstdint>
#include <vector>

#include "core/large_array.h"
#include "mesh/pairing_internal.h"

namespace slim::test {

namespace {

using namespace slim::pairing_detail;

// Index-key full table: key = BBSA float bits (31 bits: areas >= 0, so the bits order like the
// values) : smaller vertex : larger vertex, each vertex in just enough bits for the vertex count;
// complemented so that an ascending sort gives the paper's descending order.
void full_table(const PairingInput& in, Greedy& g, PairingStats& st) {
  const uint64_t T = in.tri_count;
  LargeArray<HalfEdgeRec> table(3 * T);
  size_t n = 0;
  const int vb = std::max(1, bit_width(in.vertex_count ? in.vertex_count - 1 : 0));
  const int key_bits = 31 + 2 * vb;
  using u128 = unsigned __int128;
  const u128 all = (u128(1) << key_bits) - 1;
  for (uint64_t t = 0; t < T; ++t) {
    const uint32_t* v = &in.tris[3 * t];
    for (int k = 0; k < 3; ++k) {
      uint32_t i0 = v[k], i1 = v[next3(k)];
      if (i0 == i1) continue;  // degenerate edge: never paired on
      uint32_t v0 = std::min(i0, i1), v1 = std::max(i0, i1);
      float area = edge_box_area(in.vertices[v0], in.vertices[v1]);
      u128 key = all - ((u128(float_bits(area)) << (2 * vb)) | (u128(v0) << vb) | v1);
      table[n++] = {uint64_t(key), uint32_t(key >> 64), uint32_t(3 * t + k)};
    }
  }
  st.half_edges = n;
  sort_and_scan_table(table.data(), n, key_bits, g, st);
}

// The same pairs without a global sort (EdgeOrder::Local). The greedy scan over a
// strict total order of candidate pairs accepts exactly the pairs that are "locally dominant"
// when they are accepted: heavier than every other candidate of both triangles among free
// triangles (R. Preis, "Linear time 1/2-approximation algorithm for maximum weighted matching in
// general graphs", STACS 1999). So: from a free triangle, follow best-candidate pointers (the
// priority rises along the path) until two triangles choose each other, pair them, go on. The
// order is the paper's: (BBSA, smaller vertex, larger vertex) descending, and inside a run of 3+
// twins the run's pair order (first two eligible first). Only the neighbours of a triangle are
// touched, in mesh order: no table of all edges is sorted or scanned.
struct Priority {
  uint64_t hi = 0, lo = 0;  // BBSA bits : smaller vertex | larger vertex : run positions
  bool operator>(const Priority& o) const { return hi > o.hi || (hi == o.hi && lo > o.lo); }
};
struct Candidate {
  uint32_t partner = kNone;
  uint32_t h = kNone, o = kNone;  // own half-edge, partner's half-edge
  Priority prio;
};

SLIM_INLINE Priority edge_priority(uint32_t area_bits, uint32_t i0, uint32_t i1, uint32_t i,
                                   uint32_t j) {
  uint32_t v0 = std::min(i0, i1), v1 = std::max(i0, i1);
  return {uint64_t(area_bits) << 32 | v0, uint64_t(v1) << 32 | (0xffffu - i) << 16 | (0xffffu - j)};
}

void local_scan(const PairingInput& in, Greedy& g, const Twins& tw) {
  const uint32_t* tris = in.tris;
  auto best = [&](uint32_t x) {
    Candidate c;
    const uint32_t* v = &tris[3 * size_t(x)];
    for (int k = 0; k < 3; ++k) {
      const uint32_t h = 3 * x + k;
      const uint32_t o = tw.link[h];
      if (o != kNone) {
        if (g.is_used(o / 3)) continue;
        const float area = edge_box_area(in.vertices[v[k]], in.vertices[v[next3(k)]]);
        Priority p = edge_priority(float_bits(area), v[k], v[next3(k)], 0, 1);
        if (p > c.prio || c.partner == kNone) c = {o / 3, h, o, p};
      }
    }
    if ((tw.in_run[x / 64] >> (x % 64)) & 1) {
      for (int k = 0; k < 3; ++k) {
        const uint32_t h = 3 * x + k;
        const uint32_t off = tw.run_offset(h);
        if (off == kNone) continue;
        const uint32_t* run = &tw.runs[off + 1];
        const uint32_t cnt = std::min<uint32_t>(tw.runs[off], 0xffff);
        uint32_t i = 0;
        while (i < cnt && run[i] != h) ++i;
        if (i == cnt) continue;
        for (uint32_t j = 0; j < cnt; ++j) {
          const uint32_t o = run[j], n = o / 3;
          if (j == i || n == x || g.is_used(n) || !g.compatible(h, o)) continue;
          const float area = edge_box_area(in.vertices[v[k]], in.vertices[v[next3(k)]]);
          Priority p =
              edge_priority(float_bits(area), v[k], v[next3(k)], std::min(i, j), std::max(i, j));
          if (p > c.prio || c.partner == kNone) c = {n, h, o, p};
        }
      }
    }
    return c;
  };
  std::vector<uint32_t> stack;
  for (uint64_t s = 0; s < in.tri_count; ++s) {
    if (g.is_used(uint32_t(s))) continue;
    stack.push_back(uint32_t(s));
    while (!stack.empty()) {
      const uint32_t x = stack.back();
      if (g.is_used(x)) {
        stack.pop_back();
        continue;
      }
      const Candidate c = best(x);
      if (c.partner == kNone) {  // no free neighbour left: x stays unpaired
        stack.pop_back();
        continue;
      }
      const Candidate d = best(c.partner);  // >= c.prio, since x is one of its candidates
      if (d.h == c.o && d.o == c.h) {  // the same candidate: x and its partner choose each other
        g.accept(c.h, c.o);
        stack.pop_back();
      } else {
        stack.push_back(c.partner);
      }
    }
  }
  for (size_t r = 0; r < tw.runs.size(); r += tw.runs[r] + 1) g.nonmanifold++;
}

}  // namespace

PairingResult pair_in_order(const PairingInput& in_arg, EdgeOrder order) {
  if (order == EdgeOrder::TwinSort) return pair_by_edge_heuristic(in_arg, false);
  const PairingInput in = prepare(in_arg);
  PairingResult r;
  Greedy g(in, false, false);
  if (order == EdgeOrder::FullTable) {
    full_table(in, g, r.stats);
  } else {
    Twins tw;
    find_twins(in, g, tw, false, nullptr, nullptr, r.stats);
    local_scan(in, g, tw);
  }
  finish(in, g, nullptr, r);
  return r;
}

}  // namespace slim::test
