// libFuzzer target: the triangle pairing (src/mesh/pairing.h; A. Aman, S. Fenney, "Fast Triangle
// Pairing for Ray Tracing", Imagination Technologies) on meshes made from the fuzz input:
// degenerate, duplicated and non-manifold triangles, fans of any valence, coincident unwelded
// vertices, several groups (input meshes).
//
// Input bytes:
//   [0]      bit 0: raw float vertices (any finite value within +-kMaxCoordinate; other bit
//            patterns become 0) instead of an int8 lattice; bit 1: faces carry a group
//   [1]      vertex count - 1 (1..256)
//   then     vertices (3 x int8 or 3 x float each), then faces until the input ends: a size byte
//            (3 + byte % 4 corners; with groups, byte / 4 % 3 is the group), one index byte per
//            corner (modulo the vertex count)
// The faces are fan-triangulated as Scene::build does (mesh/triangulate.h). Checks:
//   - index keys: the three EdgeOrders (tests/pairing_orders.h) give the pairs of the
//   std::stable_sort reference
//     (tests/pairing_reference.h);
//   - coordinate keys, weld, augment, pre-scan on and off, the window-2 baseline: every result
//     satisfies the invariants (each pair shares the edge it records, every triangle in exactly one
//     pair or unpaired, ascending, stats consistent); pair_triangles is deterministic; the
//     augmenting pass only adds pairs (stats.pairs = greedy pairs + augmented_pairs).
#include <cmath>
#include <cstdint>
#include <cstring>
#include <string>
#include <vector>

#include "fuzz_common.h"
#include "mesh/pairing.h"
#include "mesh/triangulate.h"
#include "pairing_orders.h"
#include "pairing_reference.h"
#include "slimrt/scene.h"

namespace {

using namespace slim;

using fuzz::Reader;

// The invariants (tests/pairing_reference.h); returns the pairs.
test::PairSet check(const PairingInput& in, const PairingResult& r, bool by_position,
                    const std::string& what) {
  test::PairSet got;
  const std::string why = test::pairing_problem(in, r, by_position, &got);
  SLIM_FUZZ_CHECK(why.empty(), what + ": " + why);
  return got;
}

bool same_result(const PairingResult& a, const PairingResult& b) {
  if (a.pairs.size() != b.pairs.size() || a.unpaired.size() != b.unpaired.size()) return false;
  for (size_t i = 0; i < a.pairs.size(); ++i) {
    const TrianglePair &x = a.pairs[i], &y = b.pairs[i];
    if (x.a != y.a || x.b != y.b || x.ea != y.ea || x.eb != y.eb) return false;
  }
  return std::equal(a.unpaired.begin(), a.unpaired.end(), b.unpaired.begin());
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  Reader rd{data, size};
  const uint8_t flags = rd.byte();
  const bool raw = flags & 1, grouped = flags & 2;
  const uint32_t nv = 1 + rd.byte();
  PolyMesh m;
  m.name = "fuzz";
  for (uint32_t i = 0; i < nv; ++i) {
    Vec3f p;
    if (raw) {
      float c[3];
      rd.bytes(c, sizeof c);
      for (float& x : c)
        if (!(std::fabs(x) <= kMaxCoordinate)) x = 0.0f;  // NaN too
      p = {c[0], c[1], c[2]};
    } else {
      int8_t c[3];
      rd.bytes(c, sizeof c);
      p = {float(c[0]), float(c[1]), float(c[2])};
    }
    m.positions.push_back(p);
  }
  std::vector<uint32_t> face_group;
  while (rd.n > 0) {
    const uint8_t s = rd.byte();
    const uint32_t corners = 3 + s % 4;
    for (uint32_t k = 0; k < corners; ++k) m.face_indices.push_back(rd.byte() % nv);
    m.face_sizes.push_back(corners);
    face_group.push_back(grouped ? s / 4 % 3 : 0);
  }
  check_mesh(m);  // every index is in range: must not throw
  const TriangleMesh tm = triangulate_fan({&m});
  // Group of each fan triangle: the group of its face (tm.prim_ids holds the input face).
  std::vector<uint32_t> groups(tm.tri_count());
  for (size_t t = 0; t < groups.size(); ++t) groups[t] = face_group[tm.prim_ids[t]];
  const PairingInput in{tm.vertices.data(), tm.vertices.size(), tm.tris.data(), tm.tri_count(),
                        groups.data()};

  const test::PairSet ref = test::reference_pairs(in);
  const test::EdgeOrder orders[3] = {test::EdgeOrder::FullTable, test::EdgeOrder::TwinSort,
                                     test::EdgeOrder::Local};
  for (test::EdgeOrder o : orders) {
    const std::string what = "index keys, order " + std::to_string(int(o));
    const test::PairSet got = check(in, test::pair_in_order(in, o), false, what);
    SLIM_FUZZ_CHECK(got == ref, what + ": not the reference's pairs (" +
                                    std::to_string(got.size()) + " vs " +
                                    std::to_string(ref.size()) + ")");
  }
  check(in, pair_by_edge_heuristic(in, true), true, "coordinate keys");
  check(in, window_pairs(in, false), false, "window-2 by index");
  check(in, window_pairs(in, true), true, "window-2 by position");

  for (int mask = 0; mask < 16; ++mask) {
    PairingOptions opt;
    opt.coordinate_keys = mask & 1;
    opt.weld = mask & 2;
    opt.augment = mask & 4;
    opt.prescan_threshold = mask & 8 ? 2.0 : 0.99;
    const std::string what = "pair_triangles options " + std::to_string(mask);
    const PairingResult r = pair_triangles(in, opt);
    // Weld and coordinate keys pair by position; the result's indices are the input's.
    check(in, r, opt.coordinate_keys || opt.weld, what);
    SLIM_FUZZ_CHECK(same_result(r, pair_triangles(in, opt)), what + ": not deterministic");
    if (!r.stats.prescan_skipped) {
      const double greedy = r.stats.heuristic_paired_fraction * double(in.tri_count) / 2;
      SLIM_FUZZ_CHECK(
          std::fabs(greedy + double(r.stats.augmented_pairs) - double(r.pairs.size())) < 0.5,
          what + ": pairs != greedy pairs + augmented pairs");
      SLIM_FUZZ_CHECK(opt.augment || r.stats.augmented_pairs == 0, what + ": augmented when off");
    }
  }
  return 0;
}
