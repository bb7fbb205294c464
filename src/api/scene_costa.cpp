// Costa quantized n-gon mesh scenes (V. Costa, J. M. Pereira, J. A. Jorge, "Fast Compression of
// Meshes for GPU Ray-Tracing", WSCG 2013): configs costa, costa-P, ..., costa-TPFV. Loading
// (section 3.1) -> optional T -> BVH2 over the primitives -> primitives reordered in leaf order ->
// the store (section 3.2) -> BVH8 whose leaves are primitive ranges (prim/costa_leaf.h). Also
// costa_sizes() (Tables 1 and 3) for the CLI and the benchmark.
#include <zlib.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <memory>
#include <stdexcept>

#include "api/bvh_scene.h"
#include "api/registry.h"
#include "core/hash.h"
#include "mesh/tessellate.h"
#include "prim/costa_leaf.h"
#include "prim/quantized_mesh.h"
#include "slimrt/costa.h"

namespace slim {

namespace {

// Everything a Costa scene keeps besides the BVH: the store and the primitive -> input face map.
struct CostaData {
  QuantizedMesh store;
  BitArray face_map;                // global input face id per primitive (in store order)
  std::vector<uint32_t> face_base;  // first global face id per mesh, + total
};

// Mesh of a global face id (for the validation keys of the source primitives).
uint32_t mesh_of(const std::vector<uint32_t>& face_base, uint32_t g) {
  return uint32_t(std::upper_bound(face_base.begin(), face_base.end(), g) - face_base.begin()) - 1;
}

// The triangles of the store's primitives, split by the leaves' rules (primitive_triangles), in
// store order, each with its input mesh and face: face_of(i, geom, face) gives them for
// primitive i. Store: a QuantizedMesh or the CostaView a scene traces (offset, face, vertex).
template <class Store, class FaceOf>
DecodedTriangles store_triangles(const Store& q, uint32_t prims, FaceOf&& face_of) {
  NgonMesh d;  // the store's primitives (indices only: primitive_triangles reads no position)
  d.prim_offsets.reserve(size_t(prims) + 1);
  for (uint32_t i = 0; i <= prims; ++i) d.prim_offsets.push_back(q.offset(i));
  d.faces.reserve(d.prim_offsets.back());
  for (uint64_t j = 0; j < d.prim_offsets.back(); ++j) d.faces.push_back(q.face(j));
  DecodedTriangles out;
  std::vector<uint32_t> tris;
  for (uint32_t i = 0; i < prims; ++i) {
    tris.clear();
    primitive_triangles(d, i, tris);
    uint32_t geom = 0, face = 0;
    face_of(i, geom, face);
    for (size_t k = 0; k < tris.size(); ++k) {
      out.vertices.push_back(q.vertex(tris[k]));
      if (k % 3 == 2) {
        out.geom.push_back(geom);
        out.face.push_back(face);
      }
    }
  }
  return out;
}

template <bool P, bool F, bool V>
class CostaScene : public BvhScene<CostaLeaf<P, F, V>> {
 public:
  std::shared_ptr<const CostaData> data;
  QuantizedMesh::Counts opened_counts{};
  uint64_t opened_face_map_bytes = 0, opened_face_base = 0;

