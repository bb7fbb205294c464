// Triangle-pair formats: bvh8-pairs, clbvh-pairs (and qbvh8-pairs), and bvh8-pairs-w2 (the same
// leaves over the paper's baseline pairing, in-order window N = 2). A. Aman, S. Fenney, "Fast
// Triangle Pairing for Ray Tracing", Imagination Technologies: the fan triangles of the input are
// paired with the edge-box surface-area heuristic (mesh/pairing.h, BuildOptions::pairing_options),
// and the BVH is built over pairs stored in Pair4 leaves (prim/pairs.h).
//
// Choices, measured single-threaded (diffuse paths, 160 x 160 pixels, thread CPU time, best of
// 5-7 interleaved runs, AVX2, on the shared 2-core build VM):
//   - Unpaired triangles are degenerate pairs in the same leaves (their B lane masked off), not a
//     second BVH of tri4v leaves beside the pair BVH: one traversal instead of two is 17-35%
//     faster (nefertiti 6.7 vs 5.0-5.2 MRays/s, igea 5.3-5.5 vs 4.5) for 1-4% more memory
//     (nefertiti 45.4 vs 44.9 B/triangle).
//   - Leaves of one Pair4 block (up to 4 pairs = 8 triangles, one 8-wide test) beat
//     Pair2 blocks (2 pairs, one 4-wide test) with leaves of 2 or 4 pairs, under BVH8 and CLBVH:
//     bvh8 bunny 4.77 vs 4.68 / 4.59 MRays/s, nefertiti 6.72 vs 6.39 / 6.30, igea 5.33 vs
//     4.59 / 4.83; and they take the least memory (bunny 46.4 vs 52.0 / 49.3 B/triangle). The
//     price: twice the triangle tests per ray of tri4v (8 lanes per leaf test instead of 4); Pair2
//     with 2-pair leaves tests as many triangles as tri4v (or slightly fewer) but gains only 3%.
#include <algorithm>
#include <cmath>
#include <mutex>
#include <vector>

#include "api/bvh_scene.h"
#include "mesh/pairing.h"
#include "mesh/triangulate.h"
#include "prim/pairs.h"

namespace slim {

namespace {

// Stacks of coincident triangles (Bvh2BuildConfig::thin_stack). A pair can be a duplicate in
// part (pairing joins coincident triangles too), so duplicates are found among the triangles of
// the node's pairs: of each group of exact duplicates (TriangleSourceOps::duplicate_key: the
// same positions in any rotation) the lowest triangle stays, which is the lowest input face of
// the group (triangles are numbered in face order). A pair that loses one triangle becomes a lone
// triangle; one that loses both, or a lone triangle that is a duplicate, is left out.
class PairStackThinner {
 public:
  PairStackThinner(LargeVector<PairRef>& refs, const PairSource& src) : refs_(refs), src_(src) {}

  void operator()(const uint32_t* ids, uint32_t n, uint8_t* keep) {
    struct Tri {
      uint64_t key;
      uint32_t t;
      uint32_t slot;  // 2 x position in ids, + 1 for triangle b of the pair
    };
    std::vector<Tri> tris;
    tris.reserve(2 * size_t(n));
    for (uint32_t i = 0; i < n; ++i) {
      const PairRef& p = refs_[ids[i]];
      tris.push_back({TriangleSourceOps::duplicate_key(src_.tris, p.a), p.a, 2 * i});
      if (p.b != kLoneTriangle)
        tris.push_back({TriangleSourceOps::duplicate_key(src_.tris, p.b), p.b, 2 * i + 1});
    }
    std::sort(tris.begin(), tris.end(), [](const Tri& x, const Tri& y) {
      return x.key != y.key ? x.key < y.key : x.t < y.t;
    });
    std::vector<uint8_t> gone(2 * size_t(n), 0);
    uint64_t dropped = 0;
    std::vector<uint32_t> kept;  // triangles kept with the current key
    for (size_t i = 0; i < tris.size();) {
      size_t j = i;
      kept.clear();
      for (; j < tris.size() && tris[j].key == tris[i].key; ++j) {
        bool dup = false;
        for (size_t k = 0; k < kept.size() && !dup; ++k)
          dup = TriangleSourceOps::same_surface(src_.tris, kept[k], tris[j].t);
        if (dup) {
          gone[tris[j].slot] = 1;
          ++dropped;
        } else {
          kept.push_back(tris[j].t);
        }
      }
      i = j;
    }
    if (!dropped) return;
    std::vector<uint64_t> old_keys, new_keys;  // fingerprint keys of the rewritten pairs
    for (uint32_t i = 0; i < n; ++i) {
      PairRef& p = refs_[ids[i]];
      const bool a_gone = gone[2 * i], b_gone = p.b == kLoneTriangle || gone[2 * i + 1];
      if (a_gone && b_gone) {
        keep[i] = 0;
      } else if (a_gone || (b_gone && p.b != kLoneTriangle)) {
        old_keys.push_back(Pair4::source_key(src_, ids[i]));
        p = PairRef{a_gone ? p.b : p.a, kLoneTriangle, 1, 0};
        new_keys.push_back(Pair4::source_key(src_, ids[i]));
      }
    }
    std::lock_guard<std::mutex> lock(mutex_);
    dropped_ += dropped;
    old_keys_.insert(old_keys_.end(), old_keys.begin(), old_keys.end());
    new_keys_.insert(new_keys_.end(), new_keys.begin(), new_keys.end());
  }

