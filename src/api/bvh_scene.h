// A scene that is one BVH8 over the blocks of one leaf format: the common case for every format.
#pragma once

#include <chrono>
#include <concepts>
#include <cstdint>
#include <cstring>
#include <functional>
#include <string>
#include <vector>

#include <tbb/enumerable_thread_specific.h>

#include "api/scene_file.h"
#include "api/scene_impl.h"
#include "bvh/build.h"
#include "bvh/bvh8.h"
#include "bvh/traverse.h"
#include "core/progress.h"

namespace slim {

// Order-independent fingerprint of a multiset of 64-bit primitive keys: validate() compares the
// keys found in the leaves with the keys of the source primitives (each exactly once).
struct Fingerprint {
  uint64_t count = 0, sum = 0, sum_sq = 0, xor_all = 0;
  void add(uint64_t k) {
    count++;
    sum += k;
    sum_sq += k * k;
    xor_all ^= k * 0x9E3779B97F4A7C15ULL;
  }
  void remove(uint64_t k) {  // undoes add(k)
    count--;
    sum -= k;
    sum_sq -= k * k;
    xor_all ^= k * 0x9E3779B97F4A7C15ULL;
  }
  void merge(const Fingerprint& o) {
    count += o.count;
    sum += o.sum;
    sum_sq += o.sum_sq;
    xor_all ^= o.xor_all;
  }
  bool operator==(const Fingerprint& o) const {
    return count == o.count && sum == o.sum && sum_sq == o.sum_sq && xor_all == o.xor_all;
  }
};

inline NodeKind node_kind(Nodes n) {
  switch (n) {
    case Nodes::Bvh8:
      return NodeKind::Bvh8;
    case Nodes::QBvh8:
      return NodeKind::QBvh8;
    case Nodes::CompressedLeaf:
      return NodeKind::CompressedLeaf;
  }
  return NodeKind::Bvh8;
}

inline CollapseRule collapse_rule(const BuildOptions& opt, NodeKind kind) {
  switch (opt.collapse) {
    case Collapse::Optimal:
      return CollapseRule::Optimal;
    case Collapse::Slots:
      return CollapseRule::Slots;
    case Collapse::Auto:
      break;
  }
  return default_collapse_rule(kind);
}

// The structure check of scene files (OpenOptions::check_structure) needs every leaf format to
// check its blocks: Leaf::check_block(ctx, block), and for a multi-leaf layout with data of its
// own Leaf::check_multileaf(ctx, data, children, bytes left in the leaf arena), each answering
// nullptr / "" for a block the traversal reads inside the mapped sections only, else what is
// wrong (fault_text, api/scene_file.h). BvhScene refuses to compile for a leaf without them.
template <class Leaf>
concept StructureCheckedLeaf = requires(const typename Leaf::Context& c, const uint8_t* b) {
  { fault_text(Leaf::check_block(c, b)) } -> std::same_as<std::string>;
}
&&(!HasMultiLeafLayout<Leaf> || requires(const typename Leaf::Context& c, const uint8_t* b) {
  { fault_text(Leaf::check_multileaf(c, b, 1u, uint64_t(0))) } -> std::same_as<std::string>;
});

template <class Leaf>
class BvhScene : public Scene::Impl {
  static_assert(StructureCheckedLeaf<Leaf>,
                "a leaf format needs its structure check: Leaf::check_block (and "
                "Leaf::check_multileaf for a multi-leaf layout with data of its own)");

 public:
  Bvh8 bvh;
  typename Leaf::Context ctx{};
  Fingerprint expected;                   // of the source primitives
  std::shared_ptr<const void> keepalive;  // data the context points into (counted in mem)

