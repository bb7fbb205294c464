// slimrt input meshes: PolyMesh, the loaders and the procedural scenes.
#pragma once

#include <cstddef>
#include <cstdint>
#include <iterator>
#include <span>
#include <string>
#include <vector>

#include "slimrt/error.h"
#include "slimrt/math.h"

namespace slim {

// A polygon mesh exactly as its author made it: polygons are kept (not triangulated).
// Face f has face_sizes[f] >= 3 corners, stored consecutively in face_indices.
struct PolyMesh {
  std::string name;                    // file name or procedural scene name
  std::vector<Vec3f> positions;        // float3 positions
  std::vector<uint32_t> face_sizes;    // corners per face
  std::vector<uint32_t> face_indices;  // corner -> position index, all faces concatenated
  // Optional attributes. normals/uvs are indexed per corner through normal_indices/uv_indices
  // (parallel to face_indices, as OBJ's v/t/n). If an index array is empty but the attribute array
  // has one entry per position, the attribute is per vertex (indexed by face_indices).
  std::vector<Vec3f> normals;
  std::vector<uint32_t> normal_indices;
  std::vector<Vec2f> uvs;
  std::vector<uint32_t> uv_indices;
  // Optional per-face object id (OBJ 'o'/'g' groups, glTF meshes); empty means all 0.
  std::vector<uint32_t> face_object;
  std::vector<std::string> object_names;

  size_t face_count() const { return face_sizes.size(); }
  size_t vertex_count() const { return positions.size(); }
  // Triangles after fan triangulation: sum over faces of (size - 2).
  uint64_t fan_triangle_count() const;
  // Prefix sums of face_sizes (face_count()+1 entries): face f's corners are
  // face_indices[offsets[f] .. offsets[f+1]).
  std::vector<uint64_t> face_offsets() const;
  Box3f bounds() const;  // over finite positions only
};

// The corners of each face of a MeshView: an array with one size per face, or one size shared by
// every face (3 for an array of triangles, which then needs no array of sizes at all).
class FaceSizes {
 public:
  FaceSizes() = default;
  // One size per face, read from `sizes` (not copied). A null array with a nonzero size reads as
  // faces of 0 corners, which check_mesh refuses.
  FaceSizes(std::span<const uint32_t> sizes)
      : sizes_(sizes.data()), count_(sizes.size()), uniform_(0) {}
  // `face_count` faces of `corners` corners each.
  static FaceSizes uniform(uint32_t corners, size_t face_count) {
    FaceSizes s;
    s.uniform_ = corners;
    s.count_ = face_count;
    return s;
  }

  uint32_t operator[](size_t f) const { return sizes_ ? sizes_[f] : uniform_; }
  size_t size() const { return count_; }
  bool empty() const { return count_ == 0; }
  // The array of sizes, or nullptr when every face has uniform_size() corners.
  const uint32_t* data() const { return sizes_; }
  uint32_t uniform_size() const { return sizes_ ? 0 : uniform_; }

  class iterator {
   public:
    using iterator_category = std::input_iterator_tag;
    using value_type = uint32_t;
    using difference_type = std::ptrdiff_t;
    using pointer = void;
    using reference = uint32_t;
    iterator(const FaceSizes* s, size_t f) : s_(s), f_(f) {}
    uint32_t operator*() const { return (*s_)[f_]; }
    iterator& operator++() {
      ++f_;
      return *this;
    }
    bool operator==(const iterator& o) const { return f_ == o.f_; }

   private:
    const FaceSizes* s_;
    size_t f_;
  };
  iterator begin() const { return {this, 0}; }
  iterator end() const { return {this, count_}; }

 private:
  const uint32_t* sizes_ = nullptr;
  size_t count_ = 0;
  uint32_t uniform_ = 3;
};

// A mesh read in place from arrays its owner keeps (a PolyMesh, numpy arrays, a memory-mapped
// file): the fields of PolyMesh as spans, nothing copied. Scene::build reads it only while it
// builds; the scene keeps nothing of it. Built from a PolyMesh it is that mesh exactly.
struct MeshView {
  std::string name;                        // in error messages ("" reads "mesh")
  std::span<const Vec3f> positions;        // float3 positions
  FaceSizes face_sizes;                    // corners per face (an array or one size for all)
  std::span<const uint32_t> face_indices;  // corner -> position index, all faces concatenated
  // Optional attributes, as in PolyMesh.
  std::span<const Vec3f> normals;
  std::span<const uint32_t> normal_indices;
  std::span<const Vec2f> uvs;
  std::span<const uint32_t> uv_indices;
  std::span<const uint32_t> face_object;
  std::span<const std::string> object_names;