  uint64_t dropped_triangles() const { return dropped_; }
  // validate()'s fingerprint of the source, as it was taken before the pairs were rewritten,
  // brought up to date.
  void update(Fingerprint& f) const {
    for (uint64_t k : old_keys_) f.remove(k);
    for (uint64_t k : new_keys_) f.add(k);
  }

 private:
  LargeVector<PairRef>& refs_;
  const PairSource& src_;
  std::mutex mutex_;
  uint64_t dropped_ = 0;
  std::vector<uint64_t> old_keys_, new_keys_;
};

}  // namespace

std::unique_ptr<Scene::Impl> empty_pair_scene(const BuildOptions&) {
  return std::make_unique<BvhScene<Pair4>>();
}

std::unique_ptr<Scene::Impl> build_pair_scene(const MeshList& meshes, const BuildOptions& opt) {
  TriangleMesh tm = triangulate_fan(meshes);
  PairingInput in{tm.vertices.data(), tm.vertices.size(), tm.tris.data(), tm.tri_count(),
                  tm.geom_ids.data()};
  // bvh8-pairs-w2: the paper's baseline ("Old #pairs").
  PairingResult pr = opt.pairing == PairingMethod::Window2
                         ? window_pairs(in)
                         : pair_triangles(in, opt.pairing_options);

  LargeVector<PairRef> refs;  // huge pages: ~12 B per triangle, filled once
  refs.reserve(pr.pairs.size() + pr.unpaired.size());
  for (const TrianglePair& p : pr.pairs) refs.push_back({p.a, p.b, p.ea, p.eb});
  for (uint32_t t : pr.unpaired) refs.push_back({t, kLoneTriangle, 1, 0});

  PairSource src{{tm.vertices.data(), tm.tris.data(), tm.geom_ids.data(), tm.prim_ids.data()},
                 refs.data()};
  // One Pair4 block (4 pairs, one 8-wide test) per leaf, see above; BuildOptions::max_leaf_size
  // counts triangles and does not apply.
  BuildOptions o = opt;
  o.max_leaf_size = int(Pair4::kBlockPrims);
  auto s = std::make_unique<BvhScene<Pair4>>();
  PairStackThinner thinner(refs, src);
  BvhScene<Pair4>::Bvh2Hooks hooks;
  hooks.thin_stack = [&](const uint32_t* ids, uint32_t n, uint8_t* keep) { thinner(ids, n, keep); };
  s->build(src, uint32_t(refs.size()), o, hooks);
  thinner.update(s->expected);

  const PairingStats& ps = pr.stats;
  auto& d = s->stats.details;
  d.emplace_back("paired_fraction", ps.paired_fraction);
  // Known when the pre-scan ran to the end; it stops once the heuristic is sure to run.
  if (!std::isnan(ps.window2_paired_fraction))
    d.emplace_back("window2_paired_fraction", ps.window2_paired_fraction);
  d.emplace_back("pairing_s", ps.pairing_s);
  d.emplace_back("pairs", double(ps.pairs));
  d.emplace_back("unpaired_triangles", double(ps.unpaired));
  d.emplace_back("duplicate_triangles", double(thinner.dropped_triangles()));
  if (opt.pairing ==
      PairingMethod::EdgeHeuristic) {  // pair_triangles: the pre-scan, then maybe the heuristic
    if (!ps.prescan_skipped) {
      d.emplace_back("heuristic_paired_fraction", ps.heuristic_paired_fraction);
      d.emplace_back("augmented_pairs", double(ps.augmented_pairs));
    }
    d.emplace_back("prescan_skipped", ps.prescan_skipped ? 1.0 : 0.0);
    d.emplace_back("half_edges", double(ps.half_edges));
    d.emplace_back("nonmanifold_edges", double(ps.nonmanifold_edges));
  }
  s->set_input(tm.input_faces, tm.input_triangles, tm.skipped_faces);
  return s;
}

}  // namespace slim
