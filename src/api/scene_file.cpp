// Scene files: Scene::save and Scene::open (README.md "Scene files", api/scene_file.h).
//
// Layout (native byte order, recorded and checked; all offsets in bytes from the file start):
//   FileHeader        512 B   magic, version, byte-order mark, sizes, the writer's instruction set,
//                             the configuration and its BuildOptions, the scene's figures
//   SectionEntry[n]    80 B each: name, offset, size, element size, XXH3-64 of the bytes
//   details           the stat_details() pairs (u16 name length, name, f64 value)
//   (padding to 64)   header_bytes = the end of all of the above, 64-byte aligned
//   sections          each 64-byte aligned, in table order, zero padding between them
// The header checksum (XXH3-64 of [0, header_bytes) with its own field zeroed) is verified on
// every open; the section checksums unless OpenOptions::verify_checksums is off.
#include <fcntl.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <unistd.h>
#include <xxhash.h>

#include <algorithm>
#include <cerrno>
#include <cstddef>
#include <cstdio>
#include <cstring>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include "api/registry.h"
#include "api/scene_file.h"
#include "api/scene_impl.h"
#include "api/scene_joined.h"
#include "core/ray.h"
#include "slimrt/output.h"
#include "slimrt/scene.h"

namespace slim {

namespace {

constexpr char kMagic[8] = {'S', 'L', 'I', 'M', 'S', 'C', 'N', '\n'};
// Version 6: the clusters' primID run starts as Elias-Fano sequences with repeat bits, their strip
// steps with a 1-bit edge after a step, their child table as residuals of linear predictions
// (prim/cluster.h), clusters of up to 64 triangles. Version 7: the cluster header of 15 bytes (no
// triangle count, pb, gb, bb and hb packed in 3 bytes), the lossy anchors at the lattice's
// per-axis widths (ClusterLattice::anchor_bits, in cluster.lattice). Version 8: a lossless
// cluster's stream starts with its box start (3 floats), the anchors derived from them. Version 9:
// lossy clusters may store their vertices in per-child ranges from the multi-leaf boxes. Version
// 10: the clusters' inner nodes are CQNode8 (32-bit child refs) where they fit. Version 11: the
// cluster lattice has a step per axis (ClusterLattice::step[3]). Version 12: the lossy multi-leaf
// boxes take 6-bit planes (39 bytes), their low bits in the cluster where it has the fine-planes
// bit, and the clusters' primIDs may take step bits (the top bit of nruns). Version 13: a lossy
// cluster's per-child vertex ranges hold each vertex as one mixed-radix number. Version 14: the
// cluster lattice's steps may be (8 + m) 2^e / 8 (ClusterLattice::step), the box extents their
// products with the scale (cluster::box_extent). Version 15: a cluster's primIDs may take steps of
// up to 3 (three flag planes). Any change of a section's layout (a node, block or context struct),
// of what its bytes decode to, or of the header needs a new version: the sections are the
// in-memory structs byte for byte.
constexpr uint32_t kVersion = 15;
constexpr uint32_t kByteOrder = 0x01020304;
constexpr uint64_t kAlign = 64;
// Bounds the table before it is read (the header size check then bounds it by the file size): a
// joined scene of 100,000 chunks of a dozen sections fits.
constexpr uint32_t kMaxSections = uint32_t(1) << 21;
constexpr uint32_t kMaxDetails = 4096;
// Sections up to this size are written first, right after the section table: what Scene::open
// reads (records, BVH metadata, a joined scene's top level and chunk records) then lies in one
// contiguous stretch of the file, so a cold open reads it in a few sequential requests instead of
// one seek per chunk.
constexpr uint64_t kSmallSection = 64 * 1024;

struct OptionsRecord {
  uint8_t nodes, leaf, grid_encoding, pairing, collapse, grid_leftovers;
  uint8_t coordinate_keys, weld, augment, cluster_redivide, reserved[6];
  int32_t grid_parts, sah_bins, max_leaf_size, threads;
  double prescan_threshold, cluster_error;
  char costa[16];
  float lattice_lo[3], lattice_hi[3];  // BuildOptions::lattice_box (the empty default: +inf, -inf)
  uint8_t reserved2[8];
};
static_assert(sizeof(OptionsRecord) == 96);

struct FileHeader {
  char magic[8];
  uint32_t version;
  uint32_t byte_order;
  uint64_t file_bytes;    // the whole file
  uint64_t header_bytes;  // header, section table and details, 64-byte aligned
  uint64_t header_checksum;
  uint32_t section_count;
  uint32_t details_count;
  uint64_t details_bytes;
  char isa[16];     // simd_isa() of the writer: the CPU must have it
  char config[64];  // BuildOptions::config_name(), for people and messages
  OptionsRecord options;
  SceneFigures figures;
  // 1 for a scene joined from `chunks` chunk scenes (api/scene_joined.h), 0 for a format's own.
  uint32_t joined, chunks;
  uint8_t reserved[168];
};
static_assert(sizeof(FileHeader) == 512);

struct SectionEntry {
  char name[48];
  uint64_t offset, size, checksum;
  uint32_t elem, reserved;
};
static_assert(sizeof(SectionEntry) == 80);

uint64_t align_up(uint64_t x) { return (x + kAlign - 1) & ~(kAlign - 1); }

std::string hex(uint64_t x) {
  char b[32];
  std::snprintf(b, sizeof b, "0x%llx", static_cast<unsigned long long>(x));
  return b;
}

// ---- saving ----------------------------------------------------------------------------------

struct Pending {
  std::string name;
  const void* data;
  uint64_t bytes;
  uint32_t elem;
  std::vector<uint8_t> copy;  // records: their bytes (the caller's object may be a temporary)
};

class SaveVisitor final : public SectionVisitor {
 public:
  std::vector<Pending> out;
  SaveVisitor() { saving_ = true; }
  void raw(const std::string& name, const void*& data, uint64_t& count, uint32_t elem) override {
    out.push_back({name, data, count * elem, elem, {}});
  }
  void record(const std::string& name, void* p, uint32_t size) override {
    Pending s{name, nullptr, size, size, {}};
    s.copy.assign(static_cast<const uint8_t*>(p), static_cast<const uint8_t*>(p) + size);
    out.push_back(std::move(s));
  }
};

OptionsRecord options_record(const BuildOptions& o) {
  OptionsRecord r;
  std::memset(&r, 0, sizeof r);
  r.nodes = uint8_t(o.nodes);
  r.leaf = uint8_t(o.leaf);
  r.grid_encoding = uint8_t(o.grid_encoding);
  r.pairing = uint8_t(o.pairing);
  r.collapse = uint8_t(o.collapse);
  r.grid_leftovers = uint8_t(o.grid_leftovers);
  r.coordinate_keys = o.pairing_options.coordinate_keys;
  r.weld = o.pairing_options.weld;
  r.augment = o.pairing_options.augment;
  r.cluster_redivide = o.cluster_redivide;
  r.grid_parts = o.grid_parts;
  r.sah_bins = o.sah_bins;
  r.max_leaf_size = o.max_leaf_size;
  r.threads = o.threads;
  r.prescan_threshold = o.pairing_options.prescan_threshold;
  r.cluster_error = o.cluster_error;
  std::snprintf(r.costa, sizeof r.costa, "%s", o.costa.c_str());
  for (int a = 0; a < 3; ++a) {
    r.lattice_lo[a] = o.lattice_box.lo[a];
    r.lattice_hi[a] = o.lattice_box.hi[a];
  }
  return r;
}

void copy_name(char* dst, size_t n, const std::string& s, const std::string& what) {
  if (s.size() >= n) throw Error("scene file: " + what + " '" + s + "' is too long");
  std::memset(dst, 0, n);
  std::memcpy(dst, s.data(), s.size());
}

// ---- opening ---------------------------------------------------------------------------------

class Opener;

class OpenVisitor final : public SectionVisitor {
 public:
  explicit OpenVisitor(Opener& o) : o_(o) { saving_ = false; }
  void raw(const std::string& name, const void*& data, uint64_t& count, uint32_t elem) override;
  void record(const std::string& name, void* p, uint32_t size) override;

