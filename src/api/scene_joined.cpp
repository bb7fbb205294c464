// Joined scenes (api/scene_joined.h) and Scene::build_chunked.
//
// Layout: the chunk scenes (each a Scene::Impl of the configuration's format, built from its chunk
// mesh), a BVH2 over their boxes (one chunk per leaf, from the binned SAH builder of bvh/build.h),
// a record per chunk (its figures and its id runs) and the id runs: chunk-local face f of a run
// starting at local face l is input face global_first + (f - l). A chunk of a grid-like input is
// made of a few long runs (rows of a tile), so the map costs far less than a face id per face.
//
// Tracing: the top-level BVH2 is traversed nearest box first; each chunk reached is traced with
// the same TravRay (its tfar lowered by the hits so far, its box-test constants derived from the
// whole scene's box, conservative for every chunk), and a hit is mapped back to the input face.
//
// Scene files: the joined scene's own sections ("join.*") and every chunk's sections under the
// prefix "c<i>."; the header counts the chunks (FileHeader::chunks in api/scene_file.cpp).
#include "api/scene_joined.h"

#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <string>
#include <vector>

#include "api/registry.h"
#include "api/scene_file.h"
#include "bvh/build.h"
#include "core/progress.h"
#include "io/face_stream.h"
#include "mesh/chunk_sources.h"
#include "mesh/chunks.h"
#include "slimrt/error.h"

#include <tbb/task_arena.h>

namespace slim {
namespace {

// Chunk-local faces local_first.. (up to the next run of the chunk) are input faces global_first..
struct IdRun {
  uint32_t local_first;
  uint32_t reserved;
  uint64_t global_first;
};
static_assert(sizeof(IdRun) == 16);

// A chunk's figures (its scene's, restored at open) and its id runs.
struct ChunkRecord {
  SceneFigures figures;
  uint64_t first_run, run_count;
};
static_assert(sizeof(ChunkRecord) == 120);

// The top-level BVH2's depth limit (the traversal's stack holds one entry per level plus one).
constexpr int kMaxDepth = 64;

// Slab test of a box with the ray's conservative constants (core/ray.h: t = bound * rdir - c, as
// the BVH8 node tests compute it, fused). Returns the entry distance through `t`.
SLIM_INLINE bool box_hit(const Box3f& b, const TravRay& r, float& t) {
  float tn = r.tnear, tf = r.tfar;
  for (int a = 0; a < 3; ++a) {
    const bool neg = (r.near_plane[a] & 1) != 0;
    const float nb = neg ? b.hi[a] : b.lo[a], fb = neg ? b.lo[a] : b.hi[a];
    tn = std::max(tn, std::fma(nb, r.rdir[a], -r.c_near[a]));
    tf = std::min(tf, std::fma(fb, r.rdir[a], -r.c_far[a]));
  }
  t = tn;
  return tn <= tf;
}

// Forwards a chunk scene's sections under a prefix.
class PrefixVisitor final : public SectionVisitor {
 public:
  PrefixVisitor(SectionVisitor& inner, std::string prefix)
      : inner_(inner), prefix_(std::move(prefix)) {
    saving_ = inner.saving();
  }
  void raw(const std::string& name, const void*& data, uint64_t& count, uint32_t elem) override {
    inner_.raw(prefix_ + name, data, count, elem);
  }
  void record(const std::string& name, void* p, uint32_t size) override {
    inner_.record(prefix_ + name, p, size);
  }

 private:
  SectionVisitor& inner_;
  std::string prefix_;
};

std::string chunk_prefix(size_t i) { return "c" + std::to_string(i) + "."; }

class JoinedScene final : public Scene::Impl {
 public:
  std::vector<std::unique_ptr<Scene::Impl>> chunks;
  // Built: the vectors own the arrays; opened: the pointers view the mapping.
  std::vector<Bvh2Node> node_store;
  std::vector<uint32_t> order_store;
  std::vector<IdRun> run_store;
  std::vector<ChunkRecord> record_store;
  const Bvh2Node* nodes = nullptr;
  const uint32_t* order = nullptr;  // chunk index of each top-level leaf slot
  const IdRun* runs = nullptr;
  const ChunkRecord* records = nullptr;
  uint64_t node_count = 0, order_count = 0, run_count = 0, record_count = 0;
  uint32_t expected_chunks = 0;  // opening: the header's count