  void intersect(TravRay& ray, HitRecord& hit) const override {
    NoStats st;
    traverse_bvh8<Leaf, false>(bvh, ctx, ray, hit, st);
  }
  bool occluded(TravRay& ray) const override {
    NoStats st;
    HitRecord h;
    return traverse_bvh8<Leaf, true>(bvh, ctx, ray, h, st);
  }
  void intersect_counted(TravRay& ray, HitRecord& hit, TraversalCounters& c) const override {
    CountStats st{&c};
    traverse_bvh8<Leaf, false>(bvh, ctx, ray, hit, st);
  }
  bool validate(std::string* why) const override {
    Fingerprint got;
    auto leaf = [&](const uint8_t* block, Box3f& bounds, std::string*) {
      Leaf::visit(ctx, block, [&](const Box3f& b, uint64_t key) {
        bounds.extend(b);
        got.add(key);
      });
      return true;
    };
    MultiLeafValidator multi;
    if constexpr (HasMultiLeafLayout<Leaf>)
      multi = [&](const uint8_t* data, uint32_t k, uint32_t i, Box3f& bounds, std::string*) {
        // A block split into several children (sub-grid parts) is counted once.
        bool primary = true;
        if constexpr (HasMultiLeafParts<Leaf>) primary = Leaf::primary_part(ctx, i);
        Leaf::visit_in_multileaf(ctx, data, k, int(i), [&](const Box3f& b, uint64_t key) {
          bounds.extend(b);
          if (primary) got.add(key);
        });
        return true;
      };
    if (!validate_bvh8(bvh, leaf, why, multi, multileaf_box_decoder())) return false;
    if (!(got == expected)) {
      if (why)
        *why = "primitives in the leaves (" + std::to_string(got.count) +
               ") differ from the source primitives (" + std::to_string(expected.count) +
               "): some missing, duplicated or altered";
      return false;
    }
    return true;
  }

  // How validate_bvh8 decodes the multi-leaf boxes (traverse.h, HasMultiLeafBoxes).
  MultiLeafBoxDecoder multileaf_box_decoder() const {
    MultiLeafBoxDecoder d;
    if constexpr (HasMultiLeafBoxes<Leaf>) {
      d.header_bytes = Leaf::kMultiLeafHeaderBytes;
      d.frame = [this](const uint8_t* p, float* start, float* extent) {
        Leaf::multileaf_frame(ctx, p, start, extent);
      };
      d.planes = [](const uint8_t* p, uint8_t(*q)[8]) { Leaf::multileaf_planes8(p, q); };
    }
    return d;
  }

  // Scene files: the BVH's arenas and figures, the source fingerprint and the leaf context's
  // buffers (Leaf::context_sections), under `p` ("" or "tris." for a second BVH).
  struct BvhMeta {
    uint64_t root;
    Box3f bounds;
    uint32_t block_bytes, reserved;
    uint64_t node_bytes, multileaf_bytes, leaf_data_bytes;
    Bvh8Stats stats;
  };
  void bvh_sections(SectionVisitor& v, const std::string& p) {
    v.arena(p + "bvh.nodes", bvh.nodes);
    v.arena(p + "bvh.leaves", bvh.leaves);
    BvhMeta m;
    std::memset(static_cast<void*>(&m), 0, sizeof m);  // no uninitialized padding in the file
    m.root = bvh.root;
    m.bounds = bvh.bounds;
    m.block_bytes = bvh.block_bytes;
    m.node_bytes = bvh.node_bytes;
    m.multileaf_bytes = bvh.multileaf_bytes;
    m.leaf_data_bytes = bvh.leaf_data_bytes;
    m.stats = bvh.stats;
    v.pod(p + "bvh.meta", m);
    bvh.root = m.root;
    bvh.bounds = m.bounds;
    bvh.block_bytes = m.block_bytes;
    bvh.node_bytes = m.node_bytes;
    bvh.multileaf_bytes = m.multileaf_bytes;
    bvh.leaf_data_bytes = m.leaf_data_bytes;
    bvh.stats = m.stats;
    v.pod(p + "bvh.expected", expected);
    if constexpr (requires { Leaf::context_sections(v, p, ctx); })
      Leaf::context_sections(v, p, ctx);
  }
  void sections(SectionVisitor& v) override { bvh_sections(v, ""); }

