// The Python module `slimrt`: RaycastingScene with the names and conventions of Open3D's
// open3d.t.geometry.RaycastingScene (add_triangles, add_mesh, cast_rays, test_occlusions,
// count_intersections, create_rays_pinhole), over any slimrt configuration, plus memory() and
// stats(). Only the public API (slimrt/slimrt.h) is used. Open3D code runs unchanged:
// RaycastingScene(nthreads), add_triangles(mesh) of an Open3D mesh, open3d.core.Tensor inputs,
// and answers (slimrt.Array, numpy arrays) that have Tensor's numpy().
//
// Arrays: rays are read in place when they are float32 and C-contiguous (any other float dtype
// or layout is converted once); vertices and triangles are referenced, not copied, when they are
// float32 and uint32 (or non-negative int32) C-contiguous arrays: the scene keeps them alive and
// reads them when it builds (other dtypes and layouts are converted once into arrays it owns). Bad
// arrays raise TypeError (dtype) or ValueError (shape, NaN, index range) naming what was expected.
// The scene is built on the first query after geometry was added (as Open3D does); building and
// tracing run with the GIL released, rays in parallel with TBB. Python threads may query one
// scene at once and add geometry while others query (a query keeps the scene it started with).
#include <pybind11/eval.h>
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include <atomic>
#include <cmath>
#include <cstring>
#include <limits>
#include <memory>
#include <mutex>
#include <optional>
#include <sstream>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

#include "slimrt/analysis.h"
#include "slimrt/clusters.h"
#include "slimrt/slimrt.h"

namespace py = pybind11;

namespace {

constexpr uint32_t kInvalid = slim::kInvalidID;
// count_intersections stops after this many hits per ray unless told otherwise.
constexpr uint32_t kDefaultMaxHits = 1u << 16;

std::string shape_str(const py::array& a) {
  std::ostringstream s;
  s << "(";
  for (py::ssize_t i = 0; i < a.ndim(); ++i) s << (i ? ", " : "") << a.shape(i);
  if (a.ndim() == 1) s << ",";
  s << ")";
  return s.str();
}

std::string dtype_str(const py::array& a) { return py::str(a.dtype()).cast<std::string>(); }

// Open3D tensors and other array-likes: anything numpy can view; objects with a numpy() method
// (open3d.core.Tensor, whose numpy.asarray would be an array of objects) through it.
py::array as_array(py::handle obj) {
  py::object o = py::reinterpret_borrow<py::object>(obj);
  if (!py::isinstance<py::array>(o) && py::hasattr(o, "numpy") &&
      PyCallable_Check(o.attr("numpy").ptr()))
    o = o.attr("numpy")();
  return py::module_::import("numpy").attr("asarray")(o).cast<py::array>();
}

// Whether a scene may keep a reference to `a` instead of a copy: its data is aligned for its
// element type and belongs to numpy (the chain of .base ends at an array owning its data), to an
// mmap (np.memmap: an mmap cannot be resized or closed while arrays view it) or to immutable
// bytes. Memory that other objects export (an Open3D Vector3dVector, a tensor's buffer) can be
// reallocated behind the scene's back, so it is copied.
bool can_reference(const py::array& a, size_t align) {
  if (reinterpret_cast<uintptr_t>(a.data()) % align != 0) return false;
  py::object base = a.attr("base");
  while (py::isinstance<py::array>(base)) base = base.attr("base");
  if (base.is_none() || py::isinstance<py::bytes>(base)) return true;
  return py::isinstance(base, py::module_::import("mmap").attr("mmap"));
}

// A C-contiguous copy of `a` as `dtype`, owned by the scene.
py::array owned_copy(const py::array& a, const char* dtype) {
  using namespace py::literals;
  return py::module_::import("numpy").attr("array")(a, "dtype"_a = dtype, "order"_a = "C",
                                                    "copy"_a = true);
}

// A float32 C-contiguous view of `obj` (no copy when it already is one). Float dtypes other than
// float32 are converted; anything else is a TypeError.
py::array_t<float, py::array::c_style> float_array(py::handle obj, const char* what,
                                                   const char* expected) {
  py::array a = as_array(obj);
  char kind = a.dtype().kind();
  if (kind != 'f')
    throw py::type_error(std::string(what) + ": expected a float32 array " + expected +
                         ", got dtype " + dtype_str(a));
  return py::array_t<float, py::array::c_style | py::array::forcecast>::ensure(a);
}

// Rays [..., 6] as float32 (ox, oy, oz, dx, dy, dz); the number of rays and the leading shape.
struct Rays {
  py::array_t<float, py::array::c_style> array;
  const float* data = nullptr;
  size_t count = 0;
  std::vector<py::ssize_t> shape;  // the leading dimensions
};

Rays get_rays(py::handle obj) {
  Rays r;
  r.array = float_array(obj, "rays", "of shape [..., 6] (ox, oy, oz, dx, dy, dz)");
  if (r.array.ndim() < 1 || r.array.shape(r.array.ndim() - 1) != 6)
    throw py::value_error("rays: expected shape [..., 6] (ox, oy, oz, dx, dy, dz), got shape " +
                          shape_str(r.array));
  r.count = 1;
  for (py::ssize_t i = 0; i + 1 < r.array.ndim(); ++i) {
    r.shape.push_back(r.array.shape(i));
    r.count *= size_t(r.array.shape(i));
  }
  r.data = r.array.data();
  return r;
}

// slimrt.Array: the numpy arrays slimrt returns, with Open3D Tensor's numpy() (returning the plain
// numpy array, no copy), so that Open3D code such as ans["t_hit"].numpy() runs unchanged.
py::handle array_type;  // set once by the module, kept for the interpreter's lifetime

py::object result(const py::array& a) { return a.attr("view")(array_type); }

template <class T>
py::array_t<T> output(const std::vector<py::ssize_t>& shape, std::vector<py::ssize_t> tail = {}) {
  std::vector<py::ssize_t> s = shape;
  s.insert(s.end(), tail.begin(), tail.end());
  return py::array_t<T>(s);
}

// Runs body(begin, end) over [0, n) in parallel with `threads` threads (0 = all cores).
template <class Body>
void parallel(size_t n, int threads, const Body& body) {
  auto run = [&] {
    tbb::parallel_for(tbb::blocked_range<size_t>(0, n, 256),
                      [&](const tbb::blocked_range<size_t>& r) { body(r.begin(), r.end()); });
  };
  if (threads > 0) {
    tbb::task_arena arena(threads);
    arena.execute(run);
  } else {
    run();
  }
}

// The first ray with a NaN component, found while tracing (kept the smallest index).
struct BadRay {
  std::atomic<size_t> index{std::numeric_limits<size_t>::max()};
  void note(size_t i) {
    size_t cur = index.load(std::memory_order_relaxed);
    while (i < cur && !index.compare_exchange_weak(cur, i)) {
    }
  }
  void raise_if_any(const Rays& rays) const {
    size_t i = index.load();
    if (i == std::numeric_limits<size_t>::max()) return;
    std::ostringstream s;
    s << "rays: expected finite numbers, ray " << i << " (flat index) is [";
    for (int k = 0; k < 6; ++k) s << (k ? ", " : "") << rays.data[i * 6 + k];
    s << "]";
    throw py::value_error(s.str());
  }
};

// Ray i of the array; false (and noted) if it holds a NaN.
inline bool load_ray(const float* p, slim::Ray& r) {
  r.org = {p[0], p[1], p[2]};
  r.dir = {p[3], p[4], p[5]};
  r.tnear = 0.0f;
  r.tfar = slim::kInf;
  return !(std::isnan(p[0]) || std::isnan(p[1]) || std::isnan(p[2]) || std::isnan(p[3]) ||
           std::isnan(p[4]) || std::isnan(p[5]));
}

// slimrt.Mesh: a mesh file loaded once (polygons kept), to add to any number of scenes without
// loading or copying it again.
struct LoadedMesh {
  std::shared_ptr<const slim::PolyMesh> mesh;
  std::string path;
};

// The options of a registry configuration with `threads` build threads (0: all cores); ValueError
// for a negative count or an unknown name (the message lists the names).
slim::BuildOptions build_options(const std::string& config, int threads) {
  if (threads < 0)
    throw py::value_error("threads: expected 0 (all cores) or more, got " +
                          std::to_string(threads));
  slim::BuildOptions opt;
  try {
    opt = slim::BuildOptions::from_config(config);
  } catch (const slim::Error& e) {
    throw py::value_error(std::string("config: ") + e.what());
  }
  opt.threads = threads;
  return opt;
}

class RaycastingScene {
  // One geometry: a mesh file (owned) or the arrays of add_triangles (referenced, or owned when
  // they were converted). Python objects are only touched with the GIL; the raw pointers are
  // what the build reads without it.
  struct Geometry {
    std::shared_ptr<const slim::PolyMesh> mesh;  // add_mesh
    bool mesh_owned = false;        // loaded by add_mesh(path), not shared with a slimrt.Mesh
    py::array vertices, triangles;  // add_triangles: float32 [N, 3], (u)int32 [M, 3]
    bool vertices_owned = false, triangles_owned = false;
    const float* positions = nullptr;
    const uint32_t* indices = nullptr;
    size_t vertex_count = 0, triangle_count = 0;
  };