  MeshView() = default;
  // Every field of `mesh`, read in place: the mesh must outlive the view.
  MeshView(const PolyMesh& mesh);
  // `triangle_count` triangles, 3 indices each in `indices`, over `vertex_count` positions.
  static MeshView triangles(const Vec3f* positions, size_t vertex_count, const uint32_t* indices,
                            size_t triangle_count, std::string name = {});

  size_t face_count() const { return face_sizes.size(); }
  size_t vertex_count() const { return positions.size(); }
  // As PolyMesh's.
  uint64_t fan_triangle_count() const;
  std::vector<uint64_t> face_offsets() const;
  Box3f bounds() const;
};

// Throws slim::Error (naming the mesh, the face and the problem) if the mesh is malformed:
// fewer than 3 corners in a face, an index out of range, array sizes that do not agree (for a
// view also a null array with a nonzero size). NaN/Inf positions are not an error here (see
// MeshSummary::nonfinite_vertices).
void check_mesh(const PolyMesh& mesh);
void check_mesh(const MeshView& mesh);

struct MeshSummary {
  uint64_t vertices = 0, faces = 0, triangles = 0, quads = 0, ngons = 0;
  uint64_t fan_triangles = 0;       // after fan triangulation
  uint64_t degenerate_faces = 0;    // faces with zero area or a repeated index
  uint64_t nonfinite_vertices = 0;  // NaN/Inf positions (faces using them are skipped at build)
  Box3f bounds;
};
MeshSummary summarize(const PolyMesh& mesh);

// Loads a mesh file (.obj, .ply, .gltf, .glb, any of them with .xz) or makes a procedural scene
// ("terrain:N", "torus:N", "canyon:N"). Throws slim::Error with file, line or byte offset and
// the reason on malformed input; the result passes check_mesh().
PolyMesh load(const std::string& path_or_scene);

// `mesh` with its faces in `order`: face i of the result is face order[i] of `mesh`, with its
// corners, normal and uv indices and object; positions, normals, uvs and object names unchanged.
// Throws slim::Error unless `order` holds each face of `mesh` once (cluster_face_order in
// slimrt/clusters.h gives an order that makes the cluster configurations smaller).
PolyMesh reorder_faces(const PolyMesh& mesh, std::span<const uint32_t> order);

// Writes `mesh` to `path` as a Wavefront OBJ: positions (and normals, uvs) with 9 significant
// digits, so that load() reads back the same floats; faces with their corners, as v, v/t, v//n or
// v/t/n; objects as `o` lines by name. load() then gives the same positions, faces and attribute
// values, with two differences: per-vertex normals and uvs come back per corner, and objects are
// numbered in order of first appearance (one object per name; a name's control characters become
// '_', an empty or missing name `objectN`). Throws slim::Error for a NaN or Inf coordinate (OBJ
// holds finite numbers). Written atomically (slimrt/output.h): complete or absent.
void save_obj(const PolyMesh& mesh, const std::string& path);

// True if the name is a procedural scene name (kind:N).
bool is_procedural(const std::string& name);
// Procedural scenes (the benchmark's): deterministic in (n, seed), all quads.
PolyMesh make_terrain(int n, uint32_t seed = 1);  // n x n quads heightfield, fractal noise
PolyMesh make_torus(int n, uint32_t seed = 1);    // n x n/2 quads displaced torus (closed)
PolyMesh make_canyon(int n, uint32_t seed = 1);   // n x n quads, steep ridged noise
// An icosahedron subdivided `levels` times (20 * 4^levels triangles, levels 0..10), its vertices
// on the unit sphere moved radially by up to +-jitter; closed, welded, wound outward.
PolyMesh make_sphere(int levels, float jitter = 0.0f, uint32_t seed = 1);

}  // namespace slim
