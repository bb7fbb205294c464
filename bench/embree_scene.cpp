// The Embree 3 baseline (docs/benchmark.md, "Embree anchors"). See embree_scene.h for what each
// configuration builds, how faces map back, and how memory is counted.
#include "embree_scene.h"

#include <embree3/rtcore.h>
#include <xmmintrin.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <chrono>
#include <cmath>
#include <mutex>

#include "slimrt/pairing.h"

namespace slim::bench {

namespace {

enum class Kind { Triangles, Quads, QuadPairs, Grids };

// Embree grids hold at most 32767 vertices a side; neighbouring records share a border, so a
// record spans at most 32766 cells.
constexpr uint32_t kMaxGridCells = 32766;

// Per geometry (= input mesh) data needed to turn an Embree hit into a slimrt one.
struct GeomInfo {
  Kind kind = Kind::Triangles;
  std::vector<uint32_t> face_of_prim;  // Embree primID -> input face; empty = identity
  // QuadPairs: per quad, the input faces of its two triangles and, per triangle, the quad corners
  // of its 2nd and 3rd input corners (2 bits each: corner1 | corner2 << 2), bit 4 set if Embree's
  // order of the triangle reverses its input winding (Ng is negated).
  std::vector<std::array<uint32_t, 2>> pair_faces;
  std::vector<std::array<uint8_t, 2>> pair_corners;
  // Grids: the lattice and how it is cut into records (row-major over tiles of kMaxGridCells).
  uint32_t nx = 0, ny = 0, tiles_x = 0;
};

// The device memory monitor: net bytes Embree has allocated through its allocators.
bool memory_monitor(void* user, ssize_t bytes, bool /*post*/) {
  static_cast<std::atomic<int64_t>*>(user)->fetch_add(int64_t(bytes), std::memory_order_relaxed);
  return true;
}

const char* error_name(RTCError e) {
  switch (e) {
    case RTC_ERROR_NONE:
      return "no error";
    case RTC_ERROR_UNKNOWN:
      return "unknown error";
    case RTC_ERROR_INVALID_ARGUMENT:
      return "invalid argument";
    case RTC_ERROR_INVALID_OPERATION:
      return "invalid operation";
    case RTC_ERROR_OUT_OF_MEMORY:
      return "out of memory";
    case RTC_ERROR_UNSUPPORTED_CPU:
      return "unsupported CPU";
    case RTC_ERROR_CANCELLED:
      return "cancelled";
  }
  return "?";
}

// u, v of the fan triangle of a quad face v0..v3 hit at face-local (s, t), where
// p = v0 + s (v1 - v0) + t (v3 - v0) on each triangle: (v0,v1,v2) holds t <= s, (v0,v2,v3) t >= s.
SLIM_INLINE void fan_uv(float s, float t, Hit& hit) {
  if (t <= s) {
    hit.u = s - t;
    hit.v = t;
  } else {
    hit.u = s;
    hit.v = t - s;
  }
}

}  // namespace

struct EmbreeScene::Impl {
  std::string config;
  Kind kind = Kind::Triangles;
  RTCDevice device = nullptr;
  RTCScene scene = nullptr;
  std::atomic<int64_t> monitor_bytes{0};
  std::vector<GeomInfo> geoms;
  // Shared buffers Embree reads; they live as long as the scene.
  std::vector<std::vector<float>> vertex_buffers;
  std::vector<std::vector<uint32_t>> index_buffers;
  std::vector<std::vector<RTCGrid>> grid_buffers;
  MemoryStats mem;
  double build_s = 0;
  Box3f box;
  std::mutex error_mutex;
  std::string first_error;

  ~Impl() {
    if (scene) rtcReleaseScene(scene);
    if (device) rtcReleaseDevice(device);
  }