 public:
  RaycastingScene(const std::string& config, int threads, py::object progress)
      : threads_(threads), progress_(std::move(progress)) {
    if (!progress_.is_none() && !PyCallable_Check(progress_.ptr()))
      throw py::type_error("progress: expected a callable progress(phase, done, total) or None");
    options_ = build_options(config, threads);
  }

  // Vertices and triangles are referenced, not copied, when they are float32 and uint32 (or
  // int32) C-contiguous numpy arrays that can_reference() accepts: the scene keeps the arrays
  // alive and reads them when it builds. Any other dtype, layout or owner is converted once into
  // an array the scene owns.
  uint32_t add_triangles(py::handle vertices_obj, py::handle triangles_obj) {
    check_not_in_own_callback();
    return add(triangle_geometry(vertices_obj, triangles_obj));
  }

  // slimrt.cluster_face_order: the arrays checked as add_triangles checks them, the order of
  // slim::cluster_face_order (slimrt/clusters.h) as a uint32 array.
  static py::array_t<uint32_t> cluster_face_order(py::handle vertices, py::handle triangles,
                                                  const std::string& config, int threads) {
    const slim::BuildOptions opt = build_options(config, threads);
    const Geometry g = triangle_geometry(vertices, triangles);
    std::vector<uint32_t> order;
    {
      py::gil_scoped_release release;
      order = slim::cluster_face_order(
          slim::MeshView::triangles(reinterpret_cast<const slim::Vec3f*>(g.positions),
                                    g.vertex_count, g.indices, g.triangle_count),
          opt);
    }
    py::array_t<uint32_t> out = output<uint32_t>({py::ssize_t(order.size())});
    std::copy(order.begin(), order.end(), out.mutable_data());
    return out;
  }

