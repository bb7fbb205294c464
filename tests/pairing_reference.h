// The triangle pairing's reference and invariants (A. Aman, S. Fenney, "Fast Triangle Pairing for
// Ray Tracing", Imagination Technologies, "Greedy pairing"), shared by tests/test_pairing.cpp and
// the libFuzzer target fuzz/fuzz_pairing.cpp. No gtest here: problems come back as text.
#pragma once

#include <algorithm>
#include <cstdint>
#include <cstring>
#include <set>
#include <string>
#include <tuple>
#include <utility>
#include <vector>

#include "mesh/pairing.h"

namespace slim::test {

using PairSet = std::set<std::pair<uint32_t, uint32_t>>;

// What is wrong with a pairing result, "" if nothing: every pair a < b shares the edge it records
// (pair pair_shares_edge, and two common vertices, or positions when `by_position`); no triangle
// is in two pairs or both paired and unpaired, every triangle is in one of them; pairs ascend by
// a, unpaired triangles ascend; the counts of the stats match. `out` (optional) gets the pairs.
inline std::string pairing_problem(const PairingInput& in, const PairingResult& r, bool by_position,
                                   PairSet* out = nullptr) {
  auto at = [](const char* what, uint64_t a, uint64_t b) {
    return std::string(what) + " (" + std::to_string(a) + ", " + std::to_string(b) + ")";
  };
  std::vector<int> uses(in.tri_count, 0);
  for (size_t i = 0; i < r.pairs.size(); ++i) {
    const TrianglePair& p = r.pairs[i];
    if (p.a >= p.b || p.b >= in.tri_count) return at("pair out of order or range", p.a, p.b);
    if (i > 0 && r.pairs[i - 1].a >= p.a) return at("pairs not ascending by a", i - 1, i);
    if (p.ea > 2 || p.eb > 2) return at("pair edge corner > 2", p.a, p.b);
    if (!pair_shares_edge(in, p, by_position)) return at("pair shares no edge", p.a, p.b);
    int common = 0;
    for (int x = 0; x < 3; ++x)
      for (int y = 0; y < 3; ++y) {
        const uint32_t va = in.tris[3 * size_t(p.a) + x], vb = in.tris[3 * size_t(p.b) + y];
        common += by_position ? std::memcmp(&in.vertices[va], &in.vertices[vb], 12) == 0 : va == vb;
      }
    if (common < 2) return at("pair with fewer than 2 common corners", p.a, p.b);
    uses[p.a]++;
    uses[p.b]++;
    if (out) out->insert({p.a, p.b});
  }
  for (size_t i = 0; i < r.unpaired.size(); ++i) {
    const uint32_t t = r.unpaired[i];
    if (t >= in.tri_count) return at("unpaired triangle out of range", i, t);
    if (i > 0 && r.unpaired[i - 1] >= t) return at("unpaired not ascending", i - 1, i);
    uses[t] += 10;
  }
  for (uint64_t t = 0; t < in.tri_count; ++t)
    if (uses[t] != 1 && uses[t] != 10) return at("triangle used (count) times", t, uses[t]);
  if (r.stats.pairs != r.pairs.size() || r.stats.unpaired != r.unpaired.size())
    return at("stats counts differ from the result", r.stats.pairs, r.stats.unpaired);
  return "";
}

// The paper's algorithm with std::stable_sort on explicit tuples (the reference for the radix
// version): half-edges sorted descending by (BBSA, smaller vertex, larger vertex), ties in table
// order; a run of equal keys pairs its first two eligible half-edges, then the next two. The
// vertices must be finite with |coordinate| <= kMaxCoordinate, so that no area is NaN.
inline PairSet reference_pairs(const PairingInput& in) {
  struct HE {
    float area;
    uint32_t v0, v1, he;
  };
  std::vector<HE> t;
  for (uint32_t i = 0; i < in.tri_count; ++i)
    for (int k = 0; k < 3; ++k) {
      uint32_t a = in.tris[3 * size_t(i) + k], b = in.tris[3 * size_t(i) + (k + 1) % 3];
      if (a == b) continue;
      uint32_t v0 = std::min(a, b), v1 = std::max(a, b);
      Vec3f d = abs(in.vertices[v1] - in.vertices[v0]);
      t.push_back({d.x * d.y + d.y * d.z + d.z * d.x, v0, v1, 3 * i + k});
    }
  std::stable_sort(t.begin(), t.end(), [](const HE& x, const HE& y) {
    return std::make_tuple(x.area, x.v0, x.v1) > std::make_tuple(y.area, y.v0, y.v1);
  });
  auto group = [&](uint32_t tri) { return in.groups ? in.groups[tri] : 0u; };
  std::vector<bool> used(in.tri_count, false);
  PairSet out;
  for (size_t i = 0; i < t.size();) {
    size_t j = i + 1;
    while (j < t.size() && t[j].area == t[i].area && t[j].v0 == t[i].v0 && t[j].v1 == t[i].v1) ++j;
    for (size_t x = i; x < j; ++x) {
      uint32_t a = t[x].he / 3;
      if (used[a]) continue;
      for (size_t y = x + 1; y < j; ++y) {
        uint32_t b = t[y].he / 3;
        if (b == a || used[b] || group(a) != group(b)) continue;
        used[a] = used[b] = true;
        out.insert({std::min(a, b), std::max(a, b)});
        break;
      }
    }
    i = j;
  }
  return out;
}

}  // namespace slim::test