  // Scene files: the BVH, the store's arrays and the face map (an opened scene has no `data`:
  // its context points into the mapping).
  void sections(SectionVisitor& v) override {
    this->bvh_sections(v, "");
    auto& c = this->ctx;
    auto& r = c.view.r;
    // Element counts: from the store of a built scene, else those of the opened file.
    QuantizedMesh::Counts& n = opened_counts;
    uint64_t& face_map_bytes = opened_face_map_bytes;
    uint64_t& face_base = opened_face_base;
    if (v.saving() && data) {
      n = data->store.counts();
      face_map_bytes = data->face_map.bytes();
      face_base = data->face_base.size();
    }
    v.array("costa.offsets", r.offsets, n.offsets);
    v.array("costa.residuals", r.residuals, n.residual_bytes);
    v.array("costa.faces", r.faces, n.faces);
    v.array("costa.packed_faces", r.packed_faces, n.packed_face_bytes);
    v.array("costa.vertices", r.vertices, n.vertices);
    v.array("costa.qvertices", r.qvertices, n.qvertices);
    v.array("costa.face_map", c.faces.bits, face_map_bytes);
    v.array("costa.face_base", c.faces.face_base, face_base);
    CostaParams k;
    std::memset(static_cast<void*>(&k), 0, sizeof k);
    k.avg = r.avg;
    k.residual_min = r.residual_min;
    k.quant = r.quant;
    k.residual_bits = r.residual_bits;
    k.face_bits = r.face_bits;
    k.face_width = c.faces.width;
    k.mesh_count = c.faces.mesh_count;
    k.prim_count = c.prim_count;
    v.pod("costa.params", k);
    r.avg = k.avg;
    r.residual_min = k.residual_min;
    r.quant = k.quant;
    r.residual_bits = k.residual_bits;
    r.face_bits = k.face_bits;
    c.faces.width = k.face_width;
    c.faces.mesh_count = k.mesh_count;
    c.prim_count = k.prim_count;
    // The array sizes the structure check bounds the blocks' references by.
    c.counts = n;
    c.face_map_bytes = face_map_bytes;
    c.face_base_count = face_base;
  }

  // Every open: the BVH root; with the structure check, the store's primitives (once), then
  // the walk of the BVH with the blocks' ranges.
  void check_opened(bool deep) const override {
    using Leaf = CostaLeaf<P, F, V>;
    if (deep) {
      const typename Leaf::StoreFault f = Leaf::check_store(this->ctx, this->bvh.leaves.size());
      if (f.what) throw SectionFault{f.section, f.offset, f.what};
    }
    this->check_bvh("", deep);
  }