  void point_at_stores() {
    nodes = node_store.data(), node_count = node_store.size();
    order = order_store.data(), order_count = order_store.size();
    runs = run_store.data(), run_count = run_store.size();
    records = record_store.data(), record_count = record_store.size();
  }

  std::optional<uint32_t> joined_chunks() const override { return uint32_t(chunks.size()); }

  uint32_t global_face(uint32_t chunk, uint32_t local) const {
    const ChunkRecord& rec = records[chunk];
    const IdRun* first = runs + rec.first_run;
    const IdRun* last = first + rec.run_count;
    const IdRun* r =
        std::upper_bound(first, last, local,
                         [](uint32_t f, const IdRun& run) { return f < run.local_first; }) -
        1;
    return uint32_t(r->global_first + (local - r->local_first));
  }

  // Visits the chunks whose boxes the ray enters, nearest first, skipping those beyond ray.tfar;
  // stops when fn returns true.
  template <class Fn>
  bool for_each_chunk(TravRay& ray, TraversalCounters* c, Fn&& fn) const {
    if (node_count == 0) return false;
    struct Entry {
      uint32_t node;
      float t;
    };
    Entry stack[kMaxDepth + 2];
    int sp = 0;
    float t0;
    if (c) c->box_tests++;
    if (!box_hit(nodes[0].box, ray, t0)) return false;
    stack[sp++] = {0, t0};
    while (sp > 0) {
      const Entry e = stack[--sp];
      if (e.t > ray.tfar) continue;
      const Bvh2Node& n = nodes[e.node];
      if (c) c->node_visits++;
      if (n.is_leaf()) {
        for (uint32_t k = 0; k < n.count; ++k)
          if (fn(order[n.first + k])) return true;
        continue;
      }
      float ta, tb;
      const bool ha = box_hit(nodes[n.first].box, ray, ta);
      const bool hb = box_hit(nodes[n.first + 1].box, ray, tb);
      if (c) c->box_tests += 2;
      if (ha && hb) {
        if (ta <= tb) {
          stack[sp++] = {n.first + 1, tb};
          stack[sp++] = {n.first, ta};
        } else {
          stack[sp++] = {n.first, ta};
          stack[sp++] = {n.first + 1, tb};
        }
      } else if (ha) {
        stack[sp++] = {n.first, ta};
      } else if (hb) {
        stack[sp++] = {n.first + 1, tb};
      }
    }
    return false;
  }

  template <bool kCounted>
  void intersect_impl(TravRay& ray, HitRecord& hit, TraversalCounters* c) const {
    for_each_chunk(ray, c, [&](uint32_t ci) {
      HitRecord h;
      if constexpr (kCounted)
        chunks[ci]->intersect_counted(ray, h, *c);
      else
        chunks[ci]->intersect(ray, h);
      if (h.valid()) {  // closer than every hit so far: the chunk traced up to ray.tfar
        h.primID = global_face(ci, h.primID);
        h.geomID = 0;
        hit = h;
      }
      return false;
    });
  }
  void intersect(TravRay& ray, HitRecord& hit) const override {
    intersect_impl<false>(ray, hit, nullptr);
  }
  void intersect_counted(TravRay& ray, HitRecord& hit, TraversalCounters& c) const override {
    intersect_impl<true>(ray, hit, &c);
  }
  bool occluded(TravRay& ray) const override {
    return for_each_chunk(ray, nullptr, [&](uint32_t ci) { return chunks[ci]->occluded(ray); });
  }

