// slimrt rays and hits: the query types of slim::Scene, the coordinate range slimrt supports, and
// the traversal counters. Small on purpose: the library's core/, prim/ and bvh/ layers include
// this header, not the scene API.
#pragma once

#include <cstdint>

#include "slimrt/math.h"

namespace slim {

constexpr uint32_t kInvalidID = 0xffffffffu;

// The coordinate range slimrt supports. Beyond it the float products of the watertight test
// overflow (t = inf or a miss) or underflow (misses), as in every float ray tracer. So:
// Scene::build throws slim::Error when a vertex used by a finite face lies beyond
// +-kMaxCoordinate, or when the scene's extent (box diagonal) is nonzero and below kMinExtent;
// rays whose origin lies beyond +-kMaxCoordinate miss.
constexpr float kMaxCoordinate = 1e12f;
constexpr float kMinExtent = 1e-12f;

// Directions whose largest component is below kMinDirection in magnitude count as zero
// directions: t = distance / |dir| would reach 1e30 and beyond, past what the float ray setup
// resolves (the box test's reciprocals are clamped at 1 / kMinDirection).
constexpr float kMinDirection = 1e-18f;

// A ray segment [tnear, tfar]. Rays with a NaN or zero direction (below kMinDirection), a NaN
// origin or one beyond +-kMaxCoordinate, or tnear > tfar (or NaN bounds) never hit anything. A
// hit is reported with a finite t: one whose t would exceed the float range is no hit.
struct Ray {
  Vec3f org;
  float tnear = 0.0f;
  Vec3f dir;
  float tfar = kInf;
};

// Kind of primitive a hit landed on (for debug shading, paper "Costa" Table 4 colours).
enum class PrimKind : uint8_t { Triangle = 0, Quad = 1, Fan = 2, Strip = 3, Pair = 4, Grid = 5 };

struct Hit {
  float t = kInf;
  // Barycentric coordinates of the hit inside the triangle that was hit (weights of its 2nd and
  // 3rd vertex); for grid formats, the per-grid u,v of the paper (grid_u, grid_v in [0,1]).
  float u = 0.0f, v = 0.0f;
  Vec3f Ng;                      // geometric normal of the triangle hit (not normalized)
  uint32_t geomID = kInvalidID;  // index of the input mesh
  uint32_t primID = kInvalidID;  // index of the face in the input mesh
  PrimKind kind = PrimKind::Triangle;

  bool valid() const { return geomID != kInvalidID; }
};

// Counters of one traversal (box tests = individual child boxes tested, prim tests = triangles
// tested, including the triangles of pairs, grids and fans).
struct TraversalCounters {
  uint64_t rays = 0;
  uint64_t node_visits = 0;
  uint64_t box_tests = 0;
  uint64_t prim_tests = 0;
  // Primitive records tested, a triangle pair counting once (the paper's dual triangle test
  // unit, "Fast Triangle Pairing", Results); equals prim_tests for formats without pairs.
  uint64_t prim_records = 0;
};

}  // namespace slim