 private:
  Opener& o_;
};

class Opener {
 public:
  Opener(const std::string& path, const uint8_t* base, uint64_t size)
      : path_(path), base_(base), size_(size) {}

  [[noreturn]] void fail(uint64_t offset, const std::string& section, const std::string& what) {
    throw Error("scene file '" + path_ + "'" +
                (section.empty() ? std::string() : ", section '" + section + "'") + ", offset " +
                std::to_string(offset) + ": " + what);
  }

  const FileHeader& header() {
    if (size_ < sizeof(FileHeader))
      fail(size_, "",
           "truncated: " + std::to_string(size_) + " bytes, the header alone takes " +
               std::to_string(sizeof(FileHeader)));
    std::memcpy(&h_, base_, sizeof h_);
    if (std::memcmp(h_.magic, kMagic, sizeof kMagic) != 0)
      fail(0, "", "not a slimrt scene file (wrong magic; expected \"SLIMSCN\\n\")");
    if (h_.byte_order != kByteOrder) {
      if (h_.byte_order == __builtin_bswap32(kByteOrder))
        fail(offsetof(FileHeader, byte_order), "", "written on a machine of the other byte order");
      fail(offsetof(FileHeader, byte_order), "", "bad byte-order mark " + hex(h_.byte_order));
    }
    if (h_.version != kVersion)
      fail(offsetof(FileHeader, version), "",
           "format version " + std::to_string(h_.version) + ", this slimrt reads version " +
               std::to_string(kVersion) + " (rebuild the file with `slimrt build`)");
    if (h_.file_bytes != size_)
      fail(std::min<uint64_t>(size_, h_.file_bytes), "",
           (size_ < h_.file_bytes ? "truncated: " : "trailing bytes: ") + std::to_string(size_) +
               " bytes, the header says " + std::to_string(h_.file_bytes));
    if (std::memchr(h_.config, 0, sizeof h_.config) == nullptr ||
        std::memchr(h_.isa, 0, sizeof h_.isa) == nullptr)
      fail(offsetof(FileHeader, isa), "", "unterminated instruction set or configuration name");
    if (h_.section_count > kMaxSections)
      fail(offsetof(FileHeader, section_count), "",
           std::to_string(h_.section_count) + " sections (at most " + std::to_string(kMaxSections) +
               ")");
    if (h_.details_count > kMaxDetails)
      fail(offsetof(FileHeader, details_count), "",
           std::to_string(h_.details_count) + " figures (at most " + std::to_string(kMaxDetails) +
               ")");
    const uint64_t table_end =
        sizeof(FileHeader) + uint64_t(h_.section_count) * sizeof(SectionEntry);
    if (h_.details_bytes > size_ || h_.header_bytes > size_ ||
        table_end + h_.details_bytes > h_.header_bytes || h_.header_bytes % kAlign != 0)
      fail(offsetof(FileHeader, header_bytes), "",
           "header size " + std::to_string(h_.header_bytes) + " inconsistent with " +
               std::to_string(h_.section_count) + " sections, " + std::to_string(h_.details_bytes) +
               " bytes of figures and the file size " + std::to_string(size_));
    // The header checksum covers the header, the table and the figures.
    XXH3_state_t* st = XXH3_createState();
    if (!st) throw std::bad_alloc();
    XXH3_64bits_reset(st);
    FileHeader z = h_;
    z.header_checksum = 0;
    XXH3_64bits_update(st, &z, sizeof z);
    XXH3_64bits_update(st, base_ + sizeof z, h_.header_bytes - sizeof z);
    const uint64_t sum = XXH3_64bits_digest(st);
    XXH3_freeState(st);
    if (sum != h_.header_checksum)
      fail(offsetof(FileHeader, header_checksum), "",
           "header checksum mismatch (the header, section table or figures are damaged)");
    return h_;
  }

