// ChunkSet: see chunks.h.
#include "mesh/chunks.h"

#include <stdlib.h>  // mkdtemp

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <limits>

#include "io/byte_window.h"
#include "slimrt/error.h"

namespace slim::detail {
namespace {

using Clock = std::chrono::steady_clock;
double since(Clock::time_point t0) {
  return std::chrono::duration<double>(Clock::now() - t0).count();
}

// Spreads the low 10 bits of v to every third bit.
uint32_t part1by2(uint32_t v) {
  v &= 0x3ff;
  v = (v | (v << 16)) & 0x030000ffu;
  v = (v | (v << 8)) & 0x0300f00fu;
  v = (v | (v << 4)) & 0x030c30c3u;
  v = (v | (v << 2)) & 0x09249249u;
  return v;
}

// Centroid of a face's corners (the same arithmetic in every pass).
Vec3f centroid(const Vec3f* c, uint32_t n) {
  Vec3f s = c[0];
  for (uint32_t k = 1; k < n; ++k) s = s + c[k];
  return s * (1.0f / float(n));
}

// Morton cell of a point in a box, `bits` per axis; NaN and out-of-box values clamp.
class CellMap {
 public:
  // Cubic cells over the box's largest side: a flat scene (a terrain) gets few cells across its
  // thickness, so the top Morton bits split it along its large sides, not into thin slabs.
  CellMap(const Box3f& box, int bits) : lo_(box.lo), side_(1u << bits) {
    const Vec3f e = box.hi - box.lo;
    const float extent = std::max(e.x, std::max(e.y, e.z));
    const float scale = extent > 0 ? float(side_) / extent : 0.0f;
    for (int a = 0; a < 3; ++a) scale_[a] = scale;
    if (box.empty()) lo_ = Vec3f(0, 0, 0);
  }
  uint32_t operator()(Vec3f p) const {
    uint32_t q[3];
    for (int a = 0; a < 3; ++a) {
      const float t = (p[a] - lo_[a]) * scale_[a];
      q[a] = t >= 1.0f ? std::min(uint32_t(std::min(t, 1e9f)), side_ - 1) : 0u;  // NaN: 0
    }
    return part1by2(q[0]) | part1by2(q[1]) << 1 | part1by2(q[2]) << 2;
  }