  void check(const char* what) {
    RTCError e = rtcGetDeviceError(device);
    std::string msg;
    {
      std::lock_guard<std::mutex> lock(error_mutex);
      msg = first_error;
    }
    if (e != RTC_ERROR_NONE || !msg.empty())
      throw Error(config + ": Embree error in " + what + ": " +
                  (msg.empty() ? std::string(error_name(e)) : msg));
  }

  // A copy of `count` float3 positions with 16 bytes of padding behind the last one (Embree reads
  // vertices with 16-byte loads).
  std::vector<float>& add_vertex_buffer(size_t count) {
    vertex_buffers.emplace_back(3 * count + 4, 0.0f);
    mem.geometry_bytes += vertex_buffers.back().size() * sizeof(float);
    return vertex_buffers.back();
  }

  void attach(RTCGeometry geom, uint32_t geom_id) {
    rtcSetGeometryBuildQuality(geom, RTC_BUILD_QUALITY_MEDIUM);
    rtcCommitGeometry(geom);
    rtcAttachGeometryByID(scene, geom, geom_id);
    rtcReleaseGeometry(geom);
    check("geometry set-up");
  }

  // The mesh's vertices and `idx` (`per` = 3 indices per triangle, or 4 per quad) as shared
  // buffers of an Embree triangle or quad geometry, attached as geom_id.
  void add_indexed(const PolyMesh& m, std::vector<uint32_t>&& idx, unsigned per, uint32_t geom_id) {
    std::vector<float>& vb = add_vertex_buffer(m.positions.size());
    std::copy_n(&m.positions[0].x, 3 * m.positions.size(), vb.data());
    const size_t prims = idx.size() / per;
    index_buffers.push_back(std::move(idx));
    mem.geometry_bytes += index_buffers.back().size() * sizeof(uint32_t);
    RTCGeometry g =
        rtcNewGeometry(device, per == 3 ? RTC_GEOMETRY_TYPE_TRIANGLE : RTC_GEOMETRY_TYPE_QUAD);
    rtcSetSharedGeometryBuffer(g, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3, vb.data(), 0,
                               3 * sizeof(float), m.positions.size());
    rtcSetSharedGeometryBuffer(g, RTC_BUFFER_TYPE_INDEX, 0,
                               per == 3 ? RTC_FORMAT_UINT3 : RTC_FORMAT_UINT4,
                               index_buffers.back().data(), 0, per * sizeof(uint32_t), prims);
    attach(g, geom_id);
  }