  void table(bool verify) {
    sections_.resize(h_.section_count);
    if (h_.section_count)
      std::memcpy(sections_.data(), base_ + sizeof(FileHeader),
                  sections_.size() * sizeof(SectionEntry));
    uint64_t prev_end = h_.header_bytes;
    for (uint32_t i = 0; i < h_.section_count; ++i) {
      const SectionEntry& e = sections_[i];
      const uint64_t at = sizeof(FileHeader) + uint64_t(i) * sizeof(SectionEntry);
      if (std::memchr(e.name, 0, sizeof e.name) == nullptr)
        fail(at, "", "section " + std::to_string(i) + " has an unterminated name");
      const std::string name = e.name;
      if (e.offset % kAlign != 0) fail(e.offset, name, "section not 64-byte aligned");
      if (e.offset > size_ || e.size > size_ - e.offset)
        fail(e.offset, name,
             "section of " + std::to_string(e.size) + " bytes runs past the end of the file (" +
                 std::to_string(size_) + " bytes)");
      if (e.offset < prev_end)
        fail(e.offset, name, "section overlaps the header or the previous section");
      prev_end = e.offset + e.size;
      if (e.elem == 0 || e.size % e.elem != 0)
        fail(e.offset, name,
             "section size " + std::to_string(e.size) + " is not a multiple of its element size " +
                 std::to_string(e.elem));
      if (!index_.emplace(name, i).second) fail(e.offset, name, "section named twice");
    }
    if (!verify) return;
    for (const SectionEntry& e : sections_) {
      const uint64_t sum = XXH3_64bits(base_ + e.offset, e.size);
      if (sum != e.checksum)
        fail(e.offset, e.name,
             "checksum mismatch (the section's bytes are damaged; XXH3-64 " + hex(sum) +
                 ", the table says " + hex(e.checksum) + ")");
    }
  }