  bool validate(std::string* why) const override {
    // An opened scene: the BVH walk only (its store is not a QuantizedMesh object).
    if (!data) return BvhScene<CostaLeaf<P, F, V>>::validate(why);
    // The store first, so that the leaf walk below only decodes well-formed primitives.
    if (!data->store.validate(why)) return false;
    if (data->face_map.size() != data->store.prim_count()) {
      if (why) *why = "costa: the face map does not have one entry per primitive";
      return false;
    }
    for (uint64_t i = 0; i < data->face_map.size(); ++i)
      if (data->face_map.get(i) >= data->face_base.back()) {
        if (why) *why = "costa: primitive " + std::to_string(i) + " maps to no input face";
        return false;
      }
    return BvhScene<CostaLeaf<P, F, V>>::validate(why);
  }
  // Decoded from the store (in the BVH's leaf order), as the leaves decode it.
  std::optional<DecodedTriangles> decoded_triangles() const override {
    // From the context, which a built and an opened scene both have.
    const auto& c = this->ctx;
    return store_triangles(c.view, c.prim_count, [&](uint32_t i, uint32_t& geom, uint32_t& face) {
      c.faces.lookup(i, geom, face);
    });
  }
};

// The primitives of `m` in the order `order` (the BVH's leaf order).
NgonMesh reorder(const NgonMesh& m, const LargeArray<uint32_t>& order) {
  NgonMesh r;
  r.vertices = m.vertices;
  r.face_base = m.face_base;
  r.faces.reserve(m.faces.size());
  r.prim_offsets.reserve(m.prim_offsets.size());
  r.prim_face.reserve(m.prim_face.size());
  r.prim_offsets.push_back(0);
  for (uint32_t i : order) {
    r.faces.insert(r.faces.end(), m.faces.begin() + m.prim_offsets[i],
                   m.faces.begin() + m.prim_offsets[i + 1]);
    r.prim_offsets.push_back(uint32_t(r.faces.size()));
    r.prim_face.push_back(m.prim_face[i]);
  }
  return r;
}

// Orders the leaves of `b2` in memory (prim_ids and each leaf's `first`; the tree is unchanged)
// for PACKPRIMITIVES (Listing 2). Its residual at primitive i is the running sum of (size - avg)
// over the primitives before i, so the packed width follows the largest excursion of that sum.
// The paper keeps the input order and notes (section 5) that mixed primitive sizes make the
// residuals large; in leaf order, a region of quads drifts one way and a region of fans the
// other (fg_cg57_cruiser: 12 bits). Leaf order in memory is ours to choose, so the leaves are
// split into two lists in depth-first order -- sum of (size - avg) below zero, and the rest --
// and merged: the next leaf comes from the list that pulls the running sum back toward zero.
// Inside a leaf the primitives are ordered the same way. Each list keeps the spatial order of the
// tree, so neighbours in memory stay near in space.
void order_leaves_for_prediction(Bvh2& b2, const NgonMesh& m) {
  if (b2.nodes.empty()) return;
  const double avg = double(m.faces.size()) / double(m.prim_count());
  std::vector<uint32_t> neg, pos;  // leaf node ids, depth-first
  std::vector<uint32_t> stack{0};
  while (!stack.empty()) {
    const uint32_t i = stack.back();
    stack.pop_back();
    const Bvh2Node& n = b2.nodes[i];
    if (!n.is_leaf()) {
      stack.push_back(n.first + 1);
      stack.push_back(n.first);
      continue;
    }
    double e = 0.0;
    for (uint32_t k = n.first; k < n.first + n.count; ++k)
      e += double(m.prim_size(b2.prim_ids[k])) - avg;
    (e < 0.0 ? neg : pos).push_back(i);
  }
  std::vector<uint32_t> ids;
  ids.reserve(b2.prim_ids.size());
  std::vector<uint32_t> leaf;
  double drift = 0.0;
  size_t a = 0, b = 0;
  while (a < neg.size() || b < pos.size()) {
    const bool take_neg = b == pos.size() || (a < neg.size() && drift >= 0.0);
    Bvh2Node& n = b2.nodes[take_neg ? neg[a++] : pos[b++]];
    leaf.assign(b2.prim_ids.begin() + n.first, b2.prim_ids.begin() + n.first + n.count);
    n.first = uint32_t(ids.size());
    // Greedy inside the leaf: the primitive that keeps the running sum nearest zero next.
    while (!leaf.empty()) {
      size_t best = 0;
      double best_abs = std::abs(drift + double(m.prim_size(leaf[0])) - avg);
      for (size_t k = 1; k < leaf.size(); ++k) {
        const double d = std::abs(drift + double(m.prim_size(leaf[k])) - avg);
        if (d < best_abs) best = k, best_abs = d;
      }
      drift += double(m.prim_size(leaf[best])) - avg;
      ids.push_back(leaf[best]);
      leaf.erase(leaf.begin() + long(best));
    }
  }
  // Primitives left out of every leaf as duplicates are left out of prim_ids too.
  if (ids.size() != b2.prim_ids.size()) b2.prim_ids = LargeArray<uint32_t>(ids.size());
  std::copy(ids.begin(), ids.end(), b2.prim_ids.begin());
}

template <bool P, bool F, bool V>
std::unique_ptr<Scene::Impl> make_scene(std::shared_ptr<CostaData> data, Bvh8&& bvh,
                                        const Fingerprint& expected) {
  auto s = std::make_unique<CostaScene<P, F, V>>();
  s->bvh = std::move(bvh);
  s->expected = expected;
  auto& ctx = s->ctx;
  ctx.view.r = data->store.raw();
  ctx.faces.bits = data->face_map.data();
  ctx.faces.width = data->face_map.width();
  ctx.faces.face_base = data->face_base.data();
  ctx.faces.mesh_count = uint32_t(data->face_base.size() - 1);
  ctx.prim_count = data->store.prim_count();
  s->data = data;
  s->keepalive = data;
  return s;
}

std::unique_ptr<Scene::Impl> make_scene(const CostaFlags& f, std::shared_ptr<CostaData> data,
                                        Bvh8&& b, const Fingerprint& e) {
  switch ((f.P ? 4 : 0) | (f.F ? 2 : 0) | (f.V ? 1 : 0)) {
    case 0:
      return make_scene<false, false, false>(std::move(data), std::move(b), e);
    case 1:
      return make_scene<false, false, true>(std::move(data), std::move(b), e);
    case 2:
      return make_scene<false, true, false>(std::move(data), std::move(b), e);
    case 3:
      return make_scene<false, true, true>(std::move(data), std::move(b), e);
    case 4:
      return make_scene<true, false, false>(std::move(data), std::move(b), e);
    case 5:
      return make_scene<true, false, true>(std::move(data), std::move(b), e);
    case 6:
      return make_scene<true, true, false>(std::move(data), std::move(b), e);
    default:
      return make_scene<true, true, true>(std::move(data), std::move(b), e);
  }
}

// gzip -9 size of the regular arrays (primitive offsets, face entries, float vertices), streamed.
uint64_t gzip9_bytes(const NgonMesh& m) {
  z_stream z{};
  if (deflateInit2(&z, 9, Z_DEFLATED, 15 + 16, 8, Z_DEFAULT_STRATEGY) != Z_OK)
    throw Error("zlib: deflateInit2 failed");
  std::vector<unsigned char> out(1 << 20);
  uint64_t total = 0;
  auto feed = [&](const void* p, uint64_t bytes, bool last) {
    const unsigned char* c = static_cast<const unsigned char*>(p);
    do {
      uInt chunk = uInt(std::min<uint64_t>(bytes, 1u << 30));
      z.next_in = const_cast<unsigned char*>(c);
      z.avail_in = chunk;
      c += chunk;
      bytes -= chunk;
      int flush = last && bytes == 0 ? Z_FINISH : Z_NO_FLUSH;
      int rc;
      do {
        z.next_out = out.data();
        z.avail_out = uInt(out.size());
        rc = deflate(&z, flush);
        total += out.size() - z.avail_out;
      } while (z.avail_out == 0 || (flush == Z_FINISH && rc != Z_STREAM_END));
    } while (bytes > 0);
  };
  feed(m.prim_offsets.data(), m.prim_offsets.size() * 4, false);
  feed(m.faces.data(), m.faces.size() * 4, false);
  feed(m.vertices.data(), m.vertices.size() * 12, true);
  deflateEnd(&z);
  return total;
}

using CostaBlockLeaf = CostaLeaf<false, false, false>;  // block layout is the same for every letter

// Exact duplicates among the primitives of `m` at the positions `p`, which the BVH2 builder
// may drop from stacks of coincident ones (Bvh2BuildConfig::duplicate_key): the same number of
// corners, the same fan/strip flag and the same positions bit for bit in the same order, or for
// a triangle in any of its three rotations (as the triangle formats, TriangleSourceOps).
struct CostaDuplicates {
  const NgonMesh& m;
  const std::vector<Vec3f>& p;

