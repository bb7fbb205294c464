// The parallel preparation of a build (check_mesh, the coordinate range check, fan
// triangulation in chunks of faces) against plain serial loops: same output, same first error.
#include <algorithm>
#include <cmath>
#include <cstring>
#include <functional>
#include <limits>
#include <string>
#include <vector>

#include "mesh/triangulate.h"
#include "test_util.h"

namespace slim {
namespace {

// Faces of 3..7 corners over a random vertex set, with some non-finite vertices: several
// chunks of FaceChunks::kFaces faces, so the chunk boundaries fall inside runs of every size.
PolyMesh mixed_mesh(uint32_t faces, uint32_t seed, uint32_t nonfinite_every) {
  Rng rng(seed, 3);
  PolyMesh m;
  m.name = "mixed" + std::to_string(seed);
  const uint32_t nv = faces / 2 + 16;
  for (uint32_t i = 0; i < nv; ++i) {
    Vec3f p(rng.uniform(), rng.uniform(), rng.uniform());
    if (nonfinite_every && i % nonfinite_every == 7) p.y = std::numeric_limits<float>::quiet_NaN();
    m.positions.push_back(p);
  }
  for (uint32_t f = 0; f < faces; ++f) {
    const uint32_t n = 3 + rng.next() % 5;
    for (uint32_t k = 0; k < n; ++k) m.face_indices.push_back(rng.next() % nv);
    m.face_sizes.push_back(n);
  }
  return m;
}

// The serial fan triangulation, as triangulate_fan computed it before it ran in parallel.
TriangleMesh serial_fan(const std::vector<const PolyMesh*>& meshes) {
  TriangleMesh out;
  for (uint32_t g = 0; g < meshes.size(); ++g) {
    const PolyMesh& m = *meshes[g];
    const uint32_t base = uint32_t(out.vertices.size());
    out.vertex_base.push_back(base);
    out.vertices.insert(out.vertices.end(), m.positions.begin(), m.positions.end());
    out.input_faces += m.face_count();
    out.input_triangles += m.fan_triangle_count();
    uint64_t c = 0;
    for (uint32_t f = 0; f < m.face_sizes.size(); ++f) {
      const uint32_t n = m.face_sizes[f];
      const uint32_t* idx = &m.face_indices[c];
      c += n;
      bool ok = true;
      for (uint32_t k = 0; k < n; ++k) ok = ok && is_finite(m.positions[idx[k]]);
      if (!ok) {
        out.skipped_faces++;
        continue;
      }
      for (uint32_t k = 1; k + 1 < n; ++k) {
        out.tris.insert(out.tris.end(), {base + idx[0], base + idx[k], base + idx[k + 1]});
        out.geom_ids.push_back(g);
        out.prim_ids.push_back(f);
      }
    }
  }
  return out;
}

TEST(MeshPrep, ParallelFanTriangulationMatchesSerial) {
  const PolyMesh a = mixed_mesh(3 * uint32_t(FaceChunks::kFaces) + 123, 1, 97);
  const PolyMesh b = mixed_mesh(17, 2, 0);                            // less than one chunk
  const PolyMesh c = mixed_mesh(uint32_t(FaceChunks::kFaces), 3, 5);  // exactly one chunk
  PolyMesh empty;
  empty.name = "empty";
  const std::vector<const PolyMesh*> meshes{&a, &empty, &b, &c};
  const TriangleMesh want = serial_fan(meshes);
  const TriangleMesh got = triangulate_fan(meshes);
  ASSERT_GT(want.skipped_faces, 100u);  // the NaN vertices do knock out faces
  EXPECT_EQ(got.skipped_faces, want.skipped_faces);
  EXPECT_EQ(got.input_faces, want.input_faces);
  EXPECT_EQ(got.input_triangles, want.input_triangles);
  EXPECT_EQ(got.vertex_base, want.vertex_base);
  ASSERT_EQ(got.vertices.size(), want.vertices.size());
  for (size_t i = 0; i < got.vertices.size(); ++i) {
    const Vec3f &p = got.vertices[i], &q = want.vertices[i];
    ASSERT_TRUE(std::memcmp(&p, &q, sizeof(Vec3f)) == 0) << "vertex " << i;
  }
  ASSERT_EQ(got.tri_count(), want.tri_count());
  EXPECT_TRUE(std::equal(got.tris.begin(), got.tris.end(), want.tris.begin()));
  EXPECT_TRUE(std::equal(got.geom_ids.begin(), got.geom_ids.end(), want.geom_ids.begin()));
  EXPECT_TRUE(std::equal(got.prim_ids.begin(), got.prim_ids.end(), want.prim_ids.begin()));
  const FaceChunks fc = face_chunks(a);
  ASSERT_EQ(fc.count(), 4u);
  EXPECT_EQ(fc.corner.back(), a.face_indices.size());
}

std::string error_of(const std::function<void()>& fn) {
  try {
    fn();
  } catch (const Error& e) {
    return e.what();
  }
  return "(no error)";
}

// The first bad corner in face order is reported, wherever the corner scan's blocks fall.
TEST(MeshPrep, FirstOutOfRangeIndexIsReported) {
  PolyMesh m = mixed_mesh(40000, 4, 0);
  const uint64_t off = [&] {
    uint64_t c = 0;
    for (uint32_t f = 0; f < 30001; ++f) c += m.face_sizes[f];
    return c;
  }();
  m.face_indices[off + 1] = uint32_t(m.positions.size());       // face 30001, its second corner
  m.face_indices[off + 40] = uint32_t(m.positions.size()) + 5;  // a later face
  const std::string what = error_of([&] { check_mesh(m); });
  EXPECT_NE(
      what.find("face 30001: vertex index " + std::to_string(m.positions.size()) + " out of range"),
      std::string::npos)
      << what;
  m.face_indices[off + 1] = 0;
  m.face_indices[off + 40] = 0;
  m.uvs.assign(3, Vec2f(0.0f, 0.0f));
  m.uv_indices.assign(m.face_indices.size(), 1);
  m.uv_indices[m.face_indices.size() - 1] = 3;  // the last corner: the last face
  const std::string uv = error_of([&] { check_mesh(m); });
  EXPECT_NE(uv.find("face 39999: uvs index 3 out of range"), std::string::npos) << uv;
}

TEST(MeshPrep, FirstVertexBeyondTheCoordinateRangeIsReported) {
  PolyMesh m = mixed_mesh(3 * uint32_t(FaceChunks::kFaces), 5, 0);
  // Two vertices of faces in the second and third chunks go out of range; the report names the
  // first offending corner in face order, as a serial scan finds it.
  auto first_corner = [&](uint32_t face) {
    uint64_t c = 0;
    for (uint32_t f = 0; f < face; ++f) c += m.face_sizes[f];
    return m.face_indices[c];
  };
  m.positions[first_corner(2 * uint32_t(FaceChunks::kFaces) + 9)].x = 1e13f;
  m.positions[first_corner(uint32_t(FaceChunks::kFaces) + 3)].z = -1e13f;
  std::string want;
  uint64_t c = 0;
  for (uint32_t f = 0; f < m.face_sizes.size() && want.empty(); c += m.face_sizes[f], ++f)
    for (uint32_t k = 0; k < m.face_sizes[f] && want.empty(); ++k) {
      const uint32_t v = m.face_indices[c + k];
      if (std::fabs(m.positions[v].x) > 1e12f || std::fabs(m.positions[v].z) > 1e12f)
        want = "vertex " + std::to_string(v) + " of face " + std::to_string(f) + " lies beyond";
    }
  ASSERT_FALSE(want.empty());
  const std::string what = error_of([&] { Scene::build(m, BuildOptions{}); });
  EXPECT_NE(what.find(want), std::string::npos) << what << "\nexpected: " << want;
}

}  // namespace
}  // namespace slim