  // The checks of an opened BVH (Scene::Impl::check_opened): the root reference and block size;
  // with `deep`, the walk of every reference with the leaf's block checks. Formats whose blocks
  // index side tables check those tables' own fields first (their check_opened).
  void check_bvh(const std::string& p, bool deep) const {
    constexpr uint32_t hb = multileaf_header_bytes<Leaf>();
    // The walk asks for at most 4: the widest typed field a layout reads from its leaves (the
    // floats of a MultiLeaf8, the uint32 of a block); stricter padding is the collapse's choice.
    constexpr uint32_t align = std::min(leaf_align<Leaf>(), 4u);
    check_bvh_root(bvh, p, Leaf::kBlockBytes, hb, align);
    if (!deep) return;
    BvhWalkHooks h;
    h.multileaf_header_bytes = hb;
    h.leaf_align = align;
    const uint8_t* leaves = bvh.leaves.data();
    h.block = [&](uint64_t off) { return fault_text(Leaf::check_block(ctx, leaves + off)); };
    if constexpr (HasMultiLeafLayout<Leaf>)
      h.multi = [&](uint64_t off, uint32_t k) {
        // off + hb <= size: checked by the walk.
        return fault_text(
            Leaf::check_multileaf(ctx, leaves + off + hb, k, bvh.leaves.size() - off - hb));
      };
    walk_bvh_checked(bvh, p, h);
  }
  void check_opened(bool deep) const override { check_bvh("", deep); }

