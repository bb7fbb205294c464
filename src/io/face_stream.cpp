// open_face_stream and the procedural face stream (the PLY and OBJ streams live with their
// whole-file readers in ply.cpp and obj.cpp, which they share the parsing code with).
#include "io/face_stream.h"

#include <algorithm>
#include <filesystem>

#include "io/xz.h"
#include "mesh/procedural.h"
#include "slimrt/error.h"
#include "slimrt/mesh.h"

namespace slim::detail {
namespace {

// A procedural scene made row band by row band (ProceduralGrid::tile over full rows), so face
// ids come in the in-memory mesh's order; only the band's vertex rows are ever in memory.
class ProceduralFaceStream final : public FaceStream {
 public:
  ProceduralFaceStream(const std::string& spec, size_t max_corners)
      : FaceStream(spec), grid_(parse_procedural(spec, kMaxProceduralN)) {
    rows_ = int(std::max<size_t>(1, max_corners / (4 * size_t(grid_.cells_x))));
  }
  bool next(FaceBatch& out) override {
    out.clear();
    if (row_ >= grid_.cells_y) return false;
    const int j1 = std::min(grid_.cells_y, row_ + rows_);
    grid_.tile(0, grid_.cells_x, row_, j1, out.sizes, out.face_ids, out.corners);
    row_ = j1;
    return true;
  }
  void rewind() override { row_ = 0; }
  uint64_t declared_faces() const override {
    return uint64_t(grid_.cells_x) * uint64_t(grid_.cells_y);
  }
  uint64_t resident_bytes() const override {
    // The band's vertex rows while a batch is made (the angle tables of a torus are small).
    return uint64_t(rows_ + 1) * uint64_t(grid_.verts_x) * sizeof(Vec3f);
  }

 private:
  ProceduralGrid grid_;
  int rows_ = 1, row_ = 0;
};

std::string lower_ext(const std::string& path) {
  std::string stem = path;
  if (has_xz_suffix(stem)) stem.resize(stem.size() - 3);
  std::string ext = std::filesystem::path(stem).extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(),
                 [](unsigned char c) { return char(std::tolower(c)); });
  return ext;
}

}  // namespace

std::unique_ptr<FaceStream> open_procedural_stream(const std::string& spec, size_t max_corners) {
  return std::make_unique<ProceduralFaceStream>(spec, max_corners);
}

std::unique_ptr<FaceStream> open_face_stream(const std::string& path_or_scene, size_t max_corners,
                                             size_t window_bytes) {
  if (is_procedural(path_or_scene)) return open_procedural_stream(path_or_scene, max_corners);
  const std::string ext = lower_ext(path_or_scene);
  if (ext == ".ply") return open_ply_stream(path_or_scene, max_corners, window_bytes);
  if (ext == ".obj") return open_obj_stream(path_or_scene, max_corners, window_bytes);
  throw Error(path_or_scene + ": cannot stream '" + ext +
              "' files; expected .ply or .obj (optionally .xz) or a procedural scene terrain:N, "
              "canyon:N or torus:N");
}

}  // namespace slim::detail
