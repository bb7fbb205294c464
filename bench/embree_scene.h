// The Embree 3 baseline of docs/benchmark.md ("Embree anchors"): the same input meshes,
// triangulated exactly as slimrt does, behind the same intersect()/occluded() interface as
// slim::Scene, so that slim::trace_path and the benchmark loops run unchanged on either.
//
//   std::vector<const slim::PolyMesh*> meshes = {&mesh};
//   slim::bench::EmbreeScene scene(meshes, "embree-tri");   // throws slim::Error
//   slim::Hit hit = scene.intersect(ray);                     // thread-safe, const
//
// Configurations:
//   embree-tri          triangle mesh, default scene flags, RTC_BUILD_QUALITY_MEDIUM
//   embree-tri-compact  the same with RTC_SCENE_FLAG_COMPACT | RTC_SCENE_FLAG_ROBUST
//   embree-quad         RTC_GEOMETRY_TYPE_QUAD; only when every face of every mesh is a quad
//   embree-quad-pairs   RTC_GEOMETRY_TYPE_QUAD over slimrt's triangle pairs (slim::pair_quads per
//                       mesh: bvh8-pairs' pairs for a single mesh), unpaired triangles as
//                       (v0, v1, v2, v2): what Embree's own quad leaves make of the same pairs;
//                       any mesh
//   embree-grid         RTC_GEOMETRY_TYPE_GRID; only for "grid scenes" (see below)
// A configuration that does not apply throws slim::NotApplicable("<config>: does not apply:
// <why>").
//
// Triangulation matches slimrt's fan (v0,v1,v2), (v0,v2,v3), ... per face; faces with a NaN/Inf
// vertex are skipped. Quads are handed to Embree rotated to (v1,v2,v3,v0), because Embree splits a
// quad (a0,a1,a2,a3) along a1-a3 into (a0,a1,a3) and (a2,a3,a1): the rotation puts the split on
// v0-v2, the fan's diagonal. Hits report geomID = mesh index, primID = INPUT face index, t, the
// geometric normal Ng (orientation of the fan triangle, not normalized) and u, v = barycentric
// weights of the 2nd and 3rd vertex of the fan triangle that was hit (for quads and grids they are
// converted from Embree's quad/grid parametrization).
//
// Grid scenes: every mesh is a regular lattice of quads, face j*nx+i having the corners
// L(i,j), L(i+1,j), L(i+1,j+1), L(i,j+1), with either L(i,j) = j*(nx+1)+i over (nx+1)x(ny+1)
// vertices (terrain:N, canyon:N) or L(i,j) = (j mod ny)*nx + (i mod nx) over nx x ny vertices,
// periodic in both directions (torus:N, N x N/2). Embree grids are not periodic, so the grid vertex
// buffer holds the (nx+1)x(ny+1) lattice with the torus seam vertices duplicated (bit-identical
// copies, so the seam stays watertight; the copy costs (nx+ny+1) vertices more than the input).
// Embree splits a grid cell (x,y),(x+1,y),(x+1,y+1),(x,y+1) along (x+1,y)-(x,y+1): to get the fan's
// diagonal L(i,j)-L(i+1,j+1) the buffer stores the lattice mirrored in x (grid column x holds
// lattice column nx-x). The lattice is cut into RTCGrid records of at most 32767 vertices a side
// (neighbours share their border row/column), all reading the one vertex buffer.
//
// Memory (docs/benchmark.md): bvh_bytes = the bytes Embree's device memory monitor reports, net,
// after rtcCommitScene (BVH nodes, Embree's own leaf/primitive copies, allocator blocks);
// geometry_bytes = the shared vertex, index and RTCGrid buffers Embree reads (the monitor does not
// see shared buffers), vertex buffers including their 16 bytes of end padding; other_bytes = the
// Embree primID -> input face table (absent when the mapping is the identity; for embree-quad-pairs
// the two faces and corner bytes of each quad).
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "slimrt/scene.h"

namespace slim::bench {

class EmbreeScene {
 public:
  // Builds `config` over the meshes (mesh i becomes geomID i). Throws slim::Error for an unknown
  // configuration, a configuration that does not apply ("does not apply: ..."), malformed meshes
  // (slim::check_mesh) and Embree errors. Builds use the calling thread's TBB arena.
  EmbreeScene(const std::vector<const PolyMesh*>& meshes, const std::string& config);
  ~EmbreeScene();
  EmbreeScene(EmbreeScene&&) noexcept;
  EmbreeScene& operator=(EmbreeScene&&) noexcept;

  // Closest hit in (ray.tnear, ray.tfar]; an invalid Hit on a miss. Thread-safe. Rays with a NaN
  // or zero direction, NaN origin or tnear > tfar never hit (as slim::Scene).
  Hit intersect(const Ray& ray) const;
  // Any hit. Thread-safe.
  bool occluded(const Ray& ray) const;

  const std::string& config() const;
  MemoryStats memory() const;    // see the header comment; triangles = fan triangles of the input
  double build_seconds() const;  // buffer set-up + rtcCommitScene (not device creation)
  Box3f bounds() const;          // Embree's scene bounds

  // "embree-tri", "embree-tri-compact", "embree-quad", "embree-quad-pairs", "embree-grid".
  static const std::vector<std::string>& config_names();
  static bool is_config(const std::string& name);
  // The widest kernels Embree selected on this CPU: "avx512" when it supports native 16-wide
  // packets, else "avx2/avx/sse" (Embree picks its ISA at run time, unlike slimrt).
  static std::string kernel_isa();

  struct Impl;

 private:
  std::unique_ptr<Impl> impl_;
};

// Regular quad lattice of a mesh (see "Grid scenes" above), or nx = 0 if the mesh is not one.
struct QuadLattice {
  uint32_t nx = 0, ny = 0;  // cells
  bool periodic = false;    // torus layout: nx x ny vertices, wrapped in both directions
  bool valid() const { return nx != 0; }
};
QuadLattice detect_quad_lattice(const PolyMesh& mesh);

// Sets FTZ and DAZ in the MXCSR of the calling thread for its lifetime and restores the previous
// mode afterwards. Embree asks every thread that traces rays to set both; the benchmark sets them
// in every worker task for slimrt and Embree alike.
class DenormalsAreZero {
 public:
  DenormalsAreZero();
  ~DenormalsAreZero();
  DenormalsAreZero(const DenormalsAreZero&) = delete;
  DenormalsAreZero& operator=(const DenormalsAreZero&) = delete;

 private:
  unsigned saved_;
};

}  // namespace slim::bench