  // Size, flag and the corners' position bits, starting at corner r.
  std::vector<uint32_t> words(uint32_t i, uint32_t r) const {
    const uint32_t o0 = m.prim_offsets[i], n = m.prim_size(i);
    std::vector<uint32_t> w(2 + 3 * size_t(n));
    w[0] = n;
    for (uint32_t j = 0; j < n; ++j) {
      uint32_t v = m.faces[o0 + (j + r) % n];
      if ((j + r) % n == 0 && n >= kFanStripFlagMin) w[1] = v & 1, v >>= 1;
      std::memcpy(&w[2 + 3 * size_t(j)], &p[v], 12);
    }
    return w;
  }
  uint64_t key(uint32_t i) const {
    std::vector<uint32_t> w = words(i, 0);
    if (m.prim_size(i) == 3) w = std::min({w, words(i, 1), words(i, 2)});
    return nh_key(w.data(), 4 * w.size());
  }
  bool same(uint32_t a, uint32_t b) const {
    if (m.prim_size(a) != m.prim_size(b)) return false;
    const std::vector<uint32_t> wa = words(a, 0);
    for (uint32_t r = 0; r < (m.prim_size(b) == 3 ? 3u : 1u); ++r)
      if (words(b, r) == wa) return true;
    return false;
  }
};

// BVH2 over the primitive boxes of `loaded` at the positions `decoded` (as the store decodes them),
// its leaves ordered for P; the source keys for validate() go to `expected` if given. With
// `duplicates`, exact duplicates in stacks of coincident primitives are left out of every leaf
// and of prim_ids (the lowest primitive of each group, that of the lowest input face, stays),
// and the triangles they held are counted there.
Bvh2 build_costa_bvh2(const NgonMesh& loaded, const std::vector<Vec3f>& decoded,
                      const BuildOptions& opt, Fingerprint* expected,
                      uint64_t* duplicates = nullptr) {
  const uint32_t prim_count = uint32_t(loaded.prim_count());
  auto source_key = [&](uint32_t i, Box3f* box) {
    const uint32_t o0 = loaded.prim_offsets[i], o1 = loaded.prim_offsets[i + 1];
    CostaKey key;
    uint32_t flag = 0;
    for (uint32_t j = o0; j < o1; ++j) {
      uint32_t v = loaded.faces[j];
      if (j == o0 && o1 - o0 >= kFanStripFlagMin) flag = v & 1, v >>= 1;
      if (box) box->extend(decoded[v]);
      key.add(decoded[v]);
    }
    const uint32_t g = loaded.prim_face[i], mesh = mesh_of(loaded.face_base, g);
    return key.finish(o1 - o0, flag, mesh, g - loaded.face_base[mesh]);
  };
  std::vector<PrimRef> refs(prim_count);
  for (uint32_t i = 0; i < prim_count; ++i) {
    Box3f box;
    const uint64_t key = source_key(i, &box);
    if (expected) expected->add(key);
    refs[i] = {box, i};
  }
  Bvh2BuildConfig cfg;
  cfg.bins = opt.sah_bins;
  cfg.max_leaf_size = std::max<uint32_t>(
      1, std::min<uint32_t>(opt.max_leaf_size, CostaBlockLeaf::kBlockPrims * kMaxLeafBlocks));
  cfg.block_prims = CostaBlockLeaf::kBlockPrims;
  cfg.threads = opt.threads;
  std::unique_ptr<PhaseProgress> progress;
  if (opt.progress) {
    report_progress(opt.progress, "prepare", 1, 1);
    progress = std::make_unique<PhaseProgress>(opt.progress, "bvh2", 2 * uint64_t(prim_count));
  }
  cfg.progress = progress.get();
  const CostaDuplicates dup{loaded, decoded};
  if (duplicates) {
    cfg.duplicate_key = [&](uint32_t i) { return dup.key(i); };
    cfg.same_primitive = [&](uint32_t a, uint32_t b) { return dup.same(a, b); };
  }
  Bvh2 b2 = build_bvh2(refs, cfg);
  if (duplicates) {
    *duplicates = 0;
    for (uint32_t i : b2.dropped) {
      *duplicates += loaded.prim_size(i) - 2;
      if (expected) expected->remove(source_key(i, nullptr));
    }
  }
  if (prim_count) order_leaves_for_prediction(b2, loaded);
  if (progress) progress->finish();
  return b2;
}

// The mesh as the store keeps it: primitives in the leaf order of `b2`, vertices renumbered so
// that PACKFACES needs no extra bit for the fan/strip flag when the flagged vertices fit.
NgonMesh store_order(const NgonMesh& loaded, const Bvh2& b2) {
  NgonMesh ordered = reorder(loaded, b2.prim_ids);
  renumber_vertices(ordered);
  return ordered;
}

}  // namespace

std::unique_ptr<Scene::Impl> empty_costa_scene(const BuildOptions& opt) {
  const CostaFlags f = CostaFlags::parse(opt.costa);
  switch ((f.P ? 4 : 0) | (f.F ? 2 : 0) | (f.V ? 1 : 0)) {
    case 0:
      return std::make_unique<CostaScene<false, false, false>>();
    case 1:
      return std::make_unique<CostaScene<false, false, true>>();
    case 2:
      return std::make_unique<CostaScene<false, true, false>>();
    case 3:
      return std::make_unique<CostaScene<false, true, true>>();
    case 4:
      return std::make_unique<CostaScene<true, false, false>>();
    case 5:
      return std::make_unique<CostaScene<true, false, true>>();
    case 6:
      return std::make_unique<CostaScene<true, true, false>>();
    default:
      return std::make_unique<CostaScene<true, true, true>>();
  }
}

std::unique_ptr<Scene::Impl> build_costa_scene(const MeshList& meshes, const BuildOptions& opt) {
  const CostaFlags flags = CostaFlags::parse(opt.costa);
  // V: one quantization box for every scene built with the same lattice_box (chunks).
  const Box3f lattice_box = flags.V ? lattice_box_of(meshes, opt) : Box3f();
  NgonMesh loaded = load_ngon_mesh(meshes);  // section 3.1
  if (flags.T) loaded = triangulate_ngon_mesh(loaded);
  const uint32_t prim_count = uint32_t(loaded.prim_count());

  // The BVH, the leaves and the validation keys all see the vertices as the store decodes them.
  std::vector<Vec3f> decoded = loaded.vertices;
  double max_error = 0;  // Scene::error_bound(): the largest |decoded - input|
  if (flags.V) {
    VertexQuantizer q = make_vertex_quantizer(loaded.vertices, lattice_box);
    for (Vec3f& p : decoded) {
      const Vec3f in = p;
      uint16_t c[3] = {q.encode(p.x, 0), q.encode(p.y, 1), q.encode(p.z, 2)};
      p = q.decode(c);
      if (!is_finite(in)) continue;
      double e2 = 0;
      for (int a = 0; a < 3; ++a) e2 += (double(p[a]) - in[a]) * (double(p[a]) - in[a]);
      max_error = std::max(max_error, std::sqrt(e2));
    }
  }

  Fingerprint expected;
  uint64_t duplicates = 0;
  Bvh2 b2 = build_costa_bvh2(loaded, decoded, opt, &expected, &duplicates);
  decoded = {};
  const uint32_t kept = uint32_t(b2.prim_ids.size());  // the primitives in leaves (the store's)

  // "collapse": the store in leaf order, then the BVH8.
  std::unique_ptr<PhaseProgress> progress;
  if (opt.progress)
    progress = std::make_unique<PhaseProgress>(opt.progress, "collapse", 2 * uint64_t(prim_count));
  // Reorder the primitives in leaf order: a leaf block is then a range of the store.
  std::vector<uint32_t> pos(prim_count);
  for (uint32_t k = 0; k < kept; ++k) pos[b2.prim_ids[k]] = k;
  auto data = std::make_shared<CostaData>();
  NgonMesh stats_src;  // keeps the loading statistics after `loaded` is released
  {
    NgonMesh ordered = store_order(loaded, b2);
    stats_src.input_faces = loaded.input_faces;
    stats_src.skipped_faces = loaded.skipped_faces;
    stats_src.input_triangles = loaded.input_triangles;
    stats_src.triangles = loaded.triangles, stats_src.quads = loaded.quads;
    stats_src.fans = loaded.fans, stats_src.strips = loaded.strips;
    stats_src.tess = loaded.tess;
    loaded = {};
    data->store = QuantizedMesh(ordered, flags.P, flags.F, flags.V, lattice_box);  // section 3.2
    uint32_t max_face = 0;
    for (uint32_t g : ordered.prim_face) max_face = std::max(max_face, g);
    data->face_map = BitArray(kept, bits_for(max_face));
    for (uint32_t i = 0; i < kept; ++i) data->face_map.set(i, ordered.prim_face[i]);
    data->face_base = ordered.face_base;
    if (data->face_base.empty()) data->face_base.push_back(0);
  }

  LeafEncoder enc;
  enc.block_prims = CostaBlockLeaf::kBlockPrims;
  enc.block_bytes = CostaBlockLeaf::kBlockBytes;
  enc.leaf_align = leaf_align<CostaBlockLeaf>();
  enc.encode = [&](const uint32_t* prims, uint32_t n, uint8_t* out) {
    CostaBlock b{pos[prims[0]], n};
    for (uint32_t k = 1; k < n; ++k)
      if (pos[prims[k]] != b.first + k)
        throw std::logic_error("costa: a leaf block is not a range of the leaf order");
    std::memcpy(out, &b, sizeof(b));
  };
  const NodeKind kind = node_kind(opt.nodes);
  Bvh8 bvh = collapse_bvh8(b2, kind, enc, collapse_rule(opt, kind), progress.get());
  if (progress) progress->finish();

  const uint64_t node_bytes = bvh.node_bytes, multileaf_bytes = bvh.multileaf_bytes;
  const uint64_t leaf_data_bytes = bvh.leaf_data_bytes;
  const uint64_t kept_bvh = bvh.kept_bvh_bytes(), kept_leaves = bvh.kept_leaf_bytes();
  const Bvh8Stats b8 = bvh.stats;
  const Box3f bounds = bvh.bounds;
  std::unique_ptr<Scene::Impl> s = make_scene(flags, data, std::move(bvh), expected);
  s->bounds = bounds;
  s->error_bound = max_error;
  const QuantizedMesh& q = data->store;
  MemoryStats& mem = s->mem;  // everything the scene keeps
  mem.bvh_bytes = kept_bvh;
  mem.geometry_bytes = q.bytes() + kept_leaves;
  mem.other_bytes = data->face_map.bytes() + data->face_base.size() * sizeof(uint32_t);
  mem.triangles = stats_src.input_triangles;
  SceneStatsAndDetails& st = s->stats;
  st.input_faces = stats_src.input_faces;
  st.triangles = stats_src.input_triangles;
  st.skipped_faces = stats_src.skipped_faces;
  st.primitives = kept;
  auto& d = st.details;
  d.emplace_back("duplicate_triangles", double(duplicates));
  d.emplace_back("bvh2_depth", double(b2.depth));
  d.emplace_back("bvh8_depth", double(b8.depth));
  d.emplace_back("node8_count", double(b8.node8));
  d.emplace_back("qnode8_count", double(b8.qnode8));
  d.emplace_back("multileaf_count", double(b8.multileaf));
  d.emplace_back("leaf_count", double(b8.leaves));
  d.emplace_back("leaves_in_multileaf", double(b8.leaves_in_multileaf));
  d.emplace_back("leaf_blocks", double(b8.leaf_blocks));
  d.emplace_back("leaf_fill", b8.leaf_fill);
  d.emplace_back("sah_cost", b8.sah_cost);
  d.emplace_back("node_bytes", double(node_bytes));
  d.emplace_back("multileaf_bytes", double(multileaf_bytes));
  d.emplace_back("leaf_data_bytes", double(leaf_data_bytes));
  d.emplace_back("costa_triangles", double(stats_src.triangles));
  d.emplace_back("costa_quads", double(stats_src.quads));
  d.emplace_back("costa_fans", double(stats_src.fans));
  d.emplace_back("costa_strips", double(stats_src.strips));
  d.emplace_back("costa_tess_polygons", double(stats_src.tess.polygons));
  d.emplace_back("costa_tess_fallbacks", double(stats_src.tess.fallbacks()));
  d.emplace_back("store_prim_bytes", double(q.prim_bytes()));
  d.emplace_back("store_face_bytes", double(q.face_bytes()));
  d.emplace_back("store_vertex_bytes", double(q.vertex_bytes()));
  d.emplace_back("store_bytes", double(q.bytes()));
  d.emplace_back("prim_residual_bits", double(q.prim_residual_bits()));
  d.emplace_back("face_bits", double(q.face_bits()));
  d.emplace_back("face_map_bytes", double(data->face_map.bytes()));
  return s;
}

// ---- sizes (Tables 1 and 3) ---------------------------------------------------------------------

std::vector<std::string> costa_combinations() {
  std::vector<std::string> v;
  for (const char* t : {"", "T"})
    for (const char* c : {"", "V", "F", "FV", "P", "PV", "PF", "PFV"})
      v.push_back(std::string(t) + c);
  return v;
}

CostaSizes costa_sizes(const std::vector<const PolyMesh*>& meshes) {
  for (const PolyMesh* m : meshes) {
    if (!m) throw Error("costa_sizes: null mesh");
    check_mesh(*m);
  }
  CostaSizes s;
  const NgonMesh m = load_ngon_mesh(meshes);
  const NgonMesh t = triangulate_ngon_mesh(m);
  s.vertices = m.vertices.size();
  s.input_faces = m.input_faces;
  s.skipped_faces = m.skipped_faces;
  s.primitives = m.prim_count();
  s.triangles = m.triangles, s.quads = m.quads, s.fans = m.fans, s.strips = m.strips;
  s.triangulated_primitives = t.prim_count();
  s.tess_polygons = m.tess.polygons;
  s.tess_glu = m.tess.glu;
  s.tess_fallbacks = m.tess.fallbacks();
  // The store as a scene keeps it (leaf order of the default build, vertices renumbered); the
  // BVH is built over the unquantized positions here (a V scene builds over the quantized ones,
  // which can move a few primitives between leaves).
  const BuildOptions opt;
  const NgonMesh ms = store_order(m, build_costa_bvh2(m, m.vertices, opt, nullptr));
  const NgonMesh ts = store_order(t, build_costa_bvh2(t, t.vertices, opt, nullptr));
  s.gzip_bytes = gzip9_bytes(ms);
  s.gzip_triangulated_bytes = gzip9_bytes(ts);
  for (const std::string& c : costa_combinations()) {
    CostaFlags f = CostaFlags::parse(c);
    QuantizedMesh q(f.T ? ts : ms, f.P, f.F, f.V);
    s.combos[c] = q.bytes();
    s.input_order_combos[c] = QuantizedMesh(f.T ? t : m, f.P, f.F, f.V).bytes();
    if (c == "PF") s.prim_residual_bits = q.prim_residual_bits(), s.face_bits = q.face_bits();
    if (c == "TPF")
      s.prim_residual_bits_triangulated = q.prim_residual_bits(),
      s.face_bits_triangulated = q.face_bits();
  }
  s.regular_bytes = s.combos[""];
  s.triangulated_bytes = s.combos["T"];
  return s;
}

CostaTriangles costa_triangles(const std::vector<const PolyMesh*>& meshes,
                               const BuildOptions& opt) {
  if (opt.leaf != Leaf::Costa)
    throw Error("costa_triangles: " + opt.config_name() + " is not a costa configuration");
  opt.check();
  for (const PolyMesh* m : meshes) {
    if (!m) throw Error("costa_triangles: null mesh");
    check_mesh(*m);
  }
  const CostaFlags f = CostaFlags::parse(opt.costa);
  const Box3f lattice_box = f.V ? lattice_box_of(meshes, opt) : Box3f();
  NgonMesh m = load_ngon_mesh(meshes);
  if (f.T) m = triangulate_ngon_mesh(m);
  const QuantizedMesh q(m, f.P, f.F, f.V, lattice_box);
  return store_triangles(q, uint32_t(q.prim_count()),
                         [&](uint32_t i, uint32_t& geom, uint32_t& face) {
                           const uint32_t g = m.prim_face[i];
                           geom = mesh_of(m.face_base, g);
                           face = g - m.face_base[geom];
                         });
}

CostaSizes costa_sizes(const PolyMesh& mesh) {
  return costa_sizes(std::vector<const PolyMesh*>{&mesh});
}

}  // namespace slim