 private:
  Vec3f lo_;
  float scale_[3];
  uint32_t side_;
};

// Within a cell, faces fill pieces of at most `max` triangles in stream order (a face larger
// than `max` gets a piece of its own). Returns the piece index of the face within its cell.
inline uint32_t place(uint32_t& fill, uint32_t& closed, uint64_t tris, uint64_t max) {
  if (fill > 0 && fill + tris > max) {
    ++closed;
    fill = 0;
  }
  fill = uint32_t(std::min<uint64_t>(fill + tris, std::numeric_limits<uint32_t>::max()));
  return closed;
}

void write_all(const std::string& path, const std::vector<char>& buf) {
  std::FILE* f = std::fopen(path.c_str(), "ab");
  if (!f) throw Error(path + ": cannot write a chunk spill file: " + std::strerror(errno));
  const size_t put = std::fwrite(buf.data(), 1, buf.size(), f);
  const int err = errno;
  const bool closed = std::fclose(f) == 0;
  if (put != buf.size() || !closed)
    throw Error(path + ": cannot write a chunk spill file (" + std::to_string(buf.size()) +
                " bytes): " + std::strerror(err ? err : EIO));
}

}  // namespace

ChunkSet::ChunkSet(FaceStream& in, const ChunkOptions& opt) {
  if (opt.morton_bits < 1 || opt.morton_bits > 10)
    throw Error("chunking: morton_bits is " + std::to_string(opt.morton_bits) +
                "; expected 1 to 10");
  if (opt.max_triangles < 1 || opt.max_triangles > (uint64_t(1) << 31))
    throw Error("chunking: max_triangles is " + std::to_string(opt.max_triangles) +
                "; expected 1 to 2^31");
  if (opt.spill_dir.empty()) throw Error("chunking: no spill directory given");
  std::string tmpl = (std::filesystem::path(opt.spill_dir) / "slimrt-chunks-XXXXXX").string();
  if (!mkdtemp(tmpl.data()))
    throw Error(opt.spill_dir + ": cannot make a temporary directory for chunk spill files: " +
                std::strerror(errno));
  dir_ = tmpl;
  try {
    const uint64_t max = opt.max_triangles;
    FaceBatch b;
    // Pass 1: bounds of the centroids and of the positions.
    auto t0 = Clock::now();
    Box3f cbox;
    in.rewind();
    while (in.next(b)) {
      const Vec3f* c = b.corners.data();
      for (uint32_t n : b.sizes) {
        const Vec3f m = centroid(c, n);
        if (is_finite(m)) cbox.extend(m);
        for (uint32_t k = 0; k < n; ++k)
          if (is_finite(c[k])) stats_.bounds.extend(c[k]);
        stats_.triangles += n - 2;
        c += n;
      }
      stats_.faces += b.face_count();
    }
    stats_.seconds[0] = since(t0);

    // Pass 2: pieces per Morton cell, then chunks over the cells in Morton order.
    t0 = Clock::now();
    const CellMap cell(cbox, opt.morton_bits);
    const size_t cells = size_t(1) << (3 * opt.morton_bits);
    std::vector<uint32_t> fill(cells, 0), closed(cells, 0), first(cells, 0);
    stats_.histogram_bytes = 3 * cells * sizeof(uint32_t);
    in.rewind();
    while (in.next(b)) {
      const Vec3f* c = b.corners.data();
      for (uint32_t n : b.sizes) {
        const uint32_t k = cell(centroid(c, n));
        place(fill[k], closed[k], n - 2, max);
        c += n;
      }
    }
    uint32_t chunks = 0;
    uint64_t open_fill = 0;  // triangles in the last chunk, if it may take more cells
    bool open = false;
    for (size_t k = 0; k < cells; ++k) {
      if (fill[k] == 0 && closed[k] == 0) continue;
      ++stats_.cells_used;
      if (closed[k] == 0 && open && open_fill + fill[k] <= max) {
        first[k] = chunks - 1;
        open_fill += fill[k];
        continue;
      }
      // A new chunk; a cell of several pieces gets one chunk per piece, and its last piece's
      // chunk may take the next cells.
      if (uint64_t(chunks) + closed[k] + 1 > std::numeric_limits<uint32_t>::max())
        throw Error(in.name() + ": more than 2^32 chunks; expected a larger max_triangles");
      first[k] = chunks;
      chunks += closed[k] + 1;
      open = true;
      open_fill = fill[k];
    }
    info_.resize(chunks);
    stats_.seconds[1] = since(t0);

    // Pass 3: every face to its chunk's spill buffer. Records: face id (u64), corner count
    // (u32), corners (3 x f32 each), native byte order.
    t0 = Clock::now();
    std::fill(fill.begin(), fill.end(), 0);
    std::fill(closed.begin(), closed.end(), 0);
    const size_t cap = size_t(std::clamp<uint64_t>(
        opt.memory_budget / std::max<uint32_t>(chunks, 1), 4096, uint64_t(64) << 20));
    std::vector<std::vector<char>> buf(chunks);
    uint64_t held = 0;
    auto flush = [&](uint32_t k) {
      write_all(file(k), buf[k]);
      stats_.spilled_bytes += buf[k].size();
      buf[k].clear();
    };
    in.rewind();
    while (in.next(b)) {
      const Vec3f* c = b.corners.data();
      for (size_t f = 0; f < b.sizes.size(); ++f) {
        const uint32_t n = b.sizes[f];
        const uint32_t k = cell(centroid(c, n));
        const uint32_t id = first[k] + place(fill[k], closed[k], n - 2, max);
        ChunkInfo& ci = info_[id];
        ++ci.faces;
        ci.triangles += n - 2;
        ci.corners += n;
        for (uint32_t j = 0; j < n; ++j)
          if (is_finite(c[j])) ci.bounds.extend(c[j]);
        std::vector<char>& out = buf[id];
        const size_t bytes = 12 + size_t(n) * sizeof(Vec3f);
        if (out.size() + bytes > cap && !out.empty()) flush(id);
        if (out.size() + bytes > out.capacity()) {
          // Grows by doubling from 64 KiB up to `cap` (more only for one face larger than cap).
          const size_t old = out.capacity();
          out.reserve(
              std::max(out.size() + bytes, std::min(cap, std::max<size_t>(2 * old, 65536))));
          held += out.capacity() - old;
          stats_.buffer_bytes = std::max(stats_.buffer_bytes, held);
        }
        const size_t at = out.size();
        out.resize(at + bytes);  // within capacity unless one face is larger than a buffer
        std::memcpy(out.data() + at, &b.face_ids[f], 8);
        std::memcpy(out.data() + at + 8, &n, 4);
        std::memcpy(out.data() + at + 12, c, size_t(n) * sizeof(Vec3f));
        c += n;
      }
    }
    stats_.stream_bytes = in.resident_bytes();
    for (uint32_t k = 0; k < chunks; ++k) {
      if (!buf[k].empty()) flush(k);
      std::vector<char>().swap(buf[k]);
    }
    stats_.seconds[2] = since(t0);
  } catch (...) {
    remove_files();
    throw;
  }
}

ChunkSet::~ChunkSet() { remove_files(); }

void ChunkSet::remove_files() noexcept {
  if (dir_.empty()) return;
  std::error_code ec;
  std::filesystem::remove_all(dir_, ec);
  dir_.clear();
}

std::string ChunkSet::file(size_t i) const { return dir_ + "/chunk-" + std::to_string(i); }

Chunk ChunkSet::load(size_t i) const {
  const ChunkInfo& ci = info_.at(i);
  const std::string path = file(i);
  Chunk out;
  PolyMesh& m = out.mesh;
  m.name = "chunk " + std::to_string(i);
  if (ci.faces == 0) return out;
  // Read through a 1 MiB window: the chunk in memory is its PolyMesh and the weld table only.
  ByteWindow w(path, 0, size_t(1) << 20, false);
  const uint64_t expected = 12 * ci.faces + ci.corners * sizeof(Vec3f);
  if (w.total() != expected)
    throw Error(path + ": chunk spill file has " + std::to_string(w.total()) + " bytes; expected " +
                std::to_string(expected) + " (changed on disk?)");
  m.face_sizes.reserve(ci.faces);
  m.face_indices.reserve(ci.corners);
  out.face_ids.reserve(ci.faces);
  // Weld by bit pattern: an open-addressing table of position indices (4 bytes a slot, at most
  // half full).
  auto bits = [](const Vec3f& p, uint32_t k) {
    uint32_t b;
    std::memcpy(&b, reinterpret_cast<const char*>(&p) + 4 * k, 4);
    return b;
  };
  auto hash = [&](const Vec3f& p) {
    uint64_t h = bits(p, 0) * 0x9E3779B97F4A7C15ull;
    h = (h ^ bits(p, 1)) * 0xC2B2AE3D27D4EB4Full;
    h = (h ^ bits(p, 2)) * 0x165667B19E3779F9ull;
    return h ^ (h >> 29);
  };
  constexpr uint32_t kEmpty = ~uint32_t(0);
  std::vector<uint32_t> table(1024, kEmpty);
  auto insert = [&](const Vec3f& p, uint32_t idx, bool rehashing) -> uint32_t {
    const size_t mask = table.size() - 1;
    for (size_t s = size_t(hash(p)) & mask;; s = (s + 1) & mask) {
      if (table[s] == kEmpty) {
        table[s] = idx;
        return idx;
      }
      if (!rehashing && std::memcmp(&m.positions[table[s]], &p, sizeof p) == 0) return table[s];
    }
  };
  while (w.left() > 0) {
    uint64_t id;
    uint32_t n;
    const uint64_t at = w.offset(w.cur);
    if (!w.ensure(12)) throw_at_byte(path, at, "truncated chunk record");
    std::memcpy(&id, w.cur, 8);
    std::memcpy(&n, w.cur + 8, 4);
    w.cur += 12;
    if (n < 3 || w.left() / sizeof(Vec3f) < n)
      throw_at_byte(path, at, "bad chunk record (corner count " + std::to_string(n) + ")");
    out.face_ids.push_back(id);
    m.face_sizes.push_back(n);
    for (uint32_t k = 0; k < n; ++k) {
      if (!w.ensure(sizeof(Vec3f))) throw_at_byte(path, w.offset(w.cur), "truncated corner");
      Vec3f p;
      std::memcpy(&p, w.cur, sizeof p);
      w.cur += sizeof p;
      if (2 * (m.positions.size() + 1) > table.size()) {
        table.assign(table.size() * 2, kEmpty);
        for (uint32_t v = 0; v < m.positions.size(); ++v) insert(m.positions[v], v, true);
      }
      const uint32_t next = uint32_t(m.positions.size());
      const uint32_t idx = insert(p, next, false);
      if (idx == next) m.positions.push_back(p);
      m.face_indices.push_back(idx);
    }
  }
  if (m.face_sizes.size() != ci.faces)
    throw Error(path + ": chunk spill file has " + std::to_string(m.face_sizes.size()) +
                " faces; expected " + std::to_string(ci.faces));
  return out;
}

}  // namespace slim::detail