  void add_triangles(const PolyMesh& m, uint32_t geom_id);
  void add_quads(const PolyMesh& m, uint32_t geom_id);
  void add_quad_pairs(const PolyMesh& m, uint32_t geom_id);
  void add_grid(const PolyMesh& m, const QuadLattice& lat, uint32_t geom_id);
};

void EmbreeScene::Impl::add_triangles(const PolyMesh& m, uint32_t geom_id) {
  GeomInfo& info = geoms[geom_id];
  info.kind = Kind::Triangles;
  std::vector<uint32_t> idx;
  idx.reserve(3 * m.fan_triangle_count());
  std::vector<uint32_t> faces;
  faces.reserve(m.fan_triangle_count());
  bool identity = true;  // one triangle per face, none skipped
  uint64_t c = 0;
  for (uint32_t f = 0; f < m.face_sizes.size(); ++f) {
    const uint32_t n = m.face_sizes[f];
    const uint32_t* v = &m.face_indices[c];
    c += n;
    bool finite = true;
    for (uint32_t k = 0; k < n; ++k) finite = finite && is_finite(m.positions[v[k]]);
    if (!finite) {
      identity = false;
      continue;
    }
    identity = identity && n == 3;
    for (uint32_t k = 1; k + 1 < n; ++k) {
      idx.insert(idx.end(), {v[0], v[k], v[k + 1]});
      faces.push_back(f);
    }
  }
  if (faces.empty()) return;
  if (!identity) {
    info.face_of_prim = std::move(faces);
    mem.other_bytes += info.face_of_prim.size() * sizeof(uint32_t);
  }
  add_indexed(m, std::move(idx), 3, geom_id);
}

void EmbreeScene::Impl::add_quads(const PolyMesh& m, uint32_t geom_id) {
  GeomInfo& info = geoms[geom_id];
  info.kind = Kind::Quads;
  std::vector<uint32_t> idx;
  idx.reserve(4 * m.face_count());
  std::vector<uint32_t> faces;
  faces.reserve(m.face_count());
  bool identity = true;  // no face skipped
  for (uint32_t f = 0; f < m.face_sizes.size(); ++f) {
    const uint32_t* v = &m.face_indices[4 * size_t(f)];  // all faces are quads (checked)
    bool finite = true;
    for (uint32_t k = 0; k < 4; ++k) finite = finite && is_finite(m.positions[v[k]]);
    if (!finite) {
      identity = false;
      continue;
    }
    // Rotated so that Embree's a1-a3 split is the fan's v0-v2 diagonal (see the header).
    idx.insert(idx.end(), {v[1], v[2], v[3], v[0]});
    faces.push_back(f);
  }
  if (faces.empty()) return;
  if (!identity) {
    info.face_of_prim = std::move(faces);
    mem.other_bytes += info.face_of_prim.size() * sizeof(uint32_t);
  }
  add_indexed(m, std::move(idx), 4, geom_id);
}

// The triangle pairs of slimrt's pairing (slim::pair_quads with the default options) as Embree
// quads, lone triangles as (v0, v1, v2, v2). Each mesh is paired on its own; bvh8-pairs pairs all
// meshes in one call (pairs never span two meshes, but its pre-scan decides for all of them at
// once), so the pairs are bvh8-pairs' for a single mesh. The pairing's time is part of the build
// time, as in bvh8-pairs.
void EmbreeScene::Impl::add_quad_pairs(const PolyMesh& m, uint32_t geom_id) {
  GeomInfo& info = geoms[geom_id];
  info.kind = Kind::QuadPairs;
  const std::vector<PairedQuad> quads = pair_quads(m);
  if (quads.empty()) return;
  std::vector<uint32_t> idx;
  idx.reserve(4 * quads.size());
  info.pair_faces.reserve(quads.size());
  info.pair_corners.reserve(quads.size());
  // Position of each quad corner in Embree's order of triangle h: (a0, a1, a3), (a2, a3, a1).
  static constexpr int kPos[2][4] = {{0, 1, -1, 2}, {-1, 2, 0, 1}};
  auto code = [](const PairedQuad& q, int h) {
    const int d = (kPos[h][q.corner[h][1]] - kPos[h][q.corner[h][0]] + 3) % 3;
    return uint8_t(q.corner[h][1] | q.corner[h][2] << 2 | (d == 1 ? 0 : 16));
  };
  for (const PairedQuad& q : quads) {
    idx.insert(idx.end(), {q.v[0], q.v[1], q.v[2], q.v[3]});
    info.pair_faces.push_back({q.face[0], q.face[1]});
    info.pair_corners.push_back({code(q, 0), q.face[1] == kInvalidID ? uint8_t(0) : code(q, 1)});
  }
  mem.other_bytes += quads.size() * (sizeof(info.pair_faces[0]) + sizeof(info.pair_corners[0]));

  add_indexed(m, std::move(idx), 4, geom_id);
}

void EmbreeScene::Impl::add_grid(const PolyMesh& m, const QuadLattice& lat, uint32_t geom_id) {
  GeomInfo& info = geoms[geom_id];
  info.kind = Kind::Grids;
  info.nx = lat.nx;
  info.ny = lat.ny;
  const size_t side_x = size_t(lat.nx) + 1, side_y = size_t(lat.ny) + 1;
  // Grid vertex (x, y) = lattice vertex (nx - x, y), seam vertices duplicated for the torus.
  std::vector<float>& vb = add_vertex_buffer(side_x * side_y);
  const size_t stride = lat.periodic ? lat.nx : side_x;
  for (size_t y = 0; y < side_y; ++y) {
    const size_t j = lat.periodic && y == lat.ny ? 0 : y;
    for (size_t x = 0; x < side_x; ++x) {
      size_t i = lat.nx - x;
      if (lat.periodic && i == lat.nx) i = 0;
      const Vec3f p = m.positions[j * stride + i];
      float* out = &vb[3 * (y * side_x + x)];
      out[0] = p.x;
      out[1] = p.y;
      out[2] = p.z;
    }
  }
  info.tiles_x = (lat.nx + kMaxGridCells - 1) / kMaxGridCells;
  const uint32_t tiles_y = (lat.ny + kMaxGridCells - 1) / kMaxGridCells;
  std::vector<RTCGrid> grids;
  for (uint32_t ty = 0; ty < tiles_y; ++ty)
    for (uint32_t tx = 0; tx < info.tiles_x; ++tx) {
      const uint32_t x0 = tx * kMaxGridCells, y0 = ty * kMaxGridCells;
      RTCGrid r;
      r.startVertexID = uint32_t(size_t(y0) * side_x + x0);
      r.stride = uint32_t(side_x);
      r.width = uint16_t(std::min(kMaxGridCells, lat.nx - x0) + 1);
      r.height = uint16_t(std::min(kMaxGridCells, lat.ny - y0) + 1);
      grids.push_back(r);
    }
  grid_buffers.push_back(std::move(grids));
  mem.geometry_bytes += grid_buffers.back().size() * sizeof(RTCGrid);

  RTCGeometry g = rtcNewGeometry(device, RTC_GEOMETRY_TYPE_GRID);
  rtcSetSharedGeometryBuffer(g, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3, vb.data(), 0,
                             3 * sizeof(float), side_x * side_y);
  rtcSetSharedGeometryBuffer(g, RTC_BUFFER_TYPE_GRID, 0, RTC_FORMAT_GRID,
                             grid_buffers.back().data(), 0, sizeof(RTCGrid),
                             grid_buffers.back().size());
  attach(g, geom_id);
}

QuadLattice detect_quad_lattice(const PolyMesh& m) {
  const size_t faces = m.face_count();
  if (faces == 0 || m.face_indices.size() != 4 * faces) return {};
  for (uint32_t n : m.face_sizes)
    if (n != 4) return {};
  const uint32_t* f0 = m.face_indices.data();
  if (f0[0] != 0 || f0[1] != 1 || f0[3] <= 1) return {};
  // Face 0 = (L(0,0), L(1,0), L(1,1), L(0,1)); L(0,1) is the row stride.
  const uint64_t stride = f0[3];
  for (bool periodic : {false, true}) {
    const uint64_t nx = periodic ? stride : stride - 1;
    if (nx == 0 || faces % nx != 0 || (periodic && nx < 3)) continue;
    const uint64_t ny = faces / nx;
    if (periodic && ny < 3) continue;
    const uint64_t verts = periodic ? nx * ny : (nx + 1) * (ny + 1);
    if (verts != m.positions.size() || nx > 0xffffffffull || ny > 0xffffffffull) continue;
    auto L = [&](uint64_t i, uint64_t j) {
      if (periodic) {
        if (i == nx) i = 0;
        if (j == ny) j = 0;
      }
      return uint32_t(j * stride + i);
    };
    bool ok = true;
    const uint32_t* f = f0;
    for (uint64_t j = 0; ok && j < ny; ++j)
      for (uint64_t i = 0; i < nx; ++i, f += 4)
        if (f[0] != L(i, j) || f[1] != L(i + 1, j) || f[2] != L(i + 1, j + 1) ||
            f[3] != L(i, j + 1)) {
          ok = false;
          break;
        }
    if (ok) return {uint32_t(nx), uint32_t(ny), periodic};
  }
  return {};
}

const std::vector<std::string>& EmbreeScene::config_names() {
  static const std::vector<std::string> names = {"embree-tri", "embree-tri-compact", "embree-quad",
                                                 "embree-quad-pairs", "embree-grid"};
  return names;
}

bool EmbreeScene::is_config(const std::string& name) {
  const auto& n = config_names();
  return std::find(n.begin(), n.end(), name) != n.end();
}

std::string EmbreeScene::kernel_isa() {
  RTCDevice d = rtcNewDevice("verbose=0");
  if (!d) return "unknown";
  const bool avx512 = rtcGetDeviceProperty(d, RTC_DEVICE_PROPERTY_NATIVE_RAY16_SUPPORTED) != 0;
  rtcReleaseDevice(d);
  return avx512 ? "avx512" : "avx2/avx/sse";
}

EmbreeScene::EmbreeScene(const std::vector<const PolyMesh*>& meshes, const std::string& config) {
  if (!is_config(config)) throw Error("unknown Embree configuration '" + config + "'");
  auto impl = std::make_unique<Impl>();
  impl->config = config;
  impl->kind = config == "embree-quad"         ? Kind::Quads
               : config == "embree-quad-pairs" ? Kind::QuadPairs
               : config == "embree-grid"       ? Kind::Grids
                                               : Kind::Triangles;

  // Applicability first: nothing is built for a configuration that does not apply.
  uint64_t triangles = 0;
  std::vector<QuadLattice> lattices(meshes.size());
  for (size_t g = 0; g < meshes.size(); ++g) {
    if (!meshes[g]) throw Error("EmbreeScene: null mesh");
    const PolyMesh& m = *meshes[g];
    check_mesh(m);
    triangles += m.fan_triangle_count();
    if (impl->kind == Kind::Quads) {
      uint64_t non_quads = 0;
      for (uint32_t n : m.face_sizes) non_quads += n != 4;
      if (non_quads)
        throw NotApplicable(config + ": does not apply: " + std::to_string(non_quads) +
                            " non-quad faces" +
                            (meshes.size() > 1 ? " in mesh " + std::to_string(g) : ""));
    } else if (impl->kind == Kind::Grids) {
      lattices[g] = detect_quad_lattice(m);
      if (!lattices[g].valid())
        throw NotApplicable(config + ": does not apply: mesh " +
                            (m.name.empty() ? std::to_string(g) : "'" + m.name + "'") +
                            " is not a regular quad grid");
      uint64_t nonfinite = 0;
      for (const Vec3f& p : m.positions) nonfinite += !is_finite(p);
      if (nonfinite)
        throw NotApplicable(config + ": does not apply: " + std::to_string(nonfinite) +
                            " non-finite grid vertices");
    }
  }
  if (meshes.size() > 0xffffffffull) throw Error("EmbreeScene: too many meshes");
  impl->mem.triangles = triangles;
  impl->geoms.resize(meshes.size());

  impl->device = rtcNewDevice("verbose=0");
  if (!impl->device)
    throw Error(config + ": rtcNewDevice failed: " + error_name(rtcGetDeviceError(nullptr)));
  rtcSetDeviceErrorFunction(
      impl->device,
      [](void* user, RTCError code, const char* str) {
        Impl* self = static_cast<Impl*>(user);
        std::lock_guard<std::mutex> lock(self->error_mutex);
        if (self->first_error.empty())
          self->first_error = std::string(error_name(code)) + (str ? std::string(": ") + str : "");
      },
      impl.get());
  rtcSetDeviceMemoryMonitorFunction(impl->device, memory_monitor, &impl->monitor_bytes);

  const auto t0 = std::chrono::steady_clock::now();
  const int64_t monitor_before = impl->monitor_bytes.load();
  impl->scene = rtcNewScene(impl->device);
  impl->check("rtcNewScene");
  rtcSetSceneFlags(impl->scene, config == "embree-tri-compact"
                                    ? RTC_SCENE_FLAG_COMPACT | RTC_SCENE_FLAG_ROBUST
                                    : RTC_SCENE_FLAG_NONE);
  rtcSetSceneBuildQuality(impl->scene, RTC_BUILD_QUALITY_MEDIUM);
  for (uint32_t g = 0; g < meshes.size(); ++g) {
    switch (impl->kind) {
      case Kind::Triangles:
        impl->add_triangles(*meshes[g], g);
        break;
      case Kind::Quads:
        impl->add_quads(*meshes[g], g);
        break;
      case Kind::QuadPairs:
        impl->add_quad_pairs(*meshes[g], g);
        break;
      case Kind::Grids:
        impl->add_grid(*meshes[g], lattices[g], g);
        break;
    }
  }
  rtcCommitScene(impl->scene);
  impl->check("rtcCommitScene");
  impl->build_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  impl->mem.bvh_bytes = uint64_t(std::max<int64_t>(0, impl->monitor_bytes.load() - monitor_before));

  RTCBounds b;
  rtcGetSceneBounds(impl->scene, &b);
  if (b.lower_x <= b.upper_x)
    impl->box = Box3f({b.lower_x, b.lower_y, b.lower_z}, {b.upper_x, b.upper_y, b.upper_z});
  impl_ = std::move(impl);
}

EmbreeScene::~EmbreeScene() = default;
EmbreeScene::EmbreeScene(EmbreeScene&&) noexcept = default;
EmbreeScene& EmbreeScene::operator=(EmbreeScene&&) noexcept = default;

namespace {

// slimrt's ray validity rules (slim::Ray): such rays never hit.
SLIM_INLINE bool valid_ray(const Ray& r) {
  return is_finite(r.org) && is_finite(r.dir) && r.tnear <= r.tfar &&
         !(r.dir.x == 0.0f && r.dir.y == 0.0f && r.dir.z == 0.0f) &&
         std::max(r.tnear, 0.0f) <= r.tfar;
}

SLIM_INLINE void fill_ray(const Ray& r, RTCRay& out) {
  out.org_x = r.org.x;
  out.org_y = r.org.y;
  out.org_z = r.org.z;
  out.tnear = std::max(r.tnear, 0.0f);
  out.dir_x = r.dir.x;
  out.dir_y = r.dir.y;
  out.dir_z = r.dir.z;
  out.time = 0.0f;
  out.tfar = r.tfar;
  out.mask = 0xffffffffu;
  out.id = 0;
  out.flags = 0;
}

}  // namespace

Hit EmbreeScene::intersect(const Ray& ray) const {
  Hit hit;
  if (!valid_ray(ray)) return hit;
  RTCIntersectContext ctx;
  rtcInitIntersectContext(&ctx);
  RTCRayHit rh;
  fill_ray(ray, rh.ray);
  rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
  rh.hit.instID[0] = RTC_INVALID_GEOMETRY_ID;
  rtcIntersect1(impl_->scene, &ctx, &rh);
  if (rh.hit.geomID == RTC_INVALID_GEOMETRY_ID) return hit;

  const GeomInfo& g = impl_->geoms[rh.hit.geomID];
  hit.t = rh.ray.tfar;
  hit.Ng = Vec3f(rh.hit.Ng_x, rh.hit.Ng_y, rh.hit.Ng_z);
  hit.geomID = rh.hit.geomID;
  const uint32_t prim = rh.hit.primID;
  switch (impl_->kind) {
    case Kind::Triangles:
      hit.primID = g.face_of_prim.empty() ? prim : g.face_of_prim[prim];
      hit.u = rh.hit.u;
      hit.v = rh.hit.v;
      break;
    case Kind::Quads:
      // Embree's quad (a0..a3) = (v1,v2,v3,v0): p = a0 + u (a1-a0) + v (a3-a0), i.e. face-local
      // s = 1 - v, t = u.
      hit.primID = g.face_of_prim.empty() ? prim : g.face_of_prim[prim];
      hit.kind = PrimKind::Quad;
      fan_uv(1.0f - rh.hit.v, rh.hit.u, hit);
      break;
    case Kind::QuadPairs: {
      // Embree splits quad (a0..a3) into (a0, a1, a3), where p = a0 + u (a1 - a0) + v (a3 - a0),
      // and (a2, a3, a1), reported as u = 1 - (weight of a3), v = 1 - (weight of a1): the first
      // triangle where u + v <= 1.
      const int h = rh.hit.u + rh.hit.v > 1.0f;
      float w[4];
      if (h == 0) {
        w[0] = 1.0f - rh.hit.u - rh.hit.v, w[1] = rh.hit.u, w[2] = 0.0f, w[3] = rh.hit.v;
      } else {
        w[0] = 0.0f, w[1] = 1.0f - rh.hit.v, w[2] = rh.hit.u + rh.hit.v - 1.0f,
        w[3] = 1.0f - rh.hit.u;
      }
      const uint8_t c = g.pair_corners[prim][h];
      hit.primID = g.pair_faces[prim][h];
      hit.kind = g.pair_faces[prim][1] == kInvalidID ? PrimKind::Triangle : PrimKind::Pair;
      hit.u = w[c & 3];
      hit.v = w[(c >> 2) & 3];
      if (c & 16) hit.Ng = -hit.Ng;
      break;
    }
    case Kind::Grids: {
      // u, v span the whole record; cell (cx, cy) of the record, then the mirrored lattice cell.
      const uint32_t tx = prim % g.tiles_x, ty = prim / g.tiles_x;
      const uint32_t x0 = tx * kMaxGridCells, y0 = ty * kMaxGridCells;
      const uint32_t cells_x = std::min(kMaxGridCells, g.nx - x0);
      const uint32_t cells_y = std::min(kMaxGridCells, g.ny - y0);
      const float gu = rh.hit.u * float(cells_x), gv = rh.hit.v * float(cells_y);
      const uint32_t cx = uint32_t(std::clamp(gu, 0.0f, float(cells_x - 1)));
      const uint32_t cy = uint32_t(std::clamp(gv, 0.0f, float(cells_y - 1)));
      const uint32_t i = g.nx - 1 - (x0 + cx), j = y0 + cy;
      hit.primID = j * g.nx + i;
      hit.kind = PrimKind::Grid;
      // Grid cell corners (a0..a3) = face (v1,v0,v3,v2): face-local s = 1 - cell u, t = cell v.
      fan_uv(1.0f - std::clamp(gu - float(cx), 0.0f, 1.0f), std::clamp(gv - float(cy), 0.0f, 1.0f),
             hit);
      hit.Ng = -hit.Ng;  // the mirrored buffer reverses the winding
      break;
    }
  }
  return hit;
}

bool EmbreeScene::occluded(const Ray& ray) const {
  if (!valid_ray(ray)) return false;
  RTCIntersectContext ctx;
  rtcInitIntersectContext(&ctx);
  RTCRay r;
  fill_ray(ray, r);
  rtcOccluded1(impl_->scene, &ctx, &r);
  return r.tfar == -kInf;
}

const std::string& EmbreeScene::config() const { return impl_->config; }
MemoryStats EmbreeScene::memory() const { return impl_->mem; }
double EmbreeScene::build_seconds() const { return impl_->build_s; }
Box3f EmbreeScene::bounds() const { return impl_->box; }

DenormalsAreZero::DenormalsAreZero() : saved_(_mm_getcsr()) {
  _mm_setcsr(saved_ | _MM_FLUSH_ZERO_ON | 0x0040u /* DAZ */);
}
DenormalsAreZero::~DenormalsAreZero() { _mm_setcsr(saved_); }

}  // namespace slim::bench