  std::vector<std::pair<std::string, double>> details() {
    std::vector<std::pair<std::string, double>> d;
    uint64_t at = sizeof(FileHeader) + uint64_t(h_.section_count) * sizeof(SectionEntry);
    const uint64_t end = at + h_.details_bytes;
    for (uint32_t i = 0; i < h_.details_count; ++i) {
      uint16_t n;
      if (end - at < 2) fail(at, "", "figures truncated");
      std::memcpy(&n, base_ + at, 2);
      at += 2;
      if (end - at < uint64_t(n) + 8) fail(at, "", "figures truncated");
      std::string name(reinterpret_cast<const char*>(base_ + at), n);
      at += n;
      double v;
      std::memcpy(&v, base_ + at, 8);
      at += 8;
      d.emplace_back(std::move(name), v);
    }
    return d;
  }

  const SectionEntry& find(const std::string& name) {
    auto it = index_.find(name);
    if (it == index_.end())
      fail(h_.header_bytes, name,
           "section missing (a " + std::string(h_.config) + " scene has it)");
    used_.push_back(it->second);
    return sections_[it->second];
  }
  void all_used() {
    std::sort(used_.begin(), used_.end());
    for (uint32_t i = 0; i < sections_.size(); ++i)
      if (!std::binary_search(used_.begin(), used_.end(), i))
        fail(sections_[i].offset, sections_[i].name,
             "section not part of a " + std::string(h_.config) + " scene");
  }
  uint64_t section_offset(const std::string& name) const {
    auto it = index_.find(name);
    return it == index_.end() ? 0 : sections_[it->second].offset;
  }

  const uint8_t* base() const { return base_; }

