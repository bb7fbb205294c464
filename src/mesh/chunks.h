// Spatial chunking of a face stream within a memory budget (README.md "Inputs larger than
// memory"): the layer under the per-chunk builds and the top-level BVH.
//
// Three passes over the stream (FaceStream::rewind between them):
//  1. bounds of the face centroids;
//  2. a histogram over a 2^bits x 2^bits x 2^bits grid of cubic cells over that box (its largest
//     side), in Morton order (the cell of a face is the one of its centroid). Within each cell the faces are packed, in
//     stream order, into pieces of at most max_triangles fan triangles; consecutive cells whose
//     pieces fit are then packed into chunks. A chunk is thus a run of Morton cells (or one piece
//     of a cell holding more than max_triangles), at most max_triangles triangles unless a single
//     face alone has more;
//  3. every face goes to its chunk's spill buffer; a full buffer is appended to the chunk's
//     temporary file. The buffers together stay within memory_budget.
// Each chunk is then read back on its own (load(): through a 1 MiB window, welded with an
// open-addressing table of 8 to 16 bytes per distinct position). The temporary files live in a fresh
// directory under ChunkOptions::spill_dir, removed by the destructor and on any error.
//
// Memory: the histogram (12 bytes per cell, 24 MiB at bits = 7) + the spill buffers (at most
// memory_budget) + the stream's own (FaceStream::resident_bytes) + one batch; then one chunk at
// a time.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "io/face_stream.h"
#include "slimrt/math.h"
#include "slimrt/mesh.h"

namespace slim::detail {

struct ChunkOptions {
  uint64_t max_triangles = uint64_t(1) << 22;    // per chunk: fan triangles, size - 2 per face
  uint64_t memory_budget = uint64_t(256) << 20;  // bytes of spill buffers, all chunks together
  std::string spill_dir;                         // where the temporary directory is made
  int morton_bits = 7;                           // cells per axis = 2^bits (1..10)
};

struct ChunkInfo {
  uint64_t faces = 0, triangles = 0, corners = 0;
  Box3f bounds;  // of the chunk's finite corner positions
};

// One chunk read back: its faces as an indexed mesh (corner positions welded by bit pattern, so
// every position is the input's, bit for bit) and the input face id of each face.
struct Chunk {
  PolyMesh mesh;
  std::vector<uint64_t> face_ids;
};

struct ChunkingStats {
  uint64_t faces = 0, triangles = 0;
  Box3f bounds;                   // of all finite corner positions
  uint64_t cells_used = 0;        // non-empty Morton cells
  uint64_t histogram_bytes = 0;   // per-cell arrays
  uint64_t buffer_bytes = 0;      // spill buffers, allocated at the peak
  uint64_t stream_bytes = 0;      // FaceStream::resident_bytes at the end of pass 3
  uint64_t spilled_bytes = 0;     // written to the temporary files
  double seconds[3] = {0, 0, 0};  // per pass
};

// Where a chunked build takes its chunks from: the spill files of a ChunkSet (any face stream), or
// chunks generated on demand (procedural tiles). Chunks are loaded one at a time, in any order.
class ChunkSource {
 public:
  virtual ~ChunkSource() = default;
  virtual size_t size() const = 0;
  virtual const ChunkInfo& info(size_t i) const = 0;
  virtual Chunk load(size_t i) const = 0;
  // Figures of the whole input: faces, fan triangles, bounds of every finite corner position (the
  // box the chunks' common lattice is derived from: BuildOptions::lattice_box).
  virtual uint64_t faces() const = 0;
  virtual uint64_t triangles() const = 0;
  virtual Box3f bounds() const = 0;
};

class ChunkSet : public ChunkSource {
 public:
  // Partitions every face of `in` (rewound first). Throws slim::Error on malformed input (the
  // stream's), on a spill directory that cannot be written, or on a full disk, after removing
  // what it wrote.
  ChunkSet(FaceStream& in, const ChunkOptions& options);
  ~ChunkSet();
  ChunkSet(const ChunkSet&) = delete;
  ChunkSet& operator=(const ChunkSet&) = delete;

  size_t size() const override { return info_.size(); }
  const ChunkInfo& info(size_t i) const override { return info_[i]; }
  uint64_t faces() const override { return stats_.faces; }
  uint64_t triangles() const override { return stats_.triangles; }
  Box3f bounds() const override { return stats_.bounds; }
  const ChunkingStats& stats() const { return stats_; }
  const std::string& directory() const { return dir_; }
  // Reads chunk i back from its temporary file.
  Chunk load(size_t i) const override;

 private:
  std::string file(size_t i) const;
  void remove_files() noexcept;

  std::string dir_;
  std::vector<ChunkInfo> info_;
  ChunkingStats stats_;
};

}  // namespace slim::detail