 private:
  // The arrays of add_triangles as a Geometry: checked (dtype, shape, indices in range, finite
  // vertices), referenced where they can be, else converted into arrays the Geometry owns.
  static Geometry triangle_geometry(py::handle vertices_obj, py::handle triangles_obj) {
    Geometry g;
    py::array v = as_array(vertices_obj);
    if (v.dtype().kind() != 'f')
      throw py::type_error("vertices: expected a float32 array of shape [N, 3], got dtype " +
                           dtype_str(v));
    if (v.ndim() != 2 || v.shape(1) != 3)
      throw py::value_error("vertices: expected shape [N, 3], got shape " + shape_str(v));
    py::array t = as_array(triangles_obj);
    const char kind = t.dtype().kind();
    if (kind != 'u' && kind != 'i')
      throw py::type_error("triangles: expected a uint32 array of shape [M, 3], got dtype " +
                           dtype_str(t));
    if (t.ndim() != 2 || t.shape(1) != 3)
      throw py::value_error("triangles: expected shape [M, 3], got shape " + shape_str(t));
    const size_t nv = size_t(v.shape(0)), nt = size_t(t.shape(0));
    if (nv > size_t(kInvalid))
      throw py::value_error("vertices: at most 2^32 - 1 vertices, got " + std::to_string(nv));

    if (py::isinstance<py::array_t<float, py::array::c_style>>(v) &&
        can_reference(v, alignof(float))) {
      g.vertices = v;
    } else {
      g.vertices = owned_copy(v, "float32");
      g.vertices_owned = true;
    }
    g.positions = static_cast<const float*>(g.vertices.data());
    g.vertex_count = nv;

    // Indices: uint32 and int32 C-contiguous arrays as they are (int32 checked non-negative,
    // then read as uint32: the same bits), other integer dtypes converted to uint32 after the
    // range check in their own type.
    const bool as_is = (py::isinstance<py::array_t<uint32_t, py::array::c_style>>(t) ||
                        py::isinstance<py::array_t<int32_t, py::array::c_style>>(t)) &&
                       can_reference(t, alignof(uint32_t));
    std::string bad;
    if (as_is) {
      g.triangles = t;
      const void* p = t.data();
      const bool is_signed = kind == 'i';
      py::gil_scoped_release release;
      bad = is_signed ? first_bad_index(static_cast<const int32_t*>(p), nt * 3, nv)
                      : first_bad_index(static_cast<const uint32_t*>(p), nt * 3, nv);
    } else if (kind == 'u') {
      auto u = py::array_t<uint64_t, py::array::c_style | py::array::forcecast>::ensure(t);
      py::gil_scoped_release release;
      bad = first_bad_index(u.data(), nt * 3, nv);
    } else {
      auto s = py::array_t<int64_t, py::array::c_style | py::array::forcecast>::ensure(t);
      py::gil_scoped_release release;
      bad = first_bad_index(s.data(), nt * 3, nv);
    }
    if (!bad.empty()) throw py::value_error(bad);
    if (!as_is) {
      g.triangles = owned_copy(t, "uint32");
      g.triangles_owned = true;
    }
    g.indices = static_cast<const uint32_t*>(g.triangles.data());
    g.triangle_count = nt;

    {
      py::gil_scoped_release release;
      const float* p = g.positions;
      for (size_t i = 0; i < nv; ++i)
        if (!(std::isfinite(p[3 * i]) && std::isfinite(p[3 * i + 1]) &&
              std::isfinite(p[3 * i + 2]))) {
          bad = "vertices: expected finite coordinates, vertex " + std::to_string(i) + " is [" +
                std::to_string(p[3 * i]) + ", " + std::to_string(p[3 * i + 1]) + ", " +
                std::to_string(p[3 * i + 2]) + "]";
          break;
        }
    }
    if (!bad.empty()) throw py::value_error(bad);
    return g;
  }

 public:
  uint32_t add_mesh(const std::string& path) {
    check_not_in_own_callback();
    Geometry g;
    {
      py::gil_scoped_release release;
      g.mesh = std::make_shared<const slim::PolyMesh>(slim::load(path));
    }
    g.mesh_owned = true;
    return add(std::move(g));
  }

  // A mesh loaded once (slimrt.Mesh), shared with the scene rather than copied.
  uint32_t add_loaded_mesh(const LoadedMesh& mesh) {
    check_not_in_own_callback();
    Geometry g;
    g.mesh = mesh.mesh;
    return add(std::move(g));
  }

  py::dict cast_rays(py::handle rays_obj, int nthreads) {
    Rays rays = get_rays(rays_obj);
    auto t_hit = output<float>(rays.shape);
    auto geom = output<uint32_t>(rays.shape);
    auto prim = output<uint32_t>(rays.shape);
    auto uvs = output<float>(rays.shape, {2});
    auto normals = output<float>(rays.shape, {3});
    float* pt = t_hit.mutable_data();
    uint32_t* pg = geom.mutable_data();
    uint32_t* pp = prim.mutable_data();
    float* puv = uvs.mutable_data();
    float* pn = normals.mutable_data();
    BadRay bad;
    const int nt = threads(nthreads);
    {
      py::gil_scoped_release release;
      const std::shared_ptr<const slim::Scene> kept = built();
      const slim::Scene& scene = *kept;
      parallel(rays.count, nt, [&](size_t b, size_t e) {
        for (size_t i = b; i < e; ++i) {
          slim::Ray r;
          slim::Hit h;
          if (load_ray(rays.data + i * 6, r))
            h = scene.intersect(r);
          else
            bad.note(i);
          if (h.valid()) {
            pt[i] = h.t;
            pg[i] = h.geomID;
            pp[i] = h.primID;
            puv[2 * i] = h.u;
            puv[2 * i + 1] = h.v;
            const slim::Vec3f n = slim::safe_normalize(h.Ng);  // no overflow for huge triangles
            pn[3 * i] = n.x;
            pn[3 * i + 1] = n.y;
            pn[3 * i + 2] = n.z;
          } else {  // Open3D's miss values
            pt[i] = slim::kInf;
            pg[i] = kInvalid;
            pp[i] = kInvalid;
            puv[2 * i] = puv[2 * i + 1] = 0.0f;
            pn[3 * i] = pn[3 * i + 1] = pn[3 * i + 2] = 0.0f;
          }
        }
      });
    }
    bad.raise_if_any(rays);
    py::dict out;
    out["t_hit"] = result(t_hit);
    out["geometry_ids"] = result(geom);
    out["primitive_ids"] = result(prim);
    out["primitive_uvs"] = result(uvs);
    out["primitive_normals"] = result(normals);
    return out;
  }

  py::object test_occlusions(py::handle rays_obj, float tnear, float tfar, int nthreads) {
    if (std::isnan(tnear) || std::isnan(tfar))
      throw py::value_error("test_occlusions: expected numbers for tnear and tfar, got NaN");
    Rays rays = get_rays(rays_obj);
    auto out = output<bool>(rays.shape);
    bool* po = out.mutable_data();
    BadRay bad;
    const int nt = threads(nthreads);
    {
      py::gil_scoped_release release;
      const std::shared_ptr<const slim::Scene> kept = built();
      const slim::Scene& scene = *kept;
      parallel(rays.count, nt, [&](size_t b, size_t e) {
        for (size_t i = b; i < e; ++i) {
          slim::Ray r;
          bool ok = load_ray(rays.data + i * 6, r);
          if (!ok) bad.note(i);
          r.tnear = tnear;
          r.tfar = tfar;
          po[i] = ok && scene.occluded(r);
        }
      });
    }
    bad.raise_if_any(rays);
    return result(out);
  }

