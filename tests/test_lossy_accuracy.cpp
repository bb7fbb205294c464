// End-to-end accuracy of every lossy configuration against the INPUT mesh.
//
// Oracle: a double-precision brute force over the input's fan triangles (test_util.h), and the
// error bound each format promises, derived from its specification (never from the scene's own
// statistics or decoded geometry):
//   costa-*V*: 16 bits per component in the scene box (Costa et al., Listing 4; codes round to
//     nearest): every decoded vertex within half a step per axis, e = |step| / 2 with
//     step = (box size) / 65535, plus a few float roundings of lo + q * step.
//   lossy-grid*: a vertex is (bilinear patch of its 5x5 sub-grid's corners) + a quantized
//     displacement d (Benthin et al., Eurographics 2021, section 4.1). Encoding 1:
//     a direction from 1024 first-octant unit vectors on 45 rings of an equal-area map (ring
//     spacing 1/44 in the map radius, at most 43 azimuth steps of pi/2 on a ring; the map
//     stretches angles by at most 2 radially and sqrt(2) tangentially: at most 0.041 rad to the
//     nearest entry) times a length with a 5-bit mantissa (relative error <= 1/64): error
//     <= 0.057 |d|. Encoding 2: 5-bit magnitudes of the smallest power-of-two scale that holds the
//     largest component: per component <= |d| / 31.5, <= 0.055 |d| in all. Both: k = 0.06.
//     |d| <= the largest distance from the vertex to a corner of its sub-grid (the patch is a
//     convex combination of the corners) <= 8 cell edges (5x5 vertices) <= 8 L, L = the largest
//     distance between two vertices of one input face. Global bound: e = 8 k L. Where the
//     sub-grids are known (a 9x9-vertex patch: one grid, cut at 0, 4, 8 along both axes) the
//     bound is per vertex: e_v = k |v - patch(v)|, and for encoding 2 per component: half the
//     scale s, the smallest power of two with 31.5 s >= max |d_a|.
//   Any other lossy configuration (the future compressed clusters): no bound is known here, and
//     the test FAILS until its row is added to spec_bound().
// Rays: half from around the box to a random point in it, half aimed just inside the corner of a
// random input triangle (where the corner vertex's error shows almost in full).
// Vertices: the decoded triangles the scene intersects (costa_triangles(), grid_triangles(); the
// robust consistency test holds the scene to them hit for hit) against the input vertices, per
// axis for costa (half a step), per vertex on the known sub-grid patch for the grids.
// Per ray: every hit point lies within e of the input surface; where the input is hit, the hit
// is within e / max(|cos|, 0.05) of it along the ray (theta: ray vs input normal). A hit may be
// farther only where the ray runs along the surface in between (grazing: the midpoint of the two
// hits lies within 2e of the input surface); a ray may skip the input's first crossing (or miss)
// only where it dips under the input surface by less than 2e (the midpoint of the skipped chord
// lies within 2e of the surface) or, on an open mesh, where it hits within e / max(|cos|, 0.05)
// of the boundary.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <functional>
#include <map>
#include <string>
#include <vector>

#include "slimrt/clusters.h"
#include "slimrt/costa.h"
#include "slimrt/grids.h"
#include "test_util.h"

using namespace slim;
using namespace slim::test;