 private:
  std::string path_;
  const uint8_t* base_;
  uint64_t size_;
  FileHeader h_{};
  std::vector<SectionEntry> sections_;
  std::map<std::string, uint32_t> index_;
  std::vector<uint32_t> used_;
};

void OpenVisitor::raw(const std::string& name, const void*& data, uint64_t& count, uint32_t elem) {
  const SectionEntry& e = o_.find(name);
  if (e.elem != elem)
    o_.fail(e.offset, name,
            "element size " + std::to_string(e.elem) + ", expected " + std::to_string(elem));
  data = o_.base() + e.offset;
  count = e.size / elem;
}

void OpenVisitor::record(const std::string& name, void* p, uint32_t size) {
  const SectionEntry& e = o_.find(name);
  if (e.size != size)
    o_.fail(e.offset, name,
            "record of " + std::to_string(e.size) + " bytes, expected " + std::to_string(size));
  std::memcpy(p, o_.base() + e.offset, size);
}

BuildOptions options_of(const OptionsRecord& r, Opener& o) {
  if (r.nodes > uint8_t(Nodes::CompressedLeaf) || !is_registered_leaf(r.leaf) ||
      r.grid_encoding < 1 || r.grid_encoding > 2 || r.pairing > 1 || r.collapse > 2 ||
      r.grid_leftovers > 2 || std::memchr(r.costa, 0, sizeof r.costa) == nullptr)
    o.fail(offsetof(FileHeader, options), "", "build options out of range");
  BuildOptions b;
  b.nodes = Nodes(r.nodes);
  b.leaf = Leaf(r.leaf);
  b.grid_encoding = GridEncoding(r.grid_encoding);
  b.pairing = PairingMethod(r.pairing);
  b.collapse = Collapse(r.collapse);
  b.grid_leftovers = GridLeftovers(r.grid_leftovers);
  b.pairing_options.coordinate_keys = r.coordinate_keys != 0;
  b.pairing_options.weld = r.weld != 0;
  b.pairing_options.augment = r.augment != 0;
  b.cluster_redivide = r.cluster_redivide != 0;
  b.pairing_options.prescan_threshold = r.prescan_threshold;
  b.grid_parts = r.grid_parts;
  b.sah_bins = r.sah_bins;
  b.max_leaf_size = r.max_leaf_size;
  b.threads = r.threads;
  b.cluster_error = r.cluster_error;
  b.costa = r.costa;
  b.lattice_box = Box3f({r.lattice_lo[0], r.lattice_lo[1], r.lattice_lo[2]},
                        {r.lattice_hi[0], r.lattice_hi[1], r.lattice_hi[2]});
  try {
    b.check();
  } catch (const Error& e) {
    o.fail(offsetof(FileHeader, options), "", std::string("build options: ") + e.what());
  }
  return b;
}

struct Mapping {
  void* p = MAP_FAILED;
  uint64_t n = 0;
  ~Mapping() {
    if (p != MAP_FAILED) munmap(p, n);
  }
};

}  // namespace

SceneFigures figures_of(const Scene::Impl& s) {
  SceneFigures f;
  std::memset(&f, 0, sizeof f);
  f.mem_geometry = s.mem.geometry_bytes;
  f.mem_bvh = s.mem.bvh_bytes;
  f.mem_other = s.mem.other_bytes;
  f.mem_triangles = s.mem.triangles;
  for (int a = 0; a < 3; ++a) f.bounds_lo[a] = s.bounds.lo[a], f.bounds_hi[a] = s.bounds.hi[a];
  f.error_bound = s.error_bound;
  f.build_seconds = s.stats.build_seconds;
  f.input_faces = s.stats.input_faces;
  f.triangles = s.stats.triangles;
  f.skipped_faces = s.stats.skipped_faces;
  f.primitives = s.stats.primitives;
  return f;
}

void restore_figures(const SceneFigures& f, Scene::Impl& s) {
  s.mem = {f.mem_geometry, f.mem_bvh, f.mem_other, f.mem_triangles};
  s.bounds = Box3f({f.bounds_lo[0], f.bounds_lo[1], f.bounds_lo[2]},
                   {f.bounds_hi[0], f.bounds_hi[1], f.bounds_hi[2]});
  s.error_bound = f.error_bound;
  s.stats.build_seconds = f.build_seconds;
  s.stats.input_faces = f.input_faces;
  s.stats.triangles = f.triangles;
  s.stats.skipped_faces = f.skipped_faces;
  s.stats.primitives = f.primitives;
  s.ray_setup = RaySetupBounds(s.bounds);
}

// ---- the walk of OpenOptions::check_structure -------------------------------------------------

void check_bvh_root(const Bvh8& bvh, const std::string& p, uint32_t block_bytes,
                    uint32_t multileaf_header_bytes, uint32_t leaf_align) {
  if (bvh.block_bytes != block_bytes)
    throw SectionFault{p + "bvh.meta", 0,
                       "leaf block size " + std::to_string(bvh.block_bytes) + ", the format's is " +
                           std::to_string(block_bytes)};
  const uint64_t off = NodeRef::offset(bvh.root);
  bool ok = true;
  switch (NodeRef::tag(bvh.root)) {
    case kRefEmpty:
      ok = bvh.root == 0;
      break;
    case kRefNode8:
    case kRefQNode8:
    case kRefCQNode8: {
      const uint32_t tag = NodeRef::tag(bvh.root);
      ok = off % node_align(tag) == 0 && off < bvh.nodes.size() &&
           bvh.nodes.size() - off >= node_size(tag);
      break;
    }
    case kRefLeaf:
      ok = NodeRef::blocks(bvh.root) > 0 && off % leaf_align == 0 && off <= bvh.leaves.size() &&
           bvh.leaves.size() - off >= uint64_t(NodeRef::blocks(bvh.root)) * block_bytes;
      break;
    case kRefMulti:
      ok = NodeRef::blocks(bvh.root) > 0 && off % leaf_align == 0 && off <= bvh.leaves.size() &&
           bvh.leaves.size() - off >= multileaf_header_bytes;
      break;
    default:
      ok = false;
  }
  if (!ok) throw SectionFault{p + "bvh.meta", 0, "root reference " + hex(bvh.root) + " is invalid"};
}

namespace {

struct Walker {
  const Bvh8& b;
  const std::string& p;
  const BvhWalkHooks& h;
  // No node or leaf offset is named twice (which also bounds the walk by the arenas' sizes): one
  // mark per offset / grain, the grain the smallest size a node (or a leaf block, a multi-leaf
  // header) takes, so that two nodes (leaves) that do not overlap never share a mark. A leaf
  // referenced twice could be reached with two child counts, each checked on its own, where the
  // traversal's caches hold what one count decoded (ClusterLeaf's views).
  uint64_t node_grain, leaf_grain;
  std::vector<bool> node_seen, leaf_seen;
  Walker(const Bvh8& bvh, const std::string& prefix, const BvhWalkHooks& hooks)
      : b(bvh),
        p(prefix),
        h(hooks),
        node_grain(std::min({node_size(kRefNode8), node_size(kRefQNode8), node_size(kRefCQNode8)})),
        leaf_grain(std::max<uint64_t>(
            1, std::min<uint64_t>(bvh.block_bytes, hooks.multileaf_header_bytes))),
        node_seen(bvh.nodes.size() / node_grain + 1),
        leaf_seen(bvh.leaves.size() / leaf_grain + 1) {}
  // Marks the node or leaf at `off` (inside its arena); false if it was marked before.
  static bool first_visit(std::vector<bool>& seen, uint64_t off, uint64_t grain) {
    const uint64_t i = off / grain;
    if (seen[i]) return false;
    seen[i] = true;
    return true;
  }