  // The top level's own invariants (a tree over every chunk exactly once, each chunk's box inside
  // its leaf's, child boxes inside their parents', depth within the stack). Returns what is wrong
  // and where (the section and the element index), or an empty string.
  std::string check_top(std::string* section, uint64_t* index) const {
    auto fault = [&](const char* s, uint64_t i, const std::string& what) {
      *section = s;
      *index = i;
      return what;
    };
    const size_t n = chunks.size();
    if (record_count != n) return fault("join.chunks", 0, "record count differs from the chunks");
    if (order_count != n) return fault("join.order", 0, "leaf slots differ from the chunk count");
    for (uint64_t i = 0; i < record_count; ++i) {
      const ChunkRecord& r = records[i];
      if (r.first_run > run_count || r.run_count > run_count - r.first_run || r.run_count == 0)
        return fault("join.chunks", i, "id runs outside the run table");
      const IdRun* first = runs + r.first_run;
      if (first[0].local_first != 0) return fault("join.runs", r.first_run, "first run not at 0");
      for (uint64_t k = 1; k < r.run_count; ++k)
        if (first[k].local_first <= first[k - 1].local_first)
          return fault("join.runs", r.first_run + k, "runs not in increasing order");
      const uint64_t last_local = r.figures.input_faces ? r.figures.input_faces - 1 : 0;
      for (uint64_t k = 0; k < r.run_count; ++k) {
        const uint64_t end_local = k + 1 < r.run_count ? first[k + 1].local_first - 1 : last_local;
        if (first[k].global_first > UINT32_MAX ||
            end_local - first[k].local_first > UINT32_MAX - first[k].global_first)
          return fault("join.runs", r.first_run + k, "face ids beyond 2^32 - 1");
      }
    }
    if (node_count == 0) {
      return n == 0 ? std::string() : fault("join.nodes", 0, "no top-level node over the chunks");
    }
    std::vector<uint8_t> seen(n, 0);
    struct Item {
      uint64_t node;
      int depth;
    };
    std::vector<Item> todo{{0, 0}};
    uint64_t visited = 0;
    while (!todo.empty()) {
      const Item it = todo.back();
      todo.pop_back();
      if (++visited > node_count) return fault("join.nodes", it.node, "node visited twice");
      if (it.depth > kMaxDepth) return fault("join.nodes", it.node, "top-level BVH too deep");
      const Bvh2Node& nd = nodes[it.node];
      if (nd.is_leaf()) {
        if (nd.first > order_count || nd.count > order_count - nd.first)
          return fault("join.nodes", it.node, "leaf outside the leaf slots");
        for (uint32_t k = 0; k < nd.count; ++k) {
          const uint32_t ci = order[nd.first + k];
          if (ci >= n || seen[ci]++) return fault("join.order", nd.first + k, "bad chunk index");
          if (!nd.box.contains(chunks[ci]->bounds))
            return fault("join.nodes", it.node, "chunk box outside its leaf's");
        }
      } else {
        if (nd.first == 0 || nd.first >= node_count - 1)
          return fault("join.nodes", it.node, "child index out of range");
        for (uint32_t k = 0; k < 2; ++k) {
          if (!nd.box.contains(nodes[nd.first + k].box))
            return fault("join.nodes", it.node, "child box outside its parent's");
          todo.push_back({nd.first + k, it.depth + 1});
        }
      }
    }
    for (size_t i = 0; i < n; ++i)
      if (!seen[i] && !chunks[i]->bounds.empty())
        return fault("join.order", 0, "chunk " + std::to_string(i) + " in no leaf");
    return {};
  }

  bool validate(std::string* why) const override {
    std::string section;
    uint64_t index = 0;
    const std::string top = check_top(&section, &index);
    if (!top.empty()) {
      if (why) *why = section + "[" + std::to_string(index) + "]: " + top;
      return false;
    }
    for (size_t i = 0; i < chunks.size(); ++i) {
      std::string w;
      if (!chunks[i]->validate(&w)) {
        if (why) *why = "chunk " + std::to_string(i) + ": " + w;
        return false;
      }
    }
    return true;
  }

  std::optional<DecodedTriangles> decoded_triangles() const override {
    DecodedTriangles all;
    for (size_t i = 0; i < chunks.size(); ++i) {
      std::optional<DecodedTriangles> t = chunks[i]->decoded_triangles();
      if (!t) return std::nullopt;
      all.vertices.insert(all.vertices.end(), t->vertices.begin(), t->vertices.end());
      for (size_t k = 0; k < t->size(); ++k) {
        all.geom.push_back(0);
        all.face.push_back(global_face(uint32_t(i), t->face[k]));
      }
    }
    return all;
  }