namespace {

constexpr double kGridK = 0.06;  // displacement error / |displacement|, both encodings

struct SpecBound {
  bool known = false;
  double e = 0;  // scene units
  std::string why;
};

double max_face_diameter(const PolyMesh& m) {
  double L = 0;
  uint64_t c = 0;
  for (uint32_t n : m.face_sizes) {
    for (uint32_t i = 0; i < n; ++i)
      for (uint32_t j = i + 1; j < n; ++j) {
        const Vec3f a = m.positions[m.face_indices[c + i]], b = m.positions[m.face_indices[c + j]];
        if (is_finite(a) && is_finite(b)) L = std::max(L, double(length(a - b)));
      }
    c += n;
  }
  return L;
}

// Float rounding of a decoded coordinate: a few ulps of the largest coordinate magnitude.
double rounding(const Box3f& box) {
  const double m = std::max(double(reduce_max(abs(box.lo))), double(reduce_max(abs(box.hi))));
  return 8.0 * std::ldexp(m, -24);
}

// The bound a lossy configuration promises on `m`, from the format's specification.
SpecBound spec_bound(const std::string& config, const PolyMesh& m) {
  SpecBound b;
  const Box3f box = m.bounds();
  if (config.rfind("costa", 0) == 0 && config.find('V') != std::string::npos) {
    const Vec3f s = box.size();
    double h2 = 0;
    for (int a = 0; a < 3; ++a) h2 += std::pow(0.5 * double(s[a]) / 65535.0, 2);
    b.known = true;
    b.e = std::sqrt(h2) + rounding(box);
    b.why = "half a 16-bit step per axis of the scene box";
  } else if (config.rfind("lossy-grid", 0) == 0) {
    b.known = true;
    b.e = 8.0 * kGridK * max_face_diameter(m) + rounding(box);
    b.why = "0.06 x 8 x the largest face diameter";
  } else if (config == "cluster") {
    b.known = true;
    b.e = BuildOptions::from_config(config).cluster_error * double(length(box.size())) +
          rounding(box);
    b.why = "cluster_error (1e-5) x the box diagonal";
  }
  return b;
}

// The lossy configurations of the registry.
std::vector<std::string> lossy_configs() {
  std::vector<std::string> out;
  for (const std::string& c : all_config_names())
    if (is_lossy_config(c)) out.push_back(c);
  return out;
}

// Boundary edges (used by one face) of the input, welded by index.
std::vector<RefTri> boundary_segments(const PolyMesh& m) {
  std::map<std::pair<uint32_t, uint32_t>, int> uses;
  uint64_t c = 0;
  for (uint32_t n : m.face_sizes) {
    for (uint32_t k = 0; k < n; ++k) {
      const uint32_t a = m.face_indices[c + k], b = m.face_indices[c + (k + 1) % n];
      uses[std::minmax(a, b)]++;
    }
    c += n;
  }
  std::vector<RefTri> out;  // degenerate "triangles" (a, b, b): their distance is the segment's
  for (const auto& [e, u] : uses) {
    if (u != 1) continue;
    RefTri t;
    for (int a = 0; a < 3; ++a) {
      t.v[0][a] = m.positions[e.first][a];
      t.v[1][a] = t.v[2][a] = m.positions[e.second][a];
    }
    out.push_back(t);
  }
  return out;
}

struct Tally {
  uint64_t rays = 0, hits = 0, ref_hits = 0, within = 0, grazing = 0, beyond = 0;
  double worst_ratio = 0;  // largest (deviation / allowed) over the hits
  std::string first;
};

// Checks `nrays` random rays of `s` against the input `m` with the per-hit bound `bound_at(rh)`
// (e for the reference hit rh; rh invalid: the global bound).
Tally check_against_input(const Scene& s, const PolyMesh& m, int nrays, uint32_t seed,
                          const std::function<double(const RefHit&)>& bound_at) {
  const std::vector<RefTri> tris = reference_triangles({&m});
  const std::vector<RefTri> border = boundary_segments(m);
  const double diag = length(m.bounds().size());
  Rng rng(seed, 13);
  Tally t;
  for (int i = 0; i < nrays; ++i) {
    Ray r = random_ray(rng, m.bounds());
    // Every other ray is aimed just inside a fan triangle's corner (98% of the corner vertex),
    // where that vertex's error shows almost in full; not at the vertex itself, which a ray may
    // only touch without crossing the surface.
    if (i % 2 == 1 && !tris.empty()) {
      const RefTri& f = tris[rng.next() % uint32_t(tris.size())];
      const int k = int(rng.next() % 3);
      Vec3f target;
      for (int a = 0; a < 3; ++a)
        target[a] =
            float(0.98 * f.v[k][a] + 0.01 * f.v[(k + 1) % 3][a] + 0.01 * f.v[(k + 2) % 3][a]);
      r.dir = target - r.org;
    }
    const Hit h = s.intersect(r);
    const RefHit rh = reference_intersect(tris, r);
    t.rays++;
    t.hits += h.valid();
    t.ref_hits += rh.valid();
    if (!h.valid() && !rh.valid()) continue;
    const double len = length(r.dir);
    const double e = bound_at(rh);
    double cosv = 1;
    if (rh.valid()) {
      const RefTri& f = tris[rh.tri];
      double n[3], e1[3], e2[3];
      for (int a = 0; a < 3; ++a) e1[a] = f.v[1][a] - f.v[0][a], e2[a] = f.v[2][a] - f.v[0][a];
      n[0] = e1[1] * e2[2] - e1[2] * e2[1];
      n[1] = e1[2] * e2[0] - e1[0] * e2[2];
      n[2] = e1[0] * e2[1] - e1[1] * e2[0];
      const double nl = std::sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
      cosv = nl > 0 ? std::fabs(n[0] * r.dir.x + n[1] * r.dir.y + n[2] * r.dir.z) / (nl * len) : 1;
    }
    const double tol = 1e-5 * (rh.valid() ? rh.t : double(h.t)) * len + 1e-6 * diag;
    const double along = e / std::max(cosv, 0.05) + tol;
    std::string bad;
    if (h.valid()) {
      double p[3];
      point_on_ray(r, h.t, p);
      const double d = surface_distance(tris, p);
      t.worst_ratio = std::max(t.worst_ratio, d / (e + tol));
      if (d > e + tol) bad = "hit " + std::to_string(d) + " off the input surface";
    }
    if (bad.empty() && rh.valid()) {
      const double excess = h.valid() ? (double(h.t) - rh.t) * len : INFINITY;
      if (std::fabs(excess) <= along) {
        t.within++;
        t.worst_ratio = std::max(t.worst_ratio, std::fabs(excess) / along);
      } else if (excess < 0) {
        t.grazing++;  // nearer, on the decoded surface within e of the input (checked above)
      } else {
        // The input crossing was skipped: only where the ray dips under the input surface by
        // less than 2e, or passes the open boundary within `along`.
        Ray r2 = r;
        r2.tnear = float(rh.t * (1 + 1e-6));
        const RefHit next = reference_intersect(tris, r2);
        double q[3];
        bool dip = false;
        if (next.valid()) {
          point_on_ray(r, 0.5 * (rh.t + next.t), q);
          dip = surface_distance(tris, q) <= 2 * e + tol;
        }
        // A grazing ray that enters the decoded surface later runs, in between, between the two
        // surfaces: the midpoint of that stretch lies within 2e of the input surface.
        bool along_surface = false;
        if (h.valid()) {
          point_on_ray(r, 0.5 * (rh.t + double(h.t)), q);
          along_surface = surface_distance(tris, q) <= 2 * e + tol;
        }
        point_on_ray(r, rh.t, q);
        const bool at_border = !border.empty() && surface_distance(border, q) <= along;
        if (dip || along_surface || at_border)
          t.grazing++;
        else
          bad = (h.valid() ? "hit " + std::to_string(excess) + " beyond the input crossing"
                           : std::string("miss")) +
                " (allowed " + std::to_string(along) + ", |cos| " + std::to_string(cosv) + ")";
      }
    }
    if (!bad.empty() && t.beyond++ < 3) t.first += " ray " + std::to_string(i) + ": " + bad + ";";
  }
  return t;
}

// A jittered icosphere (closed triangles, paired into grid cells).
PolyMesh jittered_sphere(int levels, uint32_t seed) {
  PolyMesh m = icosphere(levels);
  Rng rng(seed);
  for (Vec3f& p : m.positions) p = p * (1.0f + 0.02f * (rng.uniform() - 0.5f));
  return m;
}

// costa-*V*: every decoded vertex (costa_triangles(), the triangles the scene intersects) within
// half a 16-bit step PER AXIS of its input vertex (the nearest corner of its input face), plus
// float rounding. Returns the largest |error| / allowed over all vertices and axes.
double costa_vertex_check(const PolyMesh& m, const BuildOptions& opt, uint64_t& over,
                          std::string& first) {
  const CostaTriangles ct = costa_triangles({&m}, opt);
  std::vector<uint64_t> start(m.face_count() + 1, 0);
  for (size_t f = 0; f < m.face_count(); ++f) start[f + 1] = start[f] + m.face_sizes[f];
  const Box3f box = m.bounds();
  const double r = rounding(box);
  double worst = 0;
  for (size_t k = 0; k < ct.vertices.size(); ++k) {
    const uint32_t f = ct.face[k / 3];
    const Vec3f q = ct.vertices[k];
    Vec3f best;
    double bd = INFINITY;
    for (uint64_t c = start[f]; c < start[f + 1]; ++c) {
      const Vec3f v = m.positions[m.face_indices[c]];
      const double d = length(q - v);
      if (d < bd) bd = d, best = v;
    }
    for (int a = 0; a < 3; ++a) {
      const double allowed = 0.5 * double(box.size()[a]) / 65535.0 + r;
      const double err = std::fabs(double(q[a]) - double(best[a]));
      worst = std::max(worst, err / allowed);
      if (err > allowed && over++ < 3)
        first += " face " + std::to_string(f) + " axis " + std::to_string(a) + ": off by " +
                 std::to_string(err) + " > " + std::to_string(allowed) + ";";
    }
  }
  return worst;
}

void expect_within_spec(const PolyMesh& m, int nrays, uint32_t seed) {
  const std::vector<std::string> configs = lossy_configs();
  ASSERT_FALSE(configs.empty());
  for (const std::string& c : configs) {
    SCOPED_TRACE(m.name + " " + c);
    const SpecBound b = spec_bound(c, m);
    ASSERT_TRUE(b.known) << c << " is lossy but has no specification bound here: add its row to "
                         << "spec_bound() (tests/test_lossy_accuracy.cpp)";
    Scene s;
    try {
      s = Scene::build(m, BuildOptions::from_config(c));
    } catch (const Error& err) {
      if (not_applicable(err)) continue;
      ADD_FAILURE() << err.what();
      continue;
    }
    if (c.rfind("costa", 0) == 0) {
      uint64_t over = 0;
      std::string first;
      const double worst = costa_vertex_check(m, BuildOptions::from_config(c), over, first);
      std::printf("  %-16s %-10s decoded vertices within %.3f of half a 16-bit step per axis\n",
                  c.c_str(), m.name.c_str(), worst);
      EXPECT_EQ(over, 0u) << c << " on " << m.name << ":" << first;
    }
    const Tally t = check_against_input(s, m, nrays, seed, [&](const RefHit&) { return b.e; });
    std::printf(
        "  %-16s %-10s e %.3g (%s): %llu rays, %llu hits (input %llu), %llu within, "
        "%llu grazing, worst %.3f of the bound\n",
        c.c_str(), m.name.c_str(), b.e, b.why.c_str(), (unsigned long long)t.rays,
        (unsigned long long)t.hits, (unsigned long long)t.ref_hits, (unsigned long long)t.within,
        (unsigned long long)t.grazing, t.worst_ratio);
    EXPECT_EQ(t.beyond, 0u) << c << " on " << m.name << " (e = " << b.e << "):" << t.first;
    EXPECT_GT(t.within, t.ref_hits * 9 / 10) << c << ": most rays must be checked, not excused";
  }
}

TEST(LossyAccuracy, EveryLossyConfigWithinItsSpecOnAJitteredSphere) {
  PolyMesh m = jittered_sphere(3, 5);  // 1280 triangles
  m.name = "sphere:3";
  expect_within_spec(m, 1500, 1);
}

TEST(LossyAccuracy, EveryLossyConfigWithinItsSpecOnATorus) {
  PolyMesh m = make_torus(24);  // 288 quads, displaced
  m.name = "torus:24";
  expect_within_spec(m, 1500, 2);
}

// A 9x9-vertex heightfield of 8x8 quads with random heights up to 4 cells: one grid, cut into
// four 5x5 sub-grids with corners at 0, 4, 8 (from either end, in either orientation), so the
// displacement of every vertex, and the per-vertex bound k |d|, follow from the input alone.
struct Patch {
  PolyMesh mesh;
  std::vector<double> e;      // per vertex (9 * j + i): k |d| + rounding
  std::vector<double> half2;  // per vertex: encoding 2's per-axis bound, half its scale s (the
                              // smallest power of two with 31.5 s >= max |d_a|: 5-bit magnitudes
                              // rounded to nearest hold up to 31.5 s) + rounding
};

Patch random_patch(uint32_t seed) {
  Patch p;
  Rng rng(seed, 21);
  p.mesh.name = "patch9";
  for (int j = 0; j < 9; ++j)
    for (int i = 0; i < 9; ++i)
      p.mesh.positions.push_back(Vec3f(float(i), float(j), 4 * rng.uniform()));
  for (int j = 0; j < 8; ++j)
    for (int i = 0; i < 8; ++i) {
      const uint32_t v = uint32_t(9 * j + i);
      p.mesh.face_indices.insert(p.mesh.face_indices.end(), {v, v + 1, v + 10, v + 9});
      p.mesh.face_sizes.push_back(4);
    }
  const double r = rounding(p.mesh.bounds());
  p.e.resize(81);
  p.half2.resize(81);
  for (int j = 0; j < 9; ++j)
    for (int i = 0; i < 9; ++i) {
      const int i0 = i <= 4 ? 0 : 4, j0 = j <= 4 ? 0 : 4;
      // A vertex on a sub-grid border belongs to two sub-grids; both give it the same patch
      // point (the border's two corners), so either one will do.
      const double u = (i - i0) / 4.0, v = (j - j0) / 4.0;
      auto P = [&](int a, int b) { return p.mesh.positions[9 * b + a]; };
      double d2 = 0, dmax = 0;
      for (int a = 0; a < 3; ++a) {
        const double patch = (1 - v) * ((1 - u) * P(i0, j0)[a] + u * P(i0 + 4, j0)[a]) +
                             v * ((1 - u) * P(i0, j0 + 4)[a] + u * P(i0 + 4, j0 + 4)[a]);
        d2 += std::pow(double(P(i, j)[a]) - patch, 2);
        dmax = std::max(dmax, std::fabs(double(P(i, j)[a]) - patch));
      }
      p.e[9 * j + i] = kGridK * std::sqrt(d2) + r;
      double sc = 0;
      if (dmax > 0) {
        sc = std::ldexp(1.0, int(std::ceil(std::log2(dmax / 31.5))));
        while (31.5 * sc < dmax) sc *= 2;
        while (31.5 * sc / 2 >= dmax) sc /= 2;
      }
      p.half2[9 * j + i] = 0.5 * sc + r;
    }
  return p;
}

// The largest per-vertex bound over the quads around face f (its vertices' 1-ring): a ray near
// f may hit a neighbouring decoded triangle.
double patch_bound(const Patch& p, uint32_t f) {
  const int fi = int(f % 8), fj = int(f / 8);
  double e = 0;
  for (int j = std::max(0, fj - 1); j <= std::min(8, fj + 2); ++j)
    for (int i = std::max(0, fi - 1); i <= std::min(8, fi + 2); ++i)
      e = std::max(e, p.e[9 * j + i]);
  return e;
}

TEST(LossyAccuracy, LossyGridsWithinThePerVertexBoundOnAKnownSubgridPatch) {
  for (uint32_t seed : {1u, 2u, 3u}) {
    const Patch p = random_patch(seed);
    const GridStats gs = grid_stats({&p.mesh});
    ASSERT_EQ(gs.grids, 1u) << "precondition: the 8x8 quads form one grid";
    ASSERT_EQ(gs.subgrids, 4u) << "precondition: four 5x5 sub-grids";
    const double e_max = *std::max_element(p.e.begin(), p.e.end());
    for (const std::string& c : lossy_configs()) {
      if (c.rfind("lossy-grid", 0) != 0) continue;
      SCOPED_TRACE(c + " seed " + std::to_string(seed));
      const BuildOptions opt = BuildOptions::from_config(c);
      // Decoded vertices against the input vertices: each decoded corner of a face's triangles
      // is the decoded copy of the nearest of the face's 4 input vertices.
      const GridTriangles gt = grid_triangles({&p.mesh}, opt);
      ASSERT_EQ(gt.size(), 128u);
      const bool enc2 = opt.grid_encoding == GridEncoding::SharedExponent;
      uint64_t over = 0;
      double worst = 0, worst2 = 0;
      std::string first;
      for (size_t k = 0; k < gt.vertices.size(); ++k) {
        const uint32_t f = gt.face[k / 3];
        const Vec3f q = gt.vertices[k];
        uint32_t best = 0;
        double bd = INFINITY;
        for (int c4 = 0; c4 < 4; ++c4) {
          const uint32_t v = p.mesh.face_indices[4 * f + c4];
          const double d = length(q - p.mesh.positions[v]);
          if (d < bd) bd = d, best = v;
        }
        worst = std::max(worst, bd / p.e[best]);
        if (bd > p.e[best] && over++ < 3)
          first += " vertex " + std::to_string(best) + " off by " + std::to_string(bd) +
                   " > bound " + std::to_string(p.e[best]) + ";";
        if (!enc2) continue;
        for (int a = 0; a < 3; ++a) {
          const double err = std::fabs(double(q[a]) - double(p.mesh.positions[best][a]));
          worst2 = std::max(worst2, err / p.half2[best]);
          if (err > p.half2[best] && over++ < 3)
            first += " vertex " + std::to_string(best) + " axis " + std::to_string(a) + " off by " +
                     std::to_string(err) + " > half the encoding-2 scale " +
                     std::to_string(p.half2[best]) + ";";
        }
      }
      if (enc2)
        std::printf(
            "  %-18s seed %u: decoded components within %.3f of half the encoding-2 scale\n",
            c.c_str(), seed, worst2);
      std::printf("  %-18s seed %u: decoded vertices within %.3f of the per-vertex bound\n",
                  c.c_str(), seed, worst);
      EXPECT_EQ(over, 0u) << first;
      // End to end: the scene's hits against the input.
      const Scene s = Scene::build(p.mesh, opt);
      const Tally t = check_against_input(s, p.mesh, 1500, seed, [&](const RefHit& rh) {
        return rh.valid() ? patch_bound(p, rh.prim) : e_max;
      });
      std::printf("  %-18s seed %u: %llu rays, %llu within, %llu grazing, worst %.3f\n", c.c_str(),
                  seed, (unsigned long long)t.rays, (unsigned long long)t.within,
                  (unsigned long long)t.grazing, t.worst_ratio);
      EXPECT_EQ(t.beyond, 0u) << t.first;
      EXPECT_GT(t.within, t.ref_hits * 9 / 10);
    }
  }
}

// cluster: every decoded vertex against its INPUT vertex, with the promise of the format's
// specification (prim/cluster.h): one scene-wide lattice with its origin at the low corner of the
// box (the input's box, or BuildOptions::lattice_box when given) and a step per axis: the three
// steps (8 + m) 2^e / 8 (m < 8) with the largest product (of equal products the smallest error,
// then the first with x, then y, the smallest) whose error, half the steps' diagonal with half an
// ulp of the box's largest coordinate per axis, stays within cluster_error x the box diagonal,
// with at most 2^20 - 2 steps across the box and none above the power of two at or above its
// widest extent. Without a given box, where the power-of-two steps (s, the largest with
// s * sqrt(3) / 2 <= that bound, or 2s on the widest axes, ties in axis order, while the error
// stays within the bound) put every vertex of an axis on an even code (a grid), the lattice takes
// the power-of-two steps instead. Every coordinate rounds to the nearest lattice point. So per axis
// |decoded - input| <= step / 2, |decoded - input| <= cluster_error x diagonal, and (decoded -
// origin) / step is an integer (up to one float rounding of origin + q * step). The correspondence
// decoded corner -> input vertex comes from the input faces alone: cluster_triangles() gives the
// fan triangles of each face in triangulation order with their corners in input order (v0, vk,
// vk+1).
TEST(LossyAccuracy, ClusterVerticesFollowClusterError) {
  std::vector<PolyMesh> meshes;
  meshes.push_back(icosphere(4));
  for (Vec3f& p : meshes.back().positions) p = p * 3.0f + Vec3f(10.0f, -2.0f, 0.5f);
  meshes.push_back(random_soup(3000, 41, 0.3f));
  for (Vec3f& p : meshes.back().positions) p = p * 12.0f + Vec3f(3.0f, -5.0f, -4.0f);
  meshes.push_back(load("torus:32"));  // quads: two fan triangles per face
  for (Vec3f& p : meshes.back().positions) p = p * 2.0f + Vec3f(6.0f, 4.0f, -1.0f);
  std::vector<const PolyMesh*> ptrs;
  Box3f input_box;
  for (const PolyMesh& m : meshes) {
    ptrs.push_back(&m);
    input_box.extend(m.bounds());
  }
  struct Case {
    double err;
    Box3f lattice_box;  // empty: the input's box
  };
  Box3f wide = input_box;
  wide.extend(input_box.lo - Vec3f(7.0f, 0.25f, 3.0f));
  wide.extend(input_box.hi + Vec3f(0.5f, 9.0f, 1.0f));
  for (const Case& c : {Case{1e-5, {}}, Case{1e-4, {}}, Case{3e-3, {}}, Case{1e-5, wide}}) {
    const bool given = !c.lattice_box.empty();
    const Box3f box = given ? c.lattice_box : input_box;
    SCOPED_TRACE("cluster_error " + std::to_string(c.err) + (given ? ", lattice_box" : ""));
    BuildOptions opt = BuildOptions::from_config("cluster");
    opt.cluster_error = c.err;
    opt.lattice_box = c.lattice_box;
    const double diag = diagonal(box);
    const double e = c.err * diag;
    const double s = std::exp2(std::floor(std::log2(2.0 * e / std::sqrt(3.0))));
    ASSERT_LE(s * std::sqrt(3.0) / 2, e);
    ASSERT_GT(2 * s * std::sqrt(3.0) / 2, e);
    double step[3] = {s, s, s}, extent[3], ulp[3];
    int order[3] = {0, 1, 2};
    for (int a = 0; a < 3; ++a) {
      extent[a] = double(box.hi[a]) - double(box.lo[a]);
      ulp[a] = std::max(std::fabs(box.lo[a]), std::fabs(box.hi[a])) * 0x1p-24;
    }
    std::stable_sort(order, order + 3, [&](int a, int b) { return extent[a] > extent[b]; });
    for (int a : order) {
      double d2 = 0;
      for (int b = 0; b < 3; ++b) d2 += std::pow((b == a ? step[b] : step[b] / 2) + ulp[b], 2);
      if (std::sqrt(d2) <= e) step[a] *= 2;
    }
    bool grid = false;
    for (int a = 0; a < 3 && !given; ++a) {
      uint32_t any = 0;
      for (const PolyMesh& m : meshes)
        for (const Vec3f& p : m.positions)
          any |= uint32_t(std::nearbyint((double(p[a]) - double(box.lo[a])) / step[a]));
      grid |= any && (any & 1) == 0;
    }
    // The finer steps, over a wider range of exponents than any within the bound.
    const double widest = std::max({extent[0], extent[1], extent[2]});
    const double cap = std::exp2(std::ceil(std::log2(widest)));
    std::vector<double> cand[3];
    for (int a = 0; a < 3; ++a)
      for (int x = int(std::log2(s)) - 6; x <= int(std::log2(s)) + 6; ++x)
        for (int m = 0; m < 8; ++m) {
          const double v = std::ldexp((8 + m) / 8.0, x);
          if (v <= cap && extent[a] / v < (1 << 20) - 2) cand[a].push_back(v);
        }
    double fine[3] = {0, 0, 0}, best = 0, best_d2 = 0;
    for (double x : cand[0])
      for (double y : cand[1])
        for (double z : cand[2]) {
          const double v[3] = {x, y, z};
          double d2 = 0;
          for (int b = 0; b < 3; ++b) d2 += std::pow(v[b] / 2 + ulp[b], 2);
          if (std::sqrt(d2) <= e && (x * y * z > best || (x * y * z == best && d2 < best_d2))) {
            best = x * y * z;
            best_d2 = d2;
            std::copy(v, v + 3, fine);
          }
        }
    ASSERT_GT(best, 0);
    if (!grid) std::copy(fine, fine + 3, step);
    const double round = rounding(box);
    const ClusterTriangles ct = cluster_triangles(ptrs, opt);
    uint64_t expect_tris = 0;
    for (const PolyMesh& m : meshes)
      for (uint32_t n : m.face_sizes) expect_tris += n - 2;
    ASSERT_EQ(ct.size(), expect_tris);
    std::vector<std::vector<uint64_t>> offsets;
    for (const PolyMesh& m : meshes) offsets.push_back(m.face_offsets());
    std::map<std::pair<uint32_t, uint32_t>, uint32_t> fan_seen;  // triangles met per face
    uint64_t over_axis = 0, over_vertex = 0, off_lattice = 0;
    double worst_axis = 0, worst_vertex = 0;
    std::string first;
    for (size_t i = 0; i < ct.size(); ++i) {
      const uint32_t g = ct.geom[i], f = ct.face[i];
      ASSERT_LT(g, meshes.size());
      const PolyMesh& m = meshes[g];
      ASSERT_LT(f, m.face_count());
      const uint32_t k = fan_seen[std::make_pair(g, f)]++;
      ASSERT_LT(k + 2, m.face_sizes[f]) << "face " << g << "/" << f << ": too many triangles";
      const uint32_t* idx = m.face_indices.data() + offsets[g][f];
      const uint32_t corner[3] = {idx[0], idx[k + 1], idx[k + 2]};
      for (int j = 0; j < 3; ++j) {
        const Vec3f in = m.positions[corner[j]], dec = ct.vertices[3 * i + j];
        double d2 = 0;
        for (int a = 0; a < 3; ++a) {
          const double d = std::fabs(double(dec[a]) - double(in[a]));
          d2 += d * d;
          worst_axis = std::max(worst_axis, d / (step[a] / 2));
          if (d > step[a] / 2 + round && over_axis++ < 3)
            first += " vertex " + std::to_string(g) + "/" + std::to_string(corner[j]) + " axis " +
                     std::to_string(a) + " off by " + std::to_string(d) + " > half the step " +
                     std::to_string(step[a] / 2) + ";";
          const double q = (double(dec[a]) - double(box.lo[a])) / step[a];
          if (std::fabs(q - std::nearbyint(q)) > round / step[a] && off_lattice++ < 3)
            first += " vertex " + std::to_string(g) + "/" + std::to_string(corner[j]) + " axis " +
                     std::to_string(a) + " at " + std::to_string(q) + " steps from the origin;";
        }
        worst_vertex = std::max(worst_vertex, std::sqrt(d2) / e);
        if (std::sqrt(d2) > e + round && over_vertex++ < 3)
          first += " vertex " + std::to_string(g) + "/" + std::to_string(corner[j]) + " off by " +
                   std::to_string(std::sqrt(d2)) + " > cluster_error x diagonal " +
                   std::to_string(e) + ";";
      }
    }
    for (uint32_t g = 0; g < meshes.size(); ++g)
      for (uint32_t f = 0; f < meshes[g].face_count(); ++f)
        EXPECT_EQ(fan_seen[std::make_pair(g, f)] + 2, meshes[g].face_sizes[f])
            << "face " << g << "/" << f;
    std::printf(
        "  cluster_error %.0e%s: steps %g, %g, %g%s, decoded axes within %.3f of step/2, "
        "vertices within %.3f of cluster_error x diagonal\n",
        c.err, given ? " (lattice_box)" : "", step[0], step[1], step[2], grid ? " (grid)" : "",
        worst_axis, worst_vertex);
    EXPECT_EQ(over_axis, 0u) << first;
    EXPECT_EQ(over_vertex, 0u) << first;
    EXPECT_EQ(off_lattice, 0u) << first;
    // The lattice is used, not merely respected: some coordinate moves by more than a quarter
    // step (a finer lattice than promised would keep every error below step / 4).
    EXPECT_GT(worst_axis, 0.5);
  }
}

}  // namespace