  [[noreturn]] void nodes_fault(uint64_t off, const std::string& what) {
    throw SectionFault{p + "bvh.nodes", off, what};
  }
  [[noreturn]] void leaves_fault(uint64_t off, const std::string& what) {
    throw SectionFault{p + "bvh.leaves", off, what};
  }
  bool fits(uint64_t off, uint64_t n, uint64_t size) { return off <= size && size - off >= n; }

  void block(uint64_t off) {
    if (!fits(off, b.block_bytes, b.leaves.size()))
      leaves_fault(off, "leaf block outside the arena");
    if (std::string e = h.block(off); !e.empty()) leaves_fault(off, e);
  }

  // `where`: the node holding the reference (for messages).
  void visit(uint64_t ref, int depth, uint64_t where) {
    // The traversal stack holds 7 entries per level (kTraversalStackSize = 7 * 96 + 8).
    if (depth > 96) nodes_fault(where, "BVH deeper than 96 levels");
    const uint64_t off = NodeRef::offset(ref);
    switch (NodeRef::tag(ref)) {
      case kRefEmpty:
        if (ref != 0) nodes_fault(where, "empty reference with bits set");
        return;
      case kRefNode8:
      case kRefQNode8:
      case kRefCQNode8: {
        const uint32_t tag = NodeRef::tag(ref);
        // Aligned as the traversal's typed loads need (Node8: 64 bytes, QNode8: 8, CQNode8: 4);
        // a CQNode8's 32-bit refs read as the traversal expands them (bvh8.h cq_child_ref).
        if (off % node_align(tag) != 0)
          nodes_fault(off,
                      "misaligned node (referenced from offset " + std::to_string(where) + ")");
        if (!fits(off, node_size(tag), b.nodes.size()))
          nodes_fault(off, "node outside the node arena (referenced from offset " +
                               std::to_string(where) + ")");
        if (!first_visit(node_seen, off, node_grain))
          nodes_fault(off,
                      "node referenced twice (a shared subtree or a cycle; again from offset " +
                          std::to_string(where) + ")");
        uint64_t child[8];
        child_refs(ref, b.nodes.data() + off, child);
        for (uint64_t c : child) visit(c, depth + 1, off);
        return;
      }
      case kRefLeaf: {
        const uint32_t nb = NodeRef::blocks(ref);
        if (nb == 0) leaves_fault(off, "leaf of zero blocks");
        if (off % h.leaf_align != 0) leaves_fault(off, "misaligned leaf");
        for (uint32_t i = 0; i < nb; ++i) block(off + uint64_t(i) * b.block_bytes);
        if (!first_visit(leaf_seen, off, leaf_grain))  // off inside the arena: block() checked it
          leaves_fault(
              off, "leaf referenced twice (again from node offset " + std::to_string(where) + ")");
        return;
      }
      case kRefMulti: {
        const uint32_t k = NodeRef::blocks(ref);
        if (k == 0 || k > 8) leaves_fault(off, "multi-leaf of " + std::to_string(k) + " children");
        if (off % h.leaf_align != 0) leaves_fault(off, "misaligned multi-leaf");
        if (!fits(off, h.multileaf_header_bytes, b.leaves.size()))
          leaves_fault(off, "multi-leaf outside the leaf arena");
        if (!first_visit(leaf_seen, off, leaf_grain))
          leaves_fault(off, "multi-leaf referenced twice (again from node offset " +
                                std::to_string(where) + ")");
        if (h.multi) {
          if (std::string e = h.multi(off, k); !e.empty()) leaves_fault(off, e);
        } else {
          for (uint32_t i = 0; i < k; ++i)
            block(off + h.multileaf_header_bytes + uint64_t(i) * b.block_bytes);
        }
        return;
      }
      default:
        nodes_fault(where, "unknown node reference tag in " + hex(ref));
    }
  }
};

}  // namespace

void walk_bvh_checked(const Bvh8& bvh, const std::string& p, const BvhWalkHooks& h) {
  Walker w(bvh, p, h);
  w.visit(bvh.root, 0, 0);
}

// ---- Scene::save / Scene::open ----------------------------------------------------------------

void Scene::save(const std::string& path) const {
  if (!impl_) throw Error("Scene::save('" + path + "'): the scene was not built");
  SaveVisitor v;
  impl_->sections(v);
  std::stable_partition(v.out.begin(), v.out.end(),
                        [](const Pending& p) { return p.bytes <= kSmallSection; });
  const uint32_t n = uint32_t(v.out.size());

  std::string det;
  for (const auto& [name, value] : impl_->stats.details) {
    const uint16_t len = uint16_t(std::min<size_t>(name.size(), 0xffff));
    det.append(reinterpret_cast<const char*>(&len), 2);
    det.append(name.data(), len);
    det.append(reinterpret_cast<const char*>(&value), 8);
  }

  FileHeader h;
  std::memset(&h, 0, sizeof h);
  std::memcpy(h.magic, kMagic, sizeof kMagic);
  h.version = kVersion;
  h.byte_order = kByteOrder;
  h.section_count = n;
  h.details_count = uint32_t(impl_->stats.details.size());
  h.details_bytes = det.size();
  h.header_bytes = align_up(sizeof h + uint64_t(n) * sizeof(SectionEntry) + det.size());
  copy_name(h.isa, sizeof h.isa, simd_isa(), "instruction set");
  copy_name(h.config, sizeof h.config, impl_->opt.config_name(), "configuration name");
  h.options = options_record(impl_->opt);
  h.figures = figures_of(*impl_);
  if (const std::optional<uint32_t> chunks = impl_->joined_chunks()) {
    h.joined = 1;
    h.chunks = *chunks;
  }

  std::vector<SectionEntry> table(n);
  uint64_t at = h.header_bytes;
  for (uint32_t i = 0; i < n; ++i) {
    Pending& p = v.out[i];
    SectionEntry& e = table[i];
    std::memset(&e, 0, sizeof e);
    copy_name(e.name, sizeof e.name, p.name, "section name");
    const void* bytes = p.copy.empty() ? p.data : p.copy.data();
    e.offset = at;
    e.size = p.bytes;
    e.elem = p.elem;
    e.checksum = XXH3_64bits(bytes, p.bytes);
    at = align_up(at + p.bytes);
  }
  h.file_bytes = n ? table.back().offset + table.back().size : h.header_bytes;

  std::string head(h.header_bytes, '\0');
  std::memcpy(head.data() + sizeof h, table.data(), table.size() * sizeof(SectionEntry));
  std::memcpy(head.data() + sizeof h + table.size() * sizeof(SectionEntry), det.data(), det.size());
  std::memcpy(head.data(), &h, sizeof h);
  h.header_checksum = XXH3_64bits(head.data(), head.size());
  std::memcpy(head.data(), &h, sizeof h);

  write_atomically(path, [&](const std::string& tmp) {
    std::unique_ptr<FILE, int (*)(FILE*)> f(std::fopen(tmp.c_str(), "wb"), &std::fclose);
    if (!f) throw Error("cannot create '" + tmp + "': " + std::strerror(errno));
    auto put = [&](const void* d, uint64_t len) {
      if (len && std::fwrite(d, 1, len, f.get()) != len)
        throw Error("writing '" + tmp + "': " + std::strerror(errno));
    };
    static const uint8_t zeros[kAlign] = {};
    put(head.data(), head.size());
    uint64_t pos = head.size();
    for (uint32_t i = 0; i < n; ++i) {
      put(zeros, table[i].offset - pos);
      const Pending& p = v.out[i];
      put(p.copy.empty() ? p.data : p.copy.data(), p.bytes);
      pos = table[i].offset + p.bytes;
    }
    if (std::fflush(f.get()) != 0) throw Error("writing '" + tmp + "': " + std::strerror(errno));
  });
}

Scene Scene::open(const std::string& path, const OpenOptions& options) {
  check_cpu_isa();
  const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) throw Error("cannot open scene file '" + path + "': " + std::strerror(errno));
  struct stat st {};
  if (fstat(fd, &st) != 0 || !S_ISREG(st.st_mode)) {
    const int err = errno;
    ::close(fd);
    throw Error("scene file '" + path + "' is not a regular file" +
                (err ? std::string(": ") + std::strerror(err) : std::string()));
  }
  auto map = std::make_shared<Mapping>();
  map->n = uint64_t(st.st_size);
  if (map->n > 0) map->p = mmap(nullptr, map->n, PROT_READ, MAP_SHARED, fd, 0);
  const int err = errno;
  ::close(fd);
  if (map->n > 0 && map->p == MAP_FAILED)
    throw Error("cannot map scene file '" + path + "': " + std::strerror(err));
  const uint8_t* base = map->n ? static_cast<const uint8_t*>(map->p) : nullptr;