  void sections(SectionVisitor& v) override {
    v.array("join.chunks", records, record_count);
    if (!v.saving()) {
      if (record_count != expected_chunks)
        throw SectionFault{"join.chunks", 0,
                           std::to_string(record_count) + " chunk records, the header says " +
                               std::to_string(expected_chunks)};
      chunks.clear();
      for (uint64_t i = 0; i < record_count; ++i) {
        const ChunkRecord& r = records[i];
        std::unique_ptr<Scene::Impl> c = format_of(opt.leaf).empty(opt);
        c->opt = opt;
        restore_figures(r.figures, *c);
        chunks.push_back(std::move(c));
      }
    }
    v.array("join.nodes", nodes, node_count);
    v.array("join.order", order, order_count);
    v.array("join.runs", runs, run_count);
    for (size_t i = 0; i < chunks.size(); ++i) {
      PrefixVisitor pv(v, chunk_prefix(i));
      chunks[i]->sections(pv);
    }
  }

  void check_opened(bool deep) const override {
    std::string section;
    uint64_t index = 0;
    const std::string top = check_top(&section, &index);
    if (!top.empty()) {
      const uint64_t elem = section == "join.nodes"   ? sizeof(Bvh2Node)
                            : section == "join.order" ? sizeof(uint32_t)
                            : section == "join.runs"  ? sizeof(IdRun)
                                                      : sizeof(ChunkRecord);
      throw SectionFault{section, index * elem, top};
    }
    for (size_t i = 0; i < chunks.size(); ++i) {
      try {
        chunks[i]->check_opened(deep);
      } catch (SectionFault& f) {
        f.section = chunk_prefix(i) + f.section;
        throw;
      }
    }
  }
};

// The id runs of one chunk's face ids.
void append_runs(const std::vector<uint64_t>& ids, std::vector<IdRun>& out) {
  for (size_t f = 0; f < ids.size(); ++f)
    if (f == 0 || ids[f] != ids[f - 1] + 1) out.push_back({uint32_t(f), 0, ids[f]});
  if (ids.empty()) out.push_back({0, 0, 0});
}

ChunkRecord record_of(const Scene::Impl& c, uint64_t first_run, uint64_t run_count) {
  ChunkRecord r;
  std::memset(&r, 0, sizeof r);
  r.figures = figures_of(c);
  r.first_run = first_run;
  r.run_count = run_count;
  return r;
}

// The system's temporary directory ($TMPDIR where set, else /tmp), read through the standard
// library: the library itself reads no environment variable.
std::string default_spill_dir() {
  std::error_code ec;
  const std::filesystem::path p = std::filesystem::temp_directory_path(ec);
  return ec ? std::string("/tmp") : p.string();
}

}  // namespace

uint64_t default_memory_budget() {
  const long pages = sysconf(_SC_PHYS_PAGES), page = sysconf(_SC_PAGE_SIZE);
  if (pages <= 0 || page <= 0) return uint64_t(1) << 30;
  return uint64_t(pages) * uint64_t(page) / 4;
}

std::unique_ptr<Scene::Impl> empty_joined_scene(const BuildOptions& opt, uint32_t chunks) {
  auto s = std::make_unique<JoinedScene>();
  s->opt = opt;
  s->expected_chunks = chunks;
  return s;
}

std::unique_ptr<Scene::Impl> build_joined_scene(const detail::ChunkSource& src,
                                                const BuildOptions& opt) {
  if (src.faces() > uint64_t(UINT32_MAX))
    throw Error("chunked build: " + std::to_string(src.faces()) +
                " faces; a scene's face ids (Hit::primID) reach 2^32 - 1");
  auto s = std::make_unique<JoinedScene>();
  BuildOptions copt = opt;
  copt.lattice_box = src.bounds();
  copt.progress = nullptr;
  std::unique_ptr<PhaseProgress> progress;
  if (opt.progress)
    progress = std::make_unique<PhaseProgress>(opt.progress, "chunks", src.triangles());
  std::vector<PrimRef> refs;
  double duplicates = 0;  // the chunks' "duplicate_triangles" details, added up
  for (size_t i = 0; i < src.size(); ++i) {
    std::unique_ptr<Scene::Impl> c;
    {
      detail::Chunk chunk = src.load(i);
      if (chunk.face_ids.size() != chunk.mesh.face_count())
        throw Error("chunked build: chunk " + std::to_string(i) + " has " +
                    std::to_string(chunk.face_ids.size()) + " face ids for " +
                    std::to_string(chunk.mesh.face_count()) + " faces");
      const uint64_t first_run = s->run_store.size();
      append_runs(chunk.face_ids, s->run_store);
      c = build_scene_impl({&chunk.mesh}, copt);
      s->record_store.push_back(record_of(*c, first_run, s->run_store.size() - first_run));
    }
    if (!c->bounds.empty()) refs.push_back({c->bounds, uint32_t(i)});
    s->error_bound = std::max(s->error_bound, c->error_bound);
    s->bounds.extend(c->bounds);
    s->stats.input_faces += c->stats.input_faces;
    s->stats.triangles += c->stats.triangles;
    s->stats.skipped_faces += c->stats.skipped_faces;
    s->stats.primitives += c->stats.primitives;
    for (const auto& [k, v] : c->stats.details)
      if (k == "duplicate_triangles") duplicates += v;
    s->mem.geometry_bytes += c->mem.geometry_bytes;
    s->mem.bvh_bytes += c->mem.bvh_bytes;
    s->mem.other_bytes += c->mem.other_bytes;
    s->mem.triangles += c->mem.triangles;
    if (progress) progress->add(src.info(i).triangles);
    s->chunks.push_back(std::move(c));
  }
  if (progress) progress->finish();
  Bvh2BuildConfig cfg;
  cfg.max_leaf_size = 1;
  cfg.block_prims = 1;
  cfg.max_depth = kMaxDepth;
  cfg.threads = opt.threads;
  Bvh2 top = build_bvh2(refs, cfg);
  s->node_store.assign(top.nodes.begin(), top.nodes.end());
  s->order_store.assign(top.prim_ids.begin(), top.prim_ids.end());
  for (uint32_t& k : s->order_store) k = refs[k].id;  // leaf slots name chunks
  s->point_at_stores();
  s->mem.bvh_bytes += s->node_store.size() * sizeof(Bvh2Node);
  s->mem.other_bytes += s->order_store.size() * sizeof(uint32_t) +
                        s->run_store.size() * sizeof(IdRun) +
                        s->record_store.size() * sizeof(ChunkRecord);
  s->stats.details.emplace_back("chunks", double(s->chunks.size()));
  s->stats.details.emplace_back("id_runs", double(s->run_store.size()));
  if (duplicates > 0) s->stats.details.emplace_back("duplicate_triangles", duplicates);
  s->opt = opt;
  s->opt.progress = nullptr;
  return s;
}

Scene Scene::build_chunked(const std::string& input, const BuildOptions& opt,
                           const ChunkedBuildOptions& chunking) {
  check_cpu_isa();
  opt.check();
  const auto t0 = std::chrono::steady_clock::now();
  const uint64_t budget = chunking.memory_budget ? chunking.memory_budget : default_memory_budget();
  detail::ChunkOptions co;
  co.max_triangles =
      chunking.max_chunk_triangles
          ? chunking.max_chunk_triangles
          : std::max<uint64_t>(uint64_t(1) << 16, budget / kChunkBuildBytesPerTriangle);
  co.memory_budget = budget;
  co.spill_dir = chunking.spill_dir.empty() ? default_spill_dir() : chunking.spill_dir;
  // Procedural scenes and subdivided meshes are generated chunk by chunk; files are streamed and
  // spilled (mesh/chunk_sources.h, mesh/chunks.h).
  std::unique_ptr<detail::ChunkSource> src = detail::open_generated_chunks(input, co.max_triangles);
  if (!src) {
    std::unique_ptr<detail::FaceStream> stream = detail::open_face_stream(input);
    src = std::make_unique<detail::ChunkSet>(*stream, co);
  }
  std::unique_ptr<Impl> impl;
  if (opt.threads > 0) {
    tbb::task_arena arena(opt.threads);
    arena.execute([&] { impl = build_joined_scene(*src, opt); });
  } else {
    impl = build_joined_scene(*src, opt);
  }
  impl->ray_setup = RaySetupBounds(impl->bounds);
  impl->stats.build_seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  Scene s;
  s.impl_ = std::move(impl);
  return s;
}

}  // namespace slim
