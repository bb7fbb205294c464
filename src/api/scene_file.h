// Scene files (README.md "Scene files"; Scene::save / Scene::open in slimrt/scene.h): the buffers a
// scene keeps, enumerated as named sections by one visitor that serves both directions. Saving
// reads each buffer and writes it as a 64-byte aligned section; opening points the scene's
// pointers (Leaf::Context pointers, the BVH arenas as AlignedBytes views) straight into the
// read-only mapping. Node data holds no pointers (NodeRef offsets are relative to the arenas), so
// nothing is relocated: only the contexts' pointers are set at open.
#pragma once

#include <cstdint>
#include <cstring>
#include <functional>
#include <string>
#include <type_traits>

#include "api/scene_impl.h"
#include "bvh/bvh8.h"

namespace slim {

class SectionVisitor {
 public:
  virtual ~SectionVisitor() = default;
  bool saving() const { return saving_; }

  // A buffer of `count` elements of `elem` bytes at `data`. Saving writes them; opening sets
  // `data` to the section in the mapping and `count` to its element count (the section's size
  // must be a multiple of elem, its element size must be elem).
  virtual void raw(const std::string& name, const void*& data, uint64_t& count, uint32_t elem) = 0;
  // A small fixed-size record: saving writes it, opening copies the section into it (the
  // section's size must be `size`).
  virtual void record(const std::string& name, void* p, uint32_t size) = 0;

  template <class T>
  void array(const std::string& name, const T*& data, uint64_t& count) {
    static_assert(std::is_trivially_copyable_v<T>);
    const void* d = data;
    raw(name, d, count, uint32_t(sizeof(T)));
    data = static_cast<const T*>(d);
  }
  template <class T>
  void pod(const std::string& name, T& v) {
    static_assert(std::is_trivially_copyable_v<T>);
    record(name, &v, uint32_t(sizeof(T)));
  }
  // A BVH arena: saved as is, opened as a view of the mapping.
  void arena(const std::string& name, AlignedBytes& a) {
    const void* d = a.data();
    uint64_t n = a.size();
    raw(name, d, n, 1);
    if (!saving_) a = AlignedBytes::view(static_cast<const uint8_t*>(d), n);
  }

 protected:
  bool saving_ = true;
};

// A scene's figures as a scene file records them (the file header; each chunk of a joined scene):
// memory, bounds, error bound, build time and input counts.
struct SceneFigures {
  uint64_t mem_geometry, mem_bvh, mem_other, mem_triangles;
  float bounds_lo[3], bounds_hi[3];
  double error_bound;
  double build_seconds;
  uint64_t input_faces, triangles, skipped_faces, primitives;
};
static_assert(sizeof(SceneFigures) == 104);
// The figures of a scene, and the scene given its saved figures (ray_setup from the bounds).
SceneFigures figures_of(const Scene::Impl& s);
void restore_figures(const SceneFigures& f, Scene::Impl& s);

// A bad reference found by the checks of an opened scene: the section, the byte offset inside
// it, and what is wrong. Scene::open turns it into a slim::Error with the file offset.
struct SectionFault {
  std::string section;
  uint64_t offset = 0;
  std::string what;
};

// The bounds-safe walk of Scene::open's structure check (OpenOptions::check_structure): every
// node reference (tag, offset, block count) inside its arena and aligned as the traversal's typed
// loads need (Node8 64 bytes, QNode8 8, CQNode8 4, leaf blocks 4), depth within the traversal
// stack, no node or leaf offset named twice (no shared subtrees, shared leaves or cycles; a leaf
// at another offset that overlaps one is bounds-checked block by block like any). Leaf blocks are
// handed to `block(offset)`, multi-leaves of layouts with data of their own to
// `multi(offset, children)` (offsets into the leaf arena, already checked to hold the block / the
// multi-leaf header: multileaf_header_bytes). A non-empty answer is what is wrong: the walk throws
// it as a SectionFault at that offset of the leaf arena. `prefix` names the sections ("" or
// "tris.").
struct BvhWalkHooks {
  std::function<std::string(uint64_t off)> block;
  std::function<std::string(uint64_t off, uint32_t children)> multi;  // layouts with own data
  uint32_t multileaf_header_bytes = sizeof(MultiLeaf8);  // MultiLeafBoxDecoder::header_bytes
  // Leaves and multi-leaves start at multiples of it (traverse.h leaf_align, at most 4).
  uint32_t leaf_align = 4;
};
// A leaf format's check answer as the walk takes it: leaves answer nullptr / an empty string for
// a good block, else what is wrong.
inline std::string fault_text(const char* what) { return what ? what : ""; }
inline std::string fault_text(std::string what) { return what; }
void walk_bvh_checked(const Bvh8& bvh, const std::string& prefix, const BvhWalkHooks& hooks);
// The cheap check every open runs: root reference and block size.
void check_bvh_root(const Bvh8& bvh, const std::string& prefix, uint32_t block_bytes,
                    uint32_t multileaf_header_bytes = sizeof(MultiLeaf8), uint32_t leaf_align = 4);

}  // namespace slim
