// The registry of configurations (ConfigInfo in slimrt/scene.h): one row per named
// configuration with the properties of its format, and the builder of each leaf format. Every
// other part of slimrt (the CLI, the benchmark, the tests, the fuzz targets) asks a row or a built
// scene for a format's properties; nothing re-derives them from the name.
#include "api/registry.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <optional>
#include <string>
#include <vector>

#include "core/simd.h"
#include "prim/cluster.h"
#include "slimrt/analysis.h"
#include "slimrt/clusters.h"
#include "slimrt/scene.h"

namespace slim {

namespace {

// The properties of a format: the one place that knows which formats are lossy and which
// intersect their own triangles.
void describe_format(ConfigInfo& c) {
  const BuildOptions& o = c.options;
  c.lossy = o.leaf == Leaf::LossyGrids || o.leaf == Leaf::SharedLossyGrids ||
            o.leaf == Leaf::Clusters ||
            (o.leaf == Leaf::Costa && o.costa.find('V') != std::string::npos);
  // Costa splits n-gons of 5+ corners with GLU's tessellator, not into fans. Every grid triangle
  // is a fan triangle of the input (cells keep the fan's diagonal, mesh/grids.h).
  c.own_geometry = c.lossy || o.leaf == Leaf::Costa;
  if (!c.lossy)
    c.error_bound = "0 (positions are stored exactly)";
  else if (o.leaf == Leaf::Clusters)
    c.error_bound =
        "the largest |decoded - input| over the vertices, measured at build (at most "
        "BuildOptions::cluster_error x the box diagonal unless the lattice had to be coarsened: "
        "detail lattice_coarsened)";
  else if (o.leaf == Leaf::Costa)
    c.error_bound =
        "the largest |decoded - input| over the vertices, measured at build (16 bits per "
        "component in the scene box, or BuildOptions::lattice_box: half a step per axis plus float "
        "rounding)";
  else
    c.error_bound =
        "the largest |decoded - input| over the grid vertices, measured by the encoder "
        "(displacements are quantized; corners, vertices shared with other grids and, with "
        "BuildOptions::lattice_box, the meshes' boundary vertices are exact)";
}

ConfigInfo row(const char* name, Nodes nodes, Leaf leaf, const char* summary) {
  ConfigInfo c;
  c.name = name;
  c.options.nodes = nodes;
  c.options.leaf = leaf;
  c.summary = summary;
  describe_format(c);
  return c;
}

ConfigInfo pairs_row(const char* name, Nodes nodes, PairingMethod m, const char* summary) {
  ConfigInfo c = row(name, nodes, Leaf::Pairs, summary);
  c.options.pairing = m;
  return c;
}

ConfigInfo lossy_grid_row(const char* name, Nodes nodes, Leaf leaf, GridEncoding e,
                          const char* summary) {
  ConfigInfo c = row(name, nodes, leaf, summary);
  c.options.grid_encoding = e;
  return c;
}

ConfigInfo costa_row(const std::string& letters) {
  ConfigInfo c;
  c.name = letters.empty() ? "costa" : "costa-" + letters;
  c.options.leaf = Leaf::Costa;
  c.options.costa = letters;
  c.summary = "quantized n-gon mesh (Costa et al.)" +
              std::string(letters.empty() ? "" : ", options " + letters);
  describe_format(c);
  return c;
}

std::vector<ConfigInfo> make_rows() {
  std::vector<ConfigInfo> v = {
      row("bvh8-tri4v", Nodes::Bvh8, Leaf::Triangles, "BVH8, leaves of 4 gathered triangles"),
      row("bvh8-tri4i", Nodes::Bvh8, Leaf::IndexedTriangles,
          "BVH8, leaves of 4 triangles indexing one vertex array"),
      row("qbvh8-tri4v", Nodes::QBvh8, Leaf::Triangles, "quantized BVH8, gathered triangles"),
      row("qbvh8-tri4i", Nodes::QBvh8, Leaf::IndexedTriangles, "quantized BVH8, indexed triangles"),
      row("clbvh-tri4v", Nodes::CompressedLeaf, Leaf::Triangles,
          "compressed-leaf BVH, gathered triangles"),
      row("clbvh-tri4i", Nodes::CompressedLeaf, Leaf::IndexedTriangles,
          "compressed-leaf BVH, indexed triangles"),
      row("clbvh-compact", Nodes::CompressedLeaf, Leaf::CompactTriangles,
          "compressed-leaf BVH, per-multi-leaf vertex dictionaries"),
      pairs_row("bvh8-pairs", Nodes::Bvh8, PairingMethod::EdgeHeuristic,
                "BVH8, triangle pairs (edge heuristic)"),
      pairs_row("clbvh-pairs", Nodes::CompressedLeaf, PairingMethod::EdgeHeuristic,
                "compressed-leaf BVH, triangle pairs (edge heuristic)"),
      pairs_row("bvh8-pairs-w2", Nodes::Bvh8, PairingMethod::Window2,
                "BVH8, triangle pairs of the paper's baseline (input order, window 2)"),
      row("grid", Nodes::QBvh8, Leaf::Grids, "uncompressed 5x5 sub-grids over grid vertices"),
      lossy_grid_row("lossy-grid", Nodes::CompressedLeaf, Leaf::LossyGrids,
                     GridEncoding::Octahedral, "128-byte lossy sub-grids, encoding 1"),
      lossy_grid_row("lossy-grid-e2", Nodes::CompressedLeaf, Leaf::LossyGrids,
                     GridEncoding::SharedExponent, "128-byte lossy sub-grids, encoding 2"),
      lossy_grid_row("lossy-grid-qbvh8", Nodes::QBvh8, Leaf::LossyGrids, GridEncoding::Octahedral,
                     "128-byte lossy sub-grids under the quantized BVH8"),
      lossy_grid_row("lossy-grid-shared", Nodes::CompressedLeaf, Leaf::SharedLossyGrids,
                     GridEncoding::Octahedral, "68-byte lossy sub-grids over shared corners"),
      // Compressed triangle clusters (prim/cluster.h), one per multi-leaf.
      row("cluster", Nodes::CompressedLeaf, Leaf::Clusters,
          "compressed triangle clusters on one scene-wide lattice (lossy, cluster_error)"),
      row("cluster-lossless", Nodes::CompressedLeaf, Leaf::LosslessClusters,
          "compressed triangle clusters, exact floats"),
  };
  for (const char* t : {"", "T"})
    for (const char* c : {"", "P", "F", "V", "PF", "PV", "FV", "PFV"})
      v.push_back(costa_row(std::string(t) + c));
  return v;
}

std::string vec_text(const Vec3f& p) {
  char t[96];
  std::snprintf(t, sizeof t, "(%.9g, %.9g, %.9g)", double(p.x), double(p.y), double(p.z));
  return t;
}

std::string box_text(const Box3f& b) {
  return "[" + vec_text(b.lo) + " .. " + vec_text(b.hi) + "]";
}

// Any subset of T, P, F, V in that order (may be empty).
bool valid_costa(const std::string& o) {
  const char* order = "TPFV";
  size_t k = 0;
  for (char c : o) {
    while (order[k] && order[k] != c) ++k;
    if (!order[k]) return false;
    ++k;
  }
  return true;
}

bool same_format(const BuildOptions& a, const BuildOptions& b) {
  if (a.nodes != b.nodes || a.leaf != b.leaf) return false;
  switch (a.leaf) {
    case Leaf::Pairs:
      return a.pairing == b.pairing;
    case Leaf::LossyGrids:
    case Leaf::SharedLossyGrids:
      return a.grid_encoding == b.grid_encoding;
    case Leaf::Costa:
      return a.costa == b.costa;
    default:
      return true;
  }
}

const char* nodes_name(Nodes n) {
  switch (n) {
    case Nodes::Bvh8:
      return "bvh8";
    case Nodes::QBvh8:
      return "qbvh8";
    case Nodes::CompressedLeaf:
      return "clbvh";
  }
  return "?";
}

const char* leaf_name(Leaf l) {
  switch (l) {
    case Leaf::Triangles:
      return "tri4v";
    case Leaf::IndexedTriangles:
      return "tri4i";
    case Leaf::CompactTriangles:
      return "compact";
    case Leaf::Pairs:
      return "pairs";
    case Leaf::Grids:
      return "grid";
    case Leaf::LossyGrids:
      return "lossy-grid";
    case Leaf::SharedLossyGrids:
      return "lossy-grid-shared";
    case Leaf::Costa:
      return "costa";
    case Leaf::Clusters:
      return "cluster";
    case Leaf::LosslessClusters:
      return "cluster-lossless";
  }
  return "?";
}

}  // namespace

const std::vector<ConfigInfo>& configs() {
  static const std::vector<ConfigInfo> rows = make_rows();
  return rows;
}

const ConfigInfo* find_config(const std::string& name) {
  for (const ConfigInfo& c : configs())
    if (c.name == name) return &c;
  return nullptr;
}

const ConfigInfo& config_info(const std::string& name) {
  if (const ConfigInfo* c = find_config(name)) return *c;
  std::string list;
  for (const ConfigInfo& c : configs())
    if (c.options.leaf != Leaf::Costa) list += (list.empty() ? "" : ", ") + c.name;
  throw Error("unknown configuration '" + name + "' (known: " + list +
              ", costa-<any of T,P,F,V in that order>)");
}

BuildOptions BuildOptions::from_config(const std::string& name) {
  return config_info(name).options;
}

BuildOptions BuildOptions::from_config(const std::string& name, const BuildOptions& tuning) {
  const BuildOptions& row = config_info(name).options;
  BuildOptions o = tuning;
  o.nodes = row.nodes;
  o.leaf = row.leaf;
  o.grid_encoding = row.grid_encoding;
  o.costa = row.costa;
  o.pairing = row.pairing;
  return o;
}

std::string BuildOptions::config_name() const {
  for (const ConfigInfo& c : configs())
    if (same_format(c.options, *this)) return c.name;
  // Combinations without a row: nodes and leaf (and encoding).
  std::string n = std::string(nodes_name(nodes)) + "-" + leaf_name(leaf);
  if (leaf == Leaf::Costa && !costa.empty()) n += "-" + costa;
  if ((leaf == Leaf::LossyGrids || leaf == Leaf::SharedLossyGrids) &&
      grid_encoding == GridEncoding::SharedExponent)
    n += "-e2";
  if (leaf == Leaf::Pairs && pairing == PairingMethod::Window2) n += "-w2";
  return n;
}

void BuildOptions::check() const {
  if (sah_bins < 2 || sah_bins > 64) throw Error("BuildOptions: sah_bins must be 2..64");
  if (max_leaf_size < 1) throw Error("BuildOptions: max_leaf_size must be >= 1");
  if (threads < 0) throw Error("BuildOptions: threads must be >= 0 (0 = all cores)");
  if (grid_parts != 0 && grid_parts != 1 && grid_parts != 2 && grid_parts != 4)
    throw Error("BuildOptions: grid_parts must be 0 (automatic), 1, 2 or 4");
  if (grid_parts > 1 && nodes != Nodes::CompressedLeaf)
    throw Error(
        "BuildOptions: grid_parts above 1 needs CompressedLeaf nodes (parts are "
        "multi-leaf children)");
  if ((leaf == Leaf::CompactTriangles || leaf == Leaf::SharedLossyGrids || leaf == Leaf::Clusters ||
       leaf == Leaf::LosslessClusters) &&
      nodes != Nodes::CompressedLeaf)
    throw Error("BuildOptions: leaf " + std::string(leaf_name(leaf)) +
                " lives in multi-leaf nodes: it needs nodes = CompressedLeaf");
  if (leaf == Leaf::Costa && !valid_costa(costa))
    throw Error("BuildOptions: costa letters '" + costa +
                "' are not a subset of T, P, F, V in that order");
  // lattice_box: the default (and any box with lo > hi on an axis) is "not given"; a given box has
  // finite corners (an infinite or NaN one would put every vertex off the lattice).
  for (int a = 0; a < 3; ++a)
    if (std::isnan(lattice_box.lo[a]) || std::isnan(lattice_box.hi[a]) ||
        (!lattice_box.empty() &&
         !(std::isfinite(lattice_box.lo[a]) && std::isfinite(lattice_box.hi[a]))))
      throw Error("BuildOptions: lattice_box " + box_text(lattice_box) +
                  " is not a finite box (leave it empty for the meshes' own bounds)");
}

Box3f lattice_box_of(const MeshList& meshes, const BuildOptions& opt) {
  const Box3f& b = opt.lattice_box;
  if (b.empty()) return Box3f();
  for (size_t mi = 0; mi < meshes.size(); ++mi) {
    const MeshView& m = *meshes[mi];
    for (size_t v = 0; v < m.positions.size(); ++v) {
      const Vec3f p = m.positions[v];
      if (is_finite(p) && !b.contains(p))
        throw Error("mesh '" + m.name + "' (" + std::to_string(mi) + "): vertex " +
                    std::to_string(v) + " " + vec_text(p) +
                    " lies outside BuildOptions::lattice_box " + box_text(b) +
                    ", which must contain every finite vertex of the meshes");
    }
  }
  return b;
}

ConfigInfo describe(const BuildOptions& opt) {
  for (const ConfigInfo& c : configs())
    if (same_format(c.options, opt)) {
      ConfigInfo r = c;
      r.options = opt;
      return r;
    }
  ConfigInfo c;
  c.options = opt;
  c.name = opt.config_name();
  c.summary = "a combination without a registry row";
  describe_format(c);
  return c;
}

double ConfigInfo::promised_error(const std::vector<const PolyMesh*>& meshes) const {
  return promised_error(MeshList(meshes).pointers());
}

double ConfigInfo::promised_error(const std::vector<const MeshView*>& meshes) const {
  Box3f bounds;  // the finite positions of every mesh
  for (const MeshView* m : meshes) {
    if (!m) throw Error("promised_error: null mesh");
    check_mesh(*m);
    const Box3f b = m->bounds();
    if (!b.empty()) bounds.extend(b);
  }
  if (!lossy) return 0;
  // The box the format quantizes in: BuildOptions::lattice_box when given, else the meshes'
  // (the formats take the box of the vertices they use, which lies inside this one).
  const Box3f box = options.lattice_box.empty() ? bounds : options.lattice_box;
  if (box.empty()) return 0;
  // Float rounding of a decoded coordinate: a few ulps of the largest coordinate magnitude.
  const double largest = std::max(double(reduce_max(abs(box.lo))), double(reduce_max(abs(box.hi))));
  const double rounding = 8.0 * std::ldexp(largest, -24);
  double d2 = 0;
  for (int a = 0; a < 3; ++a) {
    const double e = double(box.hi[a]) - double(box.lo[a]);
    d2 += e * e;
  }
  switch (options.leaf) {
    case Leaf::Costa: {
      // Costa et al., Listing 4: 16 bits per component in the box, codes rounded to nearest:
      // half a step per axis.
      double h2 = 0;
      for (int a = 0; a < 3; ++a) {
        const double h = 0.5 * (double(box.hi[a]) - double(box.lo[a])) / 65535.0;
        h2 += h * h;
      }
      return std::sqrt(h2) + rounding;
    }
    case Leaf::Clusters: {
      // The lattice's steps (prim/cluster.cpp: fine_lattice_steps' keep the bound, else
      // lattice_steps'; quantize's coarser steps of exact axes move no vertex): rounding moves a
      // vertex by at most half a step per axis.
      const double bound = options.cluster_error * std::sqrt(d2);
      double step[3], h2 = 0;
      cluster::lattice_steps(bound, box, step);
      for (double s : step) h2 += s * s / 4;
      return std::max(bound, std::sqrt(h2)) + rounding;
    }
    case Leaf::LossyGrids:
    case Leaf::SharedLossyGrids: {
      // A vertex is its sub-grid's bilinear patch plus a displacement d quantized to within
      // 0.057 |d| (encoding 1) or 0.055 |d| (encoding 2), and |d| is at most the distance to the
      // farthest corner of its 5x5 sub-grid, 8 cell edges: 0.06 x 8 x L, L the largest distance
      // between two vertices of one input face.
      double L = 0;
      for (const MeshView* m : meshes) {
        uint64_t c = 0;
        for (uint32_t n : m->face_sizes) {
          for (uint32_t i = 0; i < n; ++i)
            for (uint32_t j = i + 1; j < n; ++j) {
              const Vec3f a = m->positions[m->face_indices[c + i]];
              const Vec3f b = m->positions[m->face_indices[c + j]];
              if (is_finite(a) && is_finite(b)) L = std::max(L, double(length(a - b)));
            }
          c += n;
        }
      }
      return 0.06 * 8.0 * L + rounding;
    }
    default:
      throw Error("promised_error: lossy format " + name + " states no bound");
  }
}

std::vector<std::string> all_config_names() {
  std::vector<std::string> v;
  for (const ConfigInfo& c : configs()) v.push_back(c.name);
  return v;
}

SceneFormat format_of(Leaf leaf) {
  switch (leaf) {
    case Leaf::Triangles:
    case Leaf::IndexedTriangles:
    case Leaf::CompactTriangles:
      return {build_triangle_scene, empty_triangle_scene};
    case Leaf::Pairs:
      return {build_pair_scene, empty_pair_scene};
    case Leaf::Grids:
    case Leaf::LossyGrids:
    case Leaf::SharedLossyGrids:
      return {build_grid_scene, empty_grid_scene};
    case Leaf::Costa:
      return {build_costa_scene, empty_costa_scene};
    case Leaf::Clusters:
    case Leaf::LosslessClusters:
      return {build_cluster_scene, empty_cluster_scene};
  }
  throw Error("BuildOptions: unknown leaf format " + std::to_string(int(leaf)));
}

bool is_registered_leaf(uint8_t value) {
  return std::any_of(configs().begin(), configs().end(),
                     [&](const ConfigInfo& c) { return uint8_t(c.options.leaf) == value; });
}

std::optional<DecodedTriangles> decoded_triangles(const std::vector<const PolyMesh*>& meshes,
                                                  const BuildOptions& opt) {
  if (!describe(opt).own_geometry) {
    for (const PolyMesh* m : meshes) {
      if (!m) throw Error("decoded_triangles: null mesh");
      check_mesh(*m);
    }
    return std::nullopt;
  }
  if (opt.leaf == Leaf::Costa) return costa_triangles(meshes, opt);
  if (opt.leaf == Leaf::Clusters) return DecodedTriangles(cluster_triangles(meshes, opt));
  return grid_triangles(meshes, opt);
}

PolyMesh to_mesh(const DecodedTriangles& t, const std::string& name) {
  PolyMesh m;
  m.name = name;
  m.positions = t.vertices;
  m.face_sizes.assign(t.size(), 3);
  m.face_indices.resize(3 * t.size());
  for (size_t i = 0; i < m.face_indices.size(); ++i) m.face_indices[i] = uint32_t(i);
  return m;
}

const char* simd_isa() { return simd::isa_name(); }

}  // namespace slim
