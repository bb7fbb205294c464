// The meshes a build reads, as views (MeshView, slimrt/mesh.h): made from the PolyMesh or MeshView
// pointers of the public entry points, so that every builder reads one type and a PolyMesh is
// read in place like any other view.
#pragma once

#include <initializer_list>
#include <vector>

#include "slimrt/mesh.h"

namespace slim {

class MeshList {
 public:
  MeshList() = default;
  // Views of the meshes (a null pointer stays null: the builds refuse it by name).
  MeshList(const std::vector<const PolyMesh*>& meshes) { add(meshes.begin(), meshes.end()); }
  MeshList(std::initializer_list<const PolyMesh*> meshes) { add(meshes.begin(), meshes.end()); }
  MeshList(const std::vector<const MeshView*>& meshes) : ptrs_(meshes) {}
  MeshList(std::initializer_list<const MeshView*> meshes) : ptrs_(meshes) {}
  // ptrs_ points into own_: moving keeps own_'s buffer, copying would not.
  MeshList(const MeshList&) = delete;
  MeshList& operator=(const MeshList&) = delete;
  MeshList(MeshList&&) = default;
  MeshList& operator=(MeshList&&) = default;

  size_t size() const { return ptrs_.size(); }
  bool empty() const { return ptrs_.empty(); }
  const MeshView* operator[](size_t i) const { return ptrs_[i]; }
  auto begin() const { return ptrs_.begin(); }
  auto end() const { return ptrs_.end(); }
  const std::vector<const MeshView*>& pointers() const { return ptrs_; }

 private:
  template <class It>
  void add(It first, It last) {
    own_.reserve(size_t(last - first));
    for (; first != last; ++first) {
      if (*first) own_.emplace_back(**first);
      ptrs_.push_back(*first ? &own_.back() : nullptr);
    }
  }
  std::vector<MeshView> own_;  // the views of PolyMesh input
  std::vector<const MeshView*> ptrs_;
};

}  // namespace slim