  Opener o(path, base, map->n);
  const FileHeader h = o.header();
  const std::string isa(h.isa, strnlen(h.isa, sizeof h.isa));
  if (!cpu_has_isa(isa))
    o.fail(offsetof(FileHeader, isa), "",
           "written for the " + isa + " instruction set, which this CPU lacks");
  o.table(options.verify_checksums);
  const BuildOptions opt = options_of(h.options, o);
  if (h.joined > 1)
    o.fail(offsetof(FileHeader, joined), "", "bad joined-scene flag " + std::to_string(h.joined));
  std::unique_ptr<Impl> impl =
      h.joined ? empty_joined_scene(opt, h.chunks) : format_of(opt.leaf).empty(opt);
  impl->opt = opt;
  impl->stats.details = o.details();
  restore_figures(h.figures, *impl);
  OpenVisitor v(o);
  try {
    impl->sections(v);
    o.all_used();
    impl->check_opened(options.check_structure);
  } catch (const SectionFault& f) {
    o.fail(o.section_offset(f.section) + f.offset, f.section, f.what);
  }
  impl->file = path;
  impl->mapping = map;
  Scene s;
  s.impl_ = std::move(impl);
  return s;
}

const std::string& Scene::file() const {
  static const std::string none;
  return impl_ ? impl_->file : none;
}

}  // namespace slim