  // slimrt has no all-hits query: each ray is traced again and again, each time starting just
  // past the last hit (tnear = the next float after its t), so every distinct hit distance counts
  // once: a ray through a shared edge or vertex counts one crossing, coincident triangles count
  // once. At most max_hits hits are counted per ray.
  py::object count_intersections(py::handle rays_obj, int nthreads, uint32_t max_hits) {
    Rays rays = get_rays(rays_obj);
    auto out = output<int32_t>(rays.shape);
    int32_t* po = out.mutable_data();
    const uint32_t limit =
        std::min<uint32_t>(max_hits, uint32_t(std::numeric_limits<int32_t>::max()));
    BadRay bad;
    const int nt = threads(nthreads);
    {
      py::gil_scoped_release release;
      const std::shared_ptr<const slim::Scene> kept = built();
      const slim::Scene& scene = *kept;
      parallel(rays.count, nt, [&](size_t b, size_t e) {
        for (size_t i = b; i < e; ++i) {
          slim::Ray r;
          uint32_t n = 0;
          if (load_ray(rays.data + i * 6, r)) {
            while (n < limit) {
              slim::Hit h = scene.intersect(r);
              if (!h.valid()) break;
              ++n;
              r.tnear = std::nextafter(h.t, slim::kInf);
              if (!(r.tnear < slim::kInf)) break;
            }
          } else {
            bad.note(i);
          }
          po[i] = int32_t(n);
        }
      });
    }
    bad.raise_if_any(rays);
    return result(out);
  }

  py::dict memory() {
    py::dict d;
    if (geometries_.empty() && !opened()) {
      for (const char* k : {"geometry", "bvh", "other", "total", "triangles"}) d[k] = 0;
      d["bytes_per_triangle"] = 0.0;
    } else {
      slim::MemoryStats m;
      {
        py::gil_scoped_release release;
        m = built()->memory();
      }
      d["geometry"] = m.geometry_bytes;
      d["bvh"] = m.bvh_bytes;
      d["other"] = m.other_bytes;
      d["total"] = m.total();
      d["triangles"] = m.triangles;
      d["bytes_per_triangle"] = m.bytes_per_triangle();
    }
    const auto [owned, referenced] = input_bytes();
    d["input_meshes"] = owned;
    d["input_referenced"] = referenced;
    return d;
  }

  py::dict stats() {
    py::dict d;
    d["config"] = options_.config_name();
    d["geometries"] = geometries_.size();
    if (geometries_.empty() && !opened()) return d;
    std::shared_ptr<const slim::Scene> scene;
    {
      py::gil_scoped_release release;
      scene = built();
    }
    const slim::SceneStats& s = scene->stats();
    d["build_seconds"] = s.build_seconds;
    d["input_faces"] = s.input_faces;
    d["triangles"] = s.triangles;
    d["skipped_faces"] = s.skipped_faces;
    d["primitives"] = s.primitives;
    d["lossy"] = scene->is_lossy();
    d["error_bound"] = scene->error_bound();
    py::dict details;
    for (const auto& [k, v] : slim::stat_details(*scene)) details[py::str(k)] = v;
    d["details"] = details;
    return d;
  }

  std::string config() const { return options_.config_name(); }
  size_t geometry_count() const { return geometries_.size(); }

  // Scene files (slim::Scene::save / open): the built scene, written atomically; a scene opened
  // from a file traces straight from its mapping and takes no more geometry.
  void save(const std::string& path) {
    py::gil_scoped_release release;
    built()->save(path);
  }
  static std::unique_ptr<RaycastingScene> open(const std::string& path, bool verify_checksums) {
    slim::OpenOptions o;
    o.verify_checksums = verify_checksums;
    slim::Scene s = [&] {
      py::gil_scoped_release release;
      return slim::Scene::open(path, o);
    }();
    return std::unique_ptr<RaycastingScene>(new RaycastingScene(std::move(s)));
  }

 private:
  // A scene opened from a file: its options as saved (any combination, with or without a
  // registry name), all cores.
  explicit RaycastingScene(slim::Scene opened)
      : options_(opened.options()), progress_(py::none()), opened_(true) {
    options_.threads = 0;
    scene_ = std::make_shared<const slim::Scene>(std::move(opened));
  }
  bool opened() const { return opened_; }

  // The first index outside [0, nv) as an error message, or "".
  template <class T>
  static std::string first_bad_index(const T* p, size_t n, size_t nv) {
    for (size_t i = 0; i < n; ++i)
      if (p[i] < 0 || uint64_t(p[i]) >= nv) {
        std::ostringstream s;
        s << "triangles: expected indices in [0, " << nv << "), triangle " << i / 3 << " has "
          << +p[i];
        return s.str();
      }
    return {};
  }

  // The scene whose progress callable the current thread is running (nullptr outside one).
  static inline thread_local const RaycastingScene* in_callback_of_ = nullptr;
  // A query or add from inside this scene's own progress callable would wait for the build that
  // is calling it: refused.
  void check_not_in_own_callback() const {
    if (in_callback_of_ == this)
      throw std::runtime_error(
          "slimrt.RaycastingScene: its progress callable cannot use the scene it is building "
          "(the scene is not built until the callable returns)");
  }

  // mutex_ is never waited for while holding the GIL: the thread that holds it may need the GIL
  // (a progress callable) before it lets go.
  std::unique_lock<std::mutex> lock_without_gil() {
    std::unique_lock<std::mutex> lock(mutex_, std::defer_lock);
    if (PyGILState_Check()) {
      py::gil_scoped_release release;
      lock.lock();
    } else {
      lock.lock();
    }
    return lock;
  }