  // Builds the BVH over `prim_count` primitives of `src` (Leaf::encode, Leaf::source_key and
  // Leaf::source_bounds read it), fills bvh, expected, bounds and the BVH part of stats/mem.
  // Optional hooks (cluster formats): the BVH2's leaf shape, and a pass that restructures
  // the BVH2 before the collapse.
  // Progress (BuildOptions::progress): this build ends the scene's "prepare" phase unless
  // ends_prepare is false, and its phases are named "bvh2" and "collapse" plus phase_suffix.
  struct Bvh2Hooks {
    uint32_t max_leaf_size = 0, block_prims = 0;  // override the BVH2 config when nonzero
    uint32_t full_blocks_below = 0;               // Bvh2BuildConfig::full_blocks_below
    // CompressedLeaf with quantized inner nodes (QCompressedLeaf: CQNode8 / QNode8, Node8 at the
    // top of the tree).
    bool quantized_inner = false;
    std::function<void(Bvh2&)> reshape;
    // Bvh2BuildConfig::thin_stack, for leaves whose primitives hold several triangles.
    std::function<void(const uint32_t* ids, uint32_t n, uint8_t* keep)> thin_stack;
    bool ends_prepare = true;
    std::string phase_suffix;
  };
  template <class Source>
  void build(const Source& src, uint32_t prim_count, const BuildOptions& opt,
             const Bvh2Hooks& hooks = {}) {
    using clock = std::chrono::steady_clock;
    auto secs = [](clock::time_point a) {
      return std::chrono::duration<double>(clock::now() - a).count();
    };
    auto t0 = clock::now();
    // The references go straight into the builder's array (no array of PrimRefs of its own);
    // the source keys for validate() are taken in the same pass over the source.
    tbb::enumerable_thread_specific<Fingerprint> keys;
    const PrimRefFill fill = [&](uint32_t begin, uint32_t end, PrimRef* out) {
      Fingerprint& f = keys.local();
      for (uint32_t i = begin; i < end; ++i) {
        out[i - begin] = {Leaf::source_bounds(src, i), i};
        f.add(Leaf::source_key(src, i));
      }
    };
    Bvh2BuildConfig cfg;
    cfg.bins = opt.sah_bins;
    cfg.max_leaf_size = std::max<uint32_t>(
        1, std::min<uint32_t>(opt.max_leaf_size, Leaf::kBlockPrims * kMaxLeafBlocks));
    cfg.block_prims = Leaf::kBlockPrims;
    if (hooks.max_leaf_size) cfg.max_leaf_size = hooks.max_leaf_size;
    if (hooks.block_prims) cfg.block_prims = hooks.block_prims;
    cfg.full_blocks_below = hooks.full_blocks_below;
    cfg.threads = opt.threads;
    std::unique_ptr<PhaseProgress> progress;
    if (opt.progress) {
      if (hooks.ends_prepare) report_progress(opt.progress, "prepare", 1, 1);
      progress = std::make_unique<PhaseProgress>(opt.progress, "bvh2" + hooks.phase_suffix,
                                                 2 * uint64_t(prim_count));
    }
    cfg.progress = progress.get();
    // Formats that keep one primitive per id (the triangle formats) let the builder drop exact
    // duplicates from stacks of coincident primitives (Bvh2BuildConfig::duplicate_key).
    constexpr bool kDropsDuplicates = requires(const Source& s) {
      { Leaf::duplicate_key(s, 0u) } -> std::same_as<uint64_t>;
      { Leaf::same_surface(s, 0u, 0u) } -> std::same_as<bool>;
    };
    if constexpr (kDropsDuplicates) {
      cfg.duplicate_key = [&](uint32_t i) { return Leaf::duplicate_key(src, i); };
      cfg.same_primitive = [&](uint32_t a, uint32_t b) { return Leaf::same_surface(src, a, b); };
    }
    cfg.thin_stack = hooks.thin_stack;
    Bvh2 b2 = build_bvh2(prim_count, fill, cfg);
    if (hooks.reshape) hooks.reshape(b2);
    if (progress) progress->finish();
    expected = Fingerprint{};
    for (const Fingerprint& f : keys) expected.merge(f);
    for (uint32_t id : b2.dropped) expected.remove(Leaf::source_key(src, id));
    double bvh2_s = secs(t0);
    t0 = clock::now();
    LeafEncoder enc;
    enc.block_prims = Leaf::kBlockPrims;
    enc.block_bytes = Leaf::kBlockBytes;
    enc.leaf_align = leaf_align<Leaf>();
    enc.encode = [&](const uint32_t* prims, uint32_t n, uint8_t* out) {
      Leaf::encode(src, prims, n, out);
    };
    if constexpr (HasMultiLeafEncoder<Leaf>)
      enc.encode_multileaf = [&](const uint32_t* const* prims, const uint32_t* counts, int k) {
        return Leaf::encode_multileaf(src, prims, counts, k);
      };
    if constexpr (HasMultiLeafBoxes<Leaf>) {
      enc.multileaf_header_bytes = Leaf::kMultiLeafHeaderBytes;
      enc.multileaf_boxes = [&](const uint8_t* data, int k, const Box3f* boxes, uint8_t* header) {
        Leaf::write_multileaf_boxes(src, data, k, boxes, header);
      };
    }
    if constexpr (HasMultiLeafParts<Leaf>) {
      enc.parts_per_block = Leaf::multileaf_parts(src);
      if (enc.parts_per_block > 1)
        enc.part_bounds = [&](uint32_t prim, Box3f* boxes) { Leaf::part_bounds(src, prim, boxes); };
    }
    if (opt.progress)
      progress = std::make_unique<PhaseProgress>(opt.progress, "collapse" + hooks.phase_suffix,
                                                 2 * uint64_t(prim_count));
    NodeKind kind = node_kind(opt.nodes);
    if (hooks.quantized_inner && kind == NodeKind::CompressedLeaf) kind = NodeKind::QCompressedLeaf;
    bvh = collapse_bvh8(b2, kind, enc, collapse_rule(opt, kind), progress.get());
    if (progress) progress->finish();
    double collapse_s = secs(t0);
    bounds = bvh.bounds;
    mem.bvh_bytes = bvh.kept_bvh_bytes();
    mem.geometry_bytes += bvh.kept_leaf_bytes();
    stats.primitives = prim_count;
    const Bvh8Stats& s = bvh.stats;
    auto& d = stats.details;
    d.emplace_back("bvh2_build_s", bvh2_s);
    d.emplace_back("collapse_s", collapse_s);
    if constexpr (kDropsDuplicates)
      d.emplace_back("duplicate_triangles", double(b2.dropped.size()));
    d.emplace_back("bvh2_depth", double(b2.depth));
    d.emplace_back("bvh8_depth", double(s.depth));
    d.emplace_back("node8_count", double(s.node8));
    d.emplace_back("qnode8_count", double(s.qnode8));
    if (s.cqnode8) d.emplace_back("cqnode8_count", double(s.cqnode8));  // of the qnode8
    d.emplace_back("multileaf_count", double(s.multileaf));
    d.emplace_back("leaf_count", double(s.leaves));
    d.emplace_back("leaves_in_multileaf", double(s.leaves_in_multileaf));
    d.emplace_back("leaf_blocks", double(s.leaf_blocks));
    d.emplace_back("leaf_fill", s.leaf_fill);
    d.emplace_back("sah_cost", s.sah_cost);
    d.emplace_back("node_bytes", double(bvh.node_bytes));
    d.emplace_back("multileaf_bytes", double(bvh.multileaf_bytes));
    d.emplace_back("leaf_data_bytes", double(bvh.leaf_data_bytes));
  }
};

}  // namespace slim
