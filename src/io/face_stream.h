// Face streams: the faces of a mesh file or a procedural scene in bounded batches, without the
// whole PolyMesh in memory (README.md "Inputs larger than memory").
//
// A batch holds polygons with their corner positions (copied out of the vertex array, bit for bit)
// and the face id each one has in slim::load()'s PolyMesh. What stays in memory besides the batch:
//  - PLY: the vertex positions (12 bytes per vertex), read once; the faces are read from the file
//    through a fixed window. Plain files only are read through the window; a .ply.xz file is
//    decompressed into memory whole (the file image, not the PolyMesh).
//  - OBJ: the positions of the 'v' lines read so far (12 bytes per vertex); OBJ faces can only
//    refer to vertices defined before them, so one pass suffices. Plain files through a window,
//    .obj.xz decompressed whole.
//  - procedural scenes: two rows of vertices; the faces are made row band by row band with the
//    same arithmetic as make_terrain/make_canyon/make_torus, so every corner has the same bits.
// Every stream can be rewound for another pass (the chunker makes three).
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "slimrt/math.h"

namespace slim::detail {

struct FaceBatch {
  std::vector<uint32_t> sizes;     // corners per face (>= 3)
  std::vector<uint64_t> face_ids;  // the face's index in slim::load()'s PolyMesh
  std::vector<Vec3f> corners;      // corner positions, faces concatenated
  void clear() {
    sizes.clear();
    face_ids.clear();
    corners.clear();
  }
  size_t face_count() const { return sizes.size(); }
};

class FaceStream {
 public:
  virtual ~FaceStream() = default;
  // Replaces `out` with the next faces: at most about max_corners() corners (a single face larger
  // than that comes alone). Returns false, with `out` empty, once every face was delivered.
  // Malformed input throws slim::Error naming the file and the line or byte offset.
  virtual bool next(FaceBatch& out) = 0;
  // Starts again from the first face (same faces, same order, same bits).
  virtual void rewind() = 0;
  // Number of faces the input declares (PLY header, procedural size); 0 if unknown (OBJ).
  virtual uint64_t declared_faces() const { return 0; }
  // Bytes the stream holds apart from the batch (positions, window), for memory accounting.
  virtual uint64_t resident_bytes() const = 0;
  const std::string& name() const { return name_; }

 protected:
  explicit FaceStream(std::string name) : name_(std::move(name)) {}
  std::string name_;
};

// Default batch size in corners: 1 Mi corners, 12 MiB of positions.
constexpr size_t kDefaultBatchCorners = size_t(1) << 20;
// Default read window of the file streams (at least 4 KiB is used).
constexpr size_t kDefaultWindowBytes = size_t(4) << 20;

// Opens `path_or_scene` (.ply, .obj, optionally .xz, or terrain:N, canyon:N, torus:N) as a stream.
// Procedural scenes accept N up to 65534 (the in-memory load stops at 16384). glTF is not
// streamed: Error. Missing files and bad headers throw at once.
std::unique_ptr<FaceStream> open_face_stream(const std::string& path_or_scene,
                                             size_t max_corners = kDefaultBatchCorners,
                                             size_t window_bytes = kDefaultWindowBytes);

// The readers' own entry points (open_face_stream picks one by extension).
std::unique_ptr<FaceStream> open_ply_stream(const std::string& path, size_t max_corners,
                                            size_t window_bytes = kDefaultWindowBytes);
std::unique_ptr<FaceStream> open_obj_stream(const std::string& path, size_t max_corners,
                                            size_t window_bytes = kDefaultWindowBytes);
std::unique_ptr<FaceStream> open_procedural_stream(const std::string& spec, size_t max_corners);

}  // namespace slim::detail