  uint32_t add(Geometry&& g) {
    if (opened())
      throw py::value_error("this scene was opened from a scene file: it takes no more geometry");
    auto lock = lock_without_gil();
    if (geometries_.size() >= size_t(kInvalid))
      throw py::value_error("at most 2^32 - 1 geometries in a scene");
    geometries_.push_back(std::move(g));
    scene_.reset();  // rebuilt on the next query; queries running now keep the old one
    return uint32_t(geometries_.size() - 1);
  }

  int threads(int nthreads) const {
    if (nthreads < 0)
      throw py::value_error("nthreads: expected 0 (all cores) or more, got " +
                            std::to_string(nthreads));
    return nthreads > 0 ? nthreads : threads_;
  }

  // The scene, built now if geometry was added since the last build; shared, so that a query
  // keeps it while another thread adds geometry. Called without the GIL; touches no Python
  // object except the progress callable, which it calls with the GIL taken (and only then),
  // isolated from the build's other TBB tasks. The callable returning False, raising, or a
  // signal (Ctrl-C) cancels the build.
  std::shared_ptr<const slim::Scene> built() {
    check_not_in_own_callback();
    auto lock = lock_without_gil();
    if (!scene_) {
      slim::BuildOptions opt = options_;
      std::unique_ptr<py::error_already_set> raised;
      if (!progress_.is_none())
        opt.progress = [this, &raised](const slim::BuildProgress& p) {
          bool go_on = false;
          tbb::this_task_arena::isolate([&] {
            py::gil_scoped_acquire gil;
            const RaycastingScene* outer = in_callback_of_;
            in_callback_of_ = this;
            try {
              if (PyErr_CheckSignals() != 0) throw py::error_already_set();
              py::object r = progress_(p.phase, p.done, p.total);
              int truth = 1;
              if (!r.is_none()) {
                truth = PyObject_IsTrue(r.ptr());
                if (truth < 0) throw py::error_already_set();
              }
              go_on = truth != 0;
            } catch (py::error_already_set& e) {
              raised = std::make_unique<py::error_already_set>(std::move(e));
              go_on = false;
            }
            in_callback_of_ = outer;
          });
          return go_on;
        };
      // The build reads the arrays of add_triangles in place, as views (3 corners per face: no
      // face size array), and the loaded meshes through views of them.
      std::vector<slim::MeshView> views;
      views.reserve(geometries_.size() + 1);
      for (size_t i = 0; i < geometries_.size(); ++i) {
        const Geometry& g = geometries_[i];
        if (g.mesh) {
          views.emplace_back(*g.mesh);
          continue;
        }
        static_assert(sizeof(slim::Vec3f) == 3 * sizeof(float));
        views.push_back(slim::MeshView::triangles(reinterpret_cast<const slim::Vec3f*>(g.positions),
                                                  g.vertex_count, g.indices, g.triangle_count,
                                                  "geometry " + std::to_string(i)));
      }
      if (views.empty()) views.emplace_back();  // a scene without geometry: one empty mesh
      std::vector<const slim::MeshView*> meshes;
      for (const slim::MeshView& v : views) meshes.push_back(&v);
      try {
        scene_ = std::make_shared<const slim::Scene>(slim::Scene::build(meshes, opt));
      } catch (const slim::Cancelled&) {
        if (raised) {
          py::gil_scoped_acquire gil;  // the exception object is Python's
          py::error_already_set e = std::move(*raised);
          raised.reset();
          throw e;
        }
        throw;
      }
    }
    return scene_;
  }

  // Bytes of input the scene keeps: owned (mesh files, converted arrays) and referenced (the
  // caller's arrays, kept alive).
  std::pair<uint64_t, uint64_t> input_bytes() const {
    uint64_t owned = 0, referenced = 0;
    for (const Geometry& g : geometries_) {
      if (const slim::PolyMesh* m = g.mesh.get()) {
        (g.mesh_owned ? owned : referenced) +=
            m->positions.size() * sizeof(slim::Vec3f) +
            (m->face_sizes.size() + m->face_indices.size() + m->normal_indices.size() +
             m->uv_indices.size() + m->face_object.size()) *
                sizeof(uint32_t) +
            m->normals.size() * sizeof(slim::Vec3f) + m->uvs.size() * sizeof(slim::Vec2f);
        continue;
      }
      (g.vertices_owned ? owned : referenced) += uint64_t(g.vertices.nbytes());
      (g.triangles_owned ? owned : referenced) += uint64_t(g.triangles.nbytes());
    }
    return {owned, referenced};
  }

  slim::BuildOptions options_;
  int threads_ = 0;
  py::object progress_;  // None or progress(phase, done, total)
  bool opened_ = false;  // opened from a scene file
  std::mutex mutex_;     // guards geometries_ and scene_ (with the GIL for geometries_)
  std::vector<Geometry> geometries_;
  std::shared_ptr<const slim::Scene> scene_;
};

// Open3D's create_rays_pinhole from intrinsic K (3x3) and the world-to-camera extrinsic (4x4):
// pixel (x, y) gets the direction R^T K^-1 (x + 0.5, y + 0.5, 1) from the camera centre -R^T t.
py::array_t<float> rays_pinhole(const double K[9], const double E[16], int width, int height) {
  if (width <= 0 || height <= 0)
    throw py::value_error("create_rays_pinhole: expected positive width_px and height_px, got " +
                          std::to_string(width) + " and " + std::to_string(height));
  const double fx = K[0], s = K[1], cx = K[2], fy = K[4], cy = K[5];
  if (!(fx != 0 && fy != 0) || !std::isfinite(fx) || !std::isfinite(fy))
    throw py::value_error(
        "create_rays_pinhole: expected nonzero finite focal lengths in the "
        "intrinsic matrix");
  double R[3][3], t[3];
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 3; ++j) R[i][j] = E[i * 4 + j];
    t[i] = E[i * 4 + 3];
  }
  double o[3];
  for (int j = 0; j < 3; ++j) o[j] = -(R[0][j] * t[0] + R[1][j] * t[1] + R[2][j] * t[2]);
  py::array_t<float> out({py::ssize_t(height), py::ssize_t(width), py::ssize_t(6)});
  float* p = out.mutable_data();
  {
    py::gil_scoped_release release;  // big images take a while; only `p` is written
    for (int y = 0; y < height; ++y)
      for (int x = 0; x < width; ++x) {
        // K^-1 of an upper triangular K = [[fx, s, cx], [0, fy, cy], [0, 0, 1]].
        double v = (y + 0.5 - cy) / fy;
        double u = (x + 0.5 - cx - s * v) / fx;
        double d[3] = {u, v, 1.0};
        for (int j = 0; j < 3; ++j) {
          p[j] = float(o[j]);
          p[3 + j] = float(R[0][j] * d[0] + R[1][j] * d[1] + R[2][j] * d[2]);
        }
        p += 6;
      }
  }
  return out;
}

std::vector<double> doubles(py::handle obj, size_t n, const char* what, const char* shape) {
  py::array a = as_array(obj);
  char kind = a.dtype().kind();
  if (kind != 'f' && kind != 'i' && kind != 'u')
    throw py::type_error(std::string(what) + ": expected a number array of shape " + shape +
                         ", got dtype " + dtype_str(a));
  auto d = py::array_t<double, py::array::c_style | py::array::forcecast>::ensure(a);
  if (size_t(d.size()) != n)
    throw py::value_error(std::string(what) + ": expected shape " + shape + ", got shape " +
                          shape_str(a));
  std::vector<double> v(d.data(), d.data() + n);
  for (double x : v)
    if (!std::isfinite(x)) throw py::value_error(std::string(what) + ": expected finite numbers");
  return v;
}

py::array_t<float> rays_pinhole_fov(double fov_deg, py::handle center_obj, py::handle eye_obj,
                                    py::handle up_obj, int width, int height) {
  if (!(fov_deg > 0.0 && fov_deg < 180.0))
    throw py::value_error("create_rays_pinhole: expected fov_deg in (0, 180), got " +
                          std::to_string(fov_deg));
  auto c = doubles(center_obj, 3, "center", "[3]");
  auto e = doubles(eye_obj, 3, "eye", "[3]");
  auto up = doubles(up_obj, 3, "up", "[3]");
  auto norm = [](double v[3]) {
    double l = std::sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]);
    if (!(l > 0)) return false;
    for (int i = 0; i < 3; ++i) v[i] /= l;
    return true;
  };
  auto cross = [](const double a[3], const double b[3], double r[3]) {
    r[0] = a[1] * b[2] - a[2] * b[1];
    r[1] = a[2] * b[0] - a[0] * b[2];
    r[2] = a[0] * b[1] - a[1] * b[0];
  };
  // The horizontal field of view sets the focal length; the camera looks along f = center - eye
  // with rows right = up x f, down-facing image rows along f x right (Open3D's convention).
  double f[3] = {c[0] - e[0], c[1] - e[1], c[2] - e[2]}, r[3], u[3];
  if (!norm(f)) throw py::value_error("create_rays_pinhole: eye and center are the same point");
  cross(up.data(), f, r);
  if (!norm(r)) throw py::value_error("create_rays_pinhole: up is parallel to the view direction");
  cross(f, r, u);
  const double focal = 0.5 * width / std::tan(0.5 * fov_deg * M_PI / 180.0);
  double K[9] = {focal, 0, 0.5 * width, 0, focal, 0.5 * height, 0, 0, 1};
  double E[16] = {};
  for (int j = 0; j < 3; ++j) {
    E[0 * 4 + j] = r[j];
    E[1 * 4 + j] = u[j];
    E[2 * 4 + j] = f[j];
  }
  for (int i = 0; i < 3; ++i)
    E[i * 4 + 3] = -(E[i * 4] * e[0] + E[i * 4 + 1] * e[1] + E[i * 4 + 2] * e[2]);
  E[15] = 1;
  return rays_pinhole(K, E, width, height);
}

// A mesh file as triangles: vertices [N, 3] float32, triangles [M, 3] uint32 (each polygon fanned
// from its first corner) and face [M] uint32, the polygon each triangle comes from.
py::tuple load_triangles(const std::string& path) {
  slim::PolyMesh m;
  {
    py::gil_scoped_release release;
    m = slim::load(path);
  }
  const uint64_t nt = m.fan_triangle_count();
  py::array_t<float> v({py::ssize_t(m.positions.size()), py::ssize_t(3)});
  py::array_t<uint32_t> t({py::ssize_t(nt), py::ssize_t(3)});
  py::array_t<uint32_t> face({py::ssize_t(nt)});
  float* pv = v.mutable_data();
  uint32_t* pt = t.mutable_data();
  uint32_t* pf = face.mutable_data();
  py::gil_scoped_release release;  // only the raw buffers are written from here on
  if (!m.positions.empty())
    std::memcpy(pv, m.positions.data(), m.positions.size() * sizeof(slim::Vec3f));
  size_t corner = 0, k = 0;
  for (size_t f = 0; f < m.face_sizes.size(); ++f) {
    const uint32_t n = m.face_sizes[f];
    for (uint32_t j = 1; j + 1 < n; ++j, ++k) {
      pt[3 * k] = m.face_indices[corner];
      pt[3 * k + 1] = m.face_indices[corner + j];
      pt[3 * k + 2] = m.face_indices[corner + j + 1];
      pf[k] = uint32_t(f);
    }
    corner += n;
  }
  py::gil_scoped_acquire gil;
  return py::make_tuple(v, t, face);
}

}  // namespace

PYBIND11_MODULE(slimrt, m) {
  m.doc() =
      "slimrt: compact CPU ray tracing of triangle and quad meshes. RaycastingScene follows "
      "Open3D's open3d.t.geometry.RaycastingScene.";
  // slimrt.Cancelled (a build its progress callback stopped) and slimrt.NotApplicable (a
  // configuration that does not apply to the mesh) are slimrt.Errors: registered after it, since
  // pybind11 tries the most recently registered translator first.
  auto& error = py::register_exception<slim::Error>(m, "Error", PyExc_RuntimeError);
  py::register_exception<slim::Cancelled>(m, "Cancelled", error.ptr());
  py::register_exception<slim::NotApplicable>(m, "NotApplicable", error.ptr());
  m.attr("INVALID_ID") = kInvalid;
  m.attr("__version__") = SLIMRT_VERSION;
  py::exec(R"(
import numpy as _np
class Array(_np.ndarray):
    """A numpy array (what slimrt returns) with numpy(), as Open3D's Tensor has: the plain
    numpy.ndarray view of the same memory."""
    __slots__ = ()
    def numpy(self):
        return self.view(_np.ndarray)
Array.__module__ = "slimrt"
)",
           m.attr("__dict__"));
  array_type = py::object(m.attr("Array")).release();
  m.def("configs", &slim::all_config_names,
        "Every configuration name (the formats of the README).");
  m.def(
      "config_info",
      [](const std::string& name) {
        const slim::ConfigInfo& c = slim::config_info(name);
        py::dict d;
        d["name"] = c.name;
        d["lossy"] = c.lossy;
        d["own_geometry"] = c.own_geometry;
        d["error_bound"] = c.error_bound;
        d["summary"] = c.summary;
        return d;
      },
      py::arg("name"),
      "The registry row of a configuration: name, lossy, own_geometry, error_bound (what the "
      "format promises), summary. Raises slimrt.Error for an unknown name.");
  m.def(
      "simd_isa", [] { return std::string(slim::simd_isa()); },
      "The SIMD path slimrt was compiled for.");
  m.def("cluster_face_order", &RaycastingScene::cluster_face_order, py::arg("vertex_positions"),
        py::arg("triangle_indices"), py::arg("config") = "cluster", py::arg("threads") = 0,
        "The triangles' order in a cluster configuration's scene (config 'cluster' or "
        "'cluster-lossless'): a uint32 array, order[i] the input triangle that comes i-th. "
        "Triangles in that order (triangle_indices[order]) take fewer bytes in the cluster "
        "configurations: their primIDs come in the clusters' order. Builds the scene once. "
        "Arrays as add_triangles takes them; raises slimrt.Error for other configurations.");
  m.def("load_triangles", &load_triangles, py::arg("path"),
        "Loads a mesh file (.obj .ply .gltf .glb, optionally .xz) or a procedural scene "
        "(terrain:N, torus:N, canyon:N) as (vertices [N,3] float32, triangles [M,3] uint32, "
        "face [M] uint32): polygons are fanned from their first corner, face[i] is the polygon "
        "of triangle i.");

  py::class_<LoadedMesh>(m, "Mesh",
                         "A mesh file (.obj .ply .gltf .glb, optionally .xz) or procedural scene "
                         "loaded once, polygons kept, to add to scenes with add_mesh(mesh) "
                         "without loading or copying it again.")
      .def(py::init([](const std::string& path) {
             LoadedMesh lm;
             lm.path = path;
             py::gil_scoped_release release;
             lm.mesh = std::make_shared<const slim::PolyMesh>(slim::load(path));
             return lm;
           }),
           py::arg("path"))
      .def_readonly("path", &LoadedMesh::path)
      .def_property_readonly("vertex_count",
                             [](const LoadedMesh& m) { return m.mesh->positions.size(); })
      .def_property_readonly("face_count",
                             [](const LoadedMesh& m) { return m.mesh->face_sizes.size(); })
      .def_property_readonly(
          "triangle_count", [](const LoadedMesh& m) { return m.mesh->fan_triangle_count(); },
          "Triangles after fan triangulation.")
      .def("__repr__", [](const LoadedMesh& m) {
        return "slimrt.Mesh(" + py::repr(py::str(m.path)).cast<std::string>() + ", " +
               std::to_string(m.mesh->face_sizes.size()) + " faces)";
      });

  py::class_<RaycastingScene>(m, "RaycastingScene",
                              "A scene of triangle meshes to cast rays against (Open3D's "
                              "RaycastingScene names and conventions). config is a slimrt "
                              "configuration (slimrt.configs()); threads = 0 uses all cores.")
      .def(py::init([](py::object config, int threads, py::object progress,
                       std::optional<int> nthreads) {
             // Open3D's RaycastingScene(nthreads=0): an int in the place of the config, or the
             // nthreads keyword.
             std::string name = "clbvh-compact";
             if (PyLong_Check(config.ptr()) && !PyBool_Check(config.ptr())) {
               if (nthreads) throw py::type_error("RaycastingScene: nthreads given twice");
               nthreads = config.cast<int>();
             } else if (!config.is_none()) {
               if (!py::isinstance<py::str>(config))
                 throw py::type_error(
                     "config: expected a configuration name (slimrt.configs()) or, as "
                     "Open3D's RaycastingScene(nthreads), a number of threads");
               name = config.cast<std::string>();
             }
             if (nthreads) {
               if (threads != 0 && threads != *nthreads)
                 throw py::value_error("RaycastingScene: threads and nthreads disagree");
               threads = *nthreads;
             }
             return std::make_unique<RaycastingScene>(name, threads, std::move(progress));
           }),
           py::arg("config") = "clbvh-compact", py::arg("threads") = 0,
           py::arg("progress") = py::none(), py::arg("nthreads") = py::none(),
           "RaycastingScene(config='clbvh-compact', threads=0, progress=None); Open3D's "
           "RaycastingScene(nthreads=0) and RaycastingScene(4) work too (nthreads is threads). "
           "progress: optional callable progress(phase, done, total) called during the build "
           "(phases 'prepare', 'bvh2', 'collapse'; done grows to total in each); returning "
           "False cancels the build, which raises slimrt.Cancelled.")
      .def_property_readonly_static("INVALID_ID", [](py::object) { return kInvalid; })
      .def(
          "add_triangles",
          [](RaycastingScene& self, py::object mesh) {
            // Open3D's add_triangles(mesh): an open3d.t.geometry.TriangleMesh (vertex
            // "positions", triangle "indices") or a legacy open3d.geometry.TriangleMesh
            // (vertices, triangles).
            if (py::hasattr(mesh, "vertex") && py::hasattr(mesh, "triangle"))
              return self.add_triangles(mesh.attr("vertex")["positions"],
                                        mesh.attr("triangle")["indices"]);
            if (py::hasattr(mesh, "vertices") && py::hasattr(mesh, "triangles"))
              return self.add_triangles(mesh.attr("vertices"), mesh.attr("triangles"));
            throw py::type_error(
                "add_triangles(mesh): expected an open3d.t.geometry.TriangleMesh or an "
                "open3d.geometry.TriangleMesh, or add_triangles(vertex_positions, "
                "triangle_indices)");
          },
          py::arg("mesh"),
          "Adds an Open3D triangle mesh (open3d.t.geometry.TriangleMesh: vertex['positions'], "
          "triangle['indices']; or legacy open3d.geometry.TriangleMesh: vertices, triangles), "
          "converted as add_triangles(vertex_positions, triangle_indices) converts arrays. "
          "Returns its geometry id.")
      .def("add_triangles", &RaycastingScene::add_triangles, py::arg("vertex_positions"),
           py::arg("triangle_indices"),
           "Adds a triangle mesh: vertices [N,3] float32, triangles [M,3] uint32. Returns its "
           "geometry id. Float32 vertices and uint32 (or non-negative int32) triangles in "
           "C-contiguous arrays are not copied: the scene keeps references to the arrays and "
           "reads them when it builds (on the next query, and again after more geometry is "
           "added), so they must not change while the scene is in use: a change during a build "
           "(from another thread or the progress callable) is undefined behaviour, as for "
           "Embree's shared buffers; pass a copy (np.array(a)) if they may change. Any other dtype "
           "(float64, int64, ...), layout (strided, Fortran order, unaligned) or memory numpy does "
           "not own (a view of an Open3D vector or tensor; np.memmap is referenced) is copied "
           "once, converted to float32 / uint32; memory() counts such copies in input_meshes and "
           "the referenced "
           "arrays in input_referenced.")
      .def("add_mesh", &RaycastingScene::add_mesh, py::arg("path"),
           "Adds a mesh file (.obj .ply .gltf .glb, optionally .xz) or a procedural scene; "
           "polygons are kept (primitive_ids are the file's face indices). Returns its geometry "
           "id.")
      .def("add_mesh", &RaycastingScene::add_loaded_mesh, py::arg("mesh"),
           "Adds a slimrt.Mesh, shared with it (not copied; memory() counts it in "
           "input_referenced). Returns its geometry id.")
      .def("cast_rays", &RaycastingScene::cast_rays, py::arg("rays"), py::arg("nthreads") = 0,
           "Closest hits of rays [..., 6] (ox, oy, oz, dx, dy, dz; t in units of the direction's "
           "length). Returns a dict: t_hit [...] (inf on a miss), geometry_ids and primitive_ids "
           "[...] (INVALID_ID on a miss), primitive_uvs [..., 2] (barycentric weights of the "
           "2nd and 3rd vertex), primitive_normals [..., 3] (unit geometric normals, (v1-v0) x "
           "(v2-v0)); zeros on a miss.")
      .def("test_occlusions", &RaycastingScene::test_occlusions, py::arg("rays"),
           py::arg("tnear") = 0.0f, py::arg("tfar") = slim::kInf, py::arg("nthreads") = 0,
           "True for the rays [..., 6] that hit anything with t in [tnear, tfar].")
      .def("count_intersections", &RaycastingScene::count_intersections, py::arg("rays"),
           py::arg("nthreads") = 0, py::arg("max_hits") = kDefaultMaxHits,
           "Number of intersections along each ray [..., 6] (int32). Each ray is traced again "
           "from just past its last hit, so hits at the same distance (a shared edge or vertex, "
           "coincident triangles) count once; at most max_hits per ray. Open3D also counts a hit "
           "at the distance of the previous one once when it is on the same geometry; here "
           "hits of different geometries at the same distance count once too.")
      .def("memory", &RaycastingScene::memory,
           "Bytes the scene keeps, by part (geometry, bvh, other, total) and per triangle; "
           "input_meshes: the input the scene owns to rebuild when geometry is added (mesh "
           "files, converted arrays); input_referenced: the caller's arrays it references "
           "(add_triangles without a copy).")
      .def("stats", &RaycastingScene::stats,
           "Build statistics (builds the scene if needed); error_bound: the largest distance "
           "between a decoded and an input vertex (0 for lossless formats).")
      .def("save", &RaycastingScene::save, py::arg("path"),
           "Writes the scene (built now if needed) as a slimrt scene file (.slim), atomically.")
      .def_static("open", &RaycastingScene::open, py::arg("path"),
                  py::arg("verify_checksums") = true,
                  "A scene mapped from a scene file written by save() or `slimrt build` (no "
                  "copy, ready to cast rays); it takes no more geometry. verify_checksums=False "
                  "skips the per-section checksums (the header is always checked).")
      .def_property_readonly("config", &RaycastingScene::config)
      .def_property_readonly("geometry_count", &RaycastingScene::geometry_count)
      .def_static(
          "create_rays_pinhole",
          [](py::handle K, py::handle E, int width_px, int height_px) {
            auto k = doubles(K, 9, "intrinsic_matrix", "[3, 3]");
            auto e = doubles(E, 16, "extrinsic_matrix", "[4, 4]");
            return result(rays_pinhole(k.data(), e.data(), width_px, height_px));
          },
          py::arg("intrinsic_matrix"), py::arg("extrinsic_matrix"), py::arg("width_px"),
          py::arg("height_px"),
          "Rays [height_px, width_px, 6] of a pinhole camera: intrinsic K (3x3), world-to-camera "
          "extrinsic (4x4); directions R^T K^-1 (x + 0.5, y + 0.5, 1), not normalized.")
      .def_static(
          "create_rays_pinhole",
          [](double fov_deg, py::handle center, py::handle eye, py::handle up, int width_px,
             int height_px) {
            return result(rays_pinhole_fov(fov_deg, center, eye, up, width_px, height_px));
          },
          py::arg("fov_deg"), py::arg("center"), py::arg("eye"), py::arg("up"), py::arg("width_px"),
          py::arg("height_px"),
          "Rays [height_px, width_px, 6] of a pinhole camera at eye looking at center, "
          "horizontal field of view fov_deg (Open3D's convention).");
}
