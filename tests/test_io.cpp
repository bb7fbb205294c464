// Tests of the input layer (src/io/, src/mesh/polymesh.cpp): OBJ, PLY, glTF/GLB, .xz, the load()
// dispatch, check_mesh() and summarize(). Good inputs are written by the tests to a temp dir; every
// bad-input test checks that the error names the file and the line or byte offset.
#include <gtest/gtest.h>
#include <lzma.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <iostream>
#include <limits>
#include <random>
#include <string>
#include <vector>

#include "slimrt/mesh.h"
#include "temp_dir.h"
#include "test_util.h"

namespace fs = std::filesystem;
using slim::PolyMesh;

using slim::test::TempDir;

namespace {

std::string xz_compress(const std::string& in) {
  std::string out(lzma_stream_buffer_bound(in.size()), '\0');
  size_t pos = 0;
  lzma_ret r = lzma_easy_buffer_encode(6, LZMA_CHECK_CRC64, nullptr,
                                       reinterpret_cast<const uint8_t*>(in.data()), in.size(),
                                       reinterpret_cast<uint8_t*>(out.data()), &pos, out.size());
  EXPECT_EQ(r, LZMA_OK);
  out.resize(pos);
  return out;
}

// Runs fn, expects a slim::Error whose message contains every one of `parts`.
void expect_error(const std::function<void()>& fn, const std::vector<std::string>& parts) {
  try {
    fn();
    ADD_FAILURE() << "expected slim::Error containing '" << parts.front() << "'";
  } catch (const slim::Error& e) {
    std::string msg = e.what();
    for (const std::string& p : parts)
      EXPECT_NE(msg.find(p), std::string::npos) << "message: " << msg << "\nmissing: " << p;
  }
}
void expect_load_error(const std::string& path, std::vector<std::string> parts) {
  parts.insert(parts.begin(), path);
  expect_error([&] { slim::load(path); }, parts);
}

// Loads `path`; any outcome but success or slim::Error (crash, other exception) fails the test.
bool load_ok_or_error(const std::string& path) {
  try {
    slim::load(path);
    return true;
  } catch (const slim::Error& e) {
    std::string msg = e.what();
    EXPECT_EQ(msg.rfind(path, 0), 0u) << msg;  // starts with the file name
    return false;
  }
}

std::string replaced(std::string s, const std::string& from, const std::string& to) {
  size_t at = s.find(from);
  EXPECT_NE(at, std::string::npos) << from;
  if (at != std::string::npos) s.replace(at, from.size(), to);
  return s;
}

std::vector<uint32_t> face(const PolyMesh& m, size_t f) {
  auto off = m.face_offsets();
  return {m.face_indices.begin() + off[f], m.face_indices.begin() + off[f + 1]};
}

// ---------------------------------------------------------------- binary writers

struct Writer {
  bool big_endian = false;
  std::string bytes;
  template <class T>
  void put(T v) {
    char b[sizeof(T)];
    std::memcpy(b, &v, sizeof(T));
    if (big_endian) std::reverse(b, b + sizeof(T));
    bytes.append(b, sizeof(T));
  }
};

std::string base64(const std::string& in) {
  static const char* k = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
  std::string out;
  size_t i = 0;
  for (; i + 2 < in.size(); i += 3) {
    uint32_t v = uint8_t(in[i]) << 16 | uint8_t(in[i + 1]) << 8 | uint8_t(in[i + 2]);
    for (int s = 18; s >= 0; s -= 6) out += k[(v >> s) & 63];
  }
  if (i + 1 == in.size()) {
    uint32_t v = uint8_t(in[i]) << 16;
    out += k[v >> 18], out += k[(v >> 12) & 63], out += "==";
  } else if (i + 2 == in.size()) {
    uint32_t v = uint8_t(in[i]) << 16 | uint8_t(in[i + 1]) << 8;
    out += k[v >> 18], out += k[(v >> 12) & 63], out += k[(v >> 6) & 63], out += '=';
  }
  return out;
}

// ---------------------------------------------------------------- check_mesh / summarize

PolyMesh small_mesh() {
  PolyMesh m;
  m.name = "small";
  m.positions = {{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0}, {2, 0.5f, 0}, {3, 0, 0}};
  m.face_sizes = {3, 4, 5};
  m.face_indices = {0, 1, 2, 0, 1, 2, 3, 0, 1, 4, 2, 3};
  return m;
}

}  // namespace

TEST(MeshCheck, AcceptsValidMesh) {
  PolyMesh m = small_mesh();
  EXPECT_NO_THROW(slim::check_mesh(m));
  m.normals = {{0, 0, 1}};
  m.normal_indices.assign(m.face_indices.size(), 0);
  m.uvs.assign(m.positions.size(), {});  // per-vertex uvs
  m.face_object = {0, 1, 1};
  m.object_names = {"a", "b"};
  EXPECT_NO_THROW(slim::check_mesh(m));
}

TEST(MeshCheck, RejectsMalformedMeshes) {
  auto expect_bad = [](const PolyMesh& m, std::vector<std::string> parts) {
    parts.insert(parts.begin(), "small");
    expect_error([&] { slim::check_mesh(m); }, parts);
  };
  PolyMesh m = small_mesh();
  m.face_sizes[1] = 2;
  m.face_sizes.push_back(2);
  expect_bad(m, {"face 1", "2 vertices", "at least 3"});

  m = small_mesh();
  m.face_indices[5] = 6;
  expect_bad(m, {"face 1", "vertex index 6 out of range"});

  m = small_mesh();
  m.face_indices.pop_back();
  expect_bad(m, {"corners"});

  m = small_mesh();
  m.normals = {{0, 0, 1}};
  m.normal_indices.assign(m.face_indices.size() - 1, 0);
  expect_bad(m, {"normals index array", "one per corner"});

  m = small_mesh();
  m.normals = {{0, 0, 1}};
  m.normal_indices.assign(m.face_indices.size(), 0);
  m.normal_indices[11] = 1;
  expect_bad(m, {"face 2", "normals index 1 out of range"});

  m = small_mesh();
  m.uvs.assign(m.positions.size() + 1, {});
  expect_bad(m, {"uvs has 7 entries", "one per vertex"});

  m = small_mesh();
  m.face_object = {0, 0};
  expect_bad(m, {"face_object has 2 entries"});

  m = small_mesh();
  m.face_object = {0, 0, 2};
  m.object_names = {"a", "b"};
  expect_bad(m, {"face 2", "object id 2"});
}

TEST(MeshSummary, CountsSizesDegeneratesAndNonFinite) {
  PolyMesh m = small_mesh();
  const float nan = std::numeric_limits<float>::quiet_NaN();
  const float inf = std::numeric_limits<float>::infinity();
  m.positions.push_back({nan, 0, 0});  // 6
  m.positions.push_back({0, inf, 0});  // 7
  m.positions.push_back({9, 9, 9});    // 8 (unused)
  // repeated index; collinear (zero area); quad with one zero-area fan triangle (not degenerate);
  // quad whose two fan triangles are both zero area; triangle with a NaN corner (not counted).
  for (auto f : std::vector<std::vector<uint32_t>>{
           {0, 1, 1}, {0, 1, 5}, {0, 1, 5, 2}, {0, 1, 5, 1}, {0, 6, 1}}) {
    m.face_sizes.push_back(uint32_t(f.size()));
    m.face_indices.insert(m.face_indices.end(), f.begin(), f.end());
  }
  slim::MeshSummary s = slim::summarize(m);
  EXPECT_EQ(s.vertices, 9u);
  EXPECT_EQ(s.faces, 8u);
  EXPECT_EQ(s.triangles, 4u);
  EXPECT_EQ(s.quads, 3u);
  EXPECT_EQ(s.ngons, 1u);
  EXPECT_EQ(s.fan_triangles, 1u + 2 + 3 + 1 + 1 + 2 + 2 + 1);
  EXPECT_EQ(s.degenerate_faces, 3u);
  EXPECT_EQ(s.nonfinite_vertices, 2u);
  EXPECT_EQ(s.bounds.lo, slim::Vec3f(0, 0, 0));
  EXPECT_EQ(s.bounds.hi, slim::Vec3f(9, 9, 9));
}

TEST(MeshSummary, LongPolygonWithRepeatedIndex) {
  PolyMesh m;
  for (int i = 0; i < 40; ++i)
    m.positions.push_back({std::cos(i * 0.157f), std::sin(i * 0.157f), 0});
  m.face_sizes = {40, 40};
  for (uint32_t i = 0; i < 40; ++i) m.face_indices.push_back(i);
  for (uint32_t i = 0; i < 40; ++i) m.face_indices.push_back(i == 39 ? 3 : i);
  EXPECT_EQ(slim::summarize(m).degenerate_faces, 1u);
}

// ---------------------------------------------------------------- OBJ

TEST(IoObj, PolygonsAttributesNegativeIndicesAndObjects) {
  TempDir d{"slimrt_io"};
  std::string path = d.write("mixed.obj",
                             "# test\n"
                             "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 0.5 1.5 0\n"
                             "vt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\n"
                             "vn 0 0 1\nvn 0 0 -1\n"
                             "f 1//1 2//1 3//1\n"           // v//n
                             "o second\r\n"                 // CRLF line
                             "f 1/1/2 2/2/2 3/3/2 4/4/2\n"  // v/t/n quad
                             "g third\n"
                             "f -5 -4 -3 -2 -1\n"  // negative pentagon
                             "f 1/4 2/3 3/2\n"     // v/t
                             "o second\n"          // same object again
                             "f 5 4 3\n");
  PolyMesh m = slim::load(path);
  EXPECT_EQ(m.name, path);
  ASSERT_EQ(m.vertex_count(), 5u);
  ASSERT_EQ(m.face_count(), 5u);
  EXPECT_EQ(m.face_sizes, (std::vector<uint32_t>{3, 4, 5, 3, 3}));
  EXPECT_EQ(face(m, 0), (std::vector<uint32_t>{0, 1, 2}));
  EXPECT_EQ(face(m, 2), (std::vector<uint32_t>{0, 1, 2, 3, 4}));
  EXPECT_EQ(face(m, 4), (std::vector<uint32_t>{4, 3, 2}));
  EXPECT_EQ(m.positions[4], slim::Vec3f(0.5f, 1.5f, 0));
  EXPECT_EQ(m.object_names, (std::vector<std::string>{"default", "second", "third"}));
  EXPECT_EQ(m.face_object, (std::vector<uint32_t>{0, 1, 2, 2, 1}));
  // Normals: 2 from the file + 1 zero normal for corners without one.
  ASSERT_EQ(m.normals.size(), 3u);
  ASSERT_EQ(m.normal_indices.size(), m.face_indices.size());
  EXPECT_EQ(m.normal_indices[0], 0u);
  EXPECT_EQ(m.normal_indices[3], 1u);
  EXPECT_EQ(m.normal_indices[7], 2u);
  EXPECT_EQ(m.normals[2], slim::Vec3f(0, 0, 0));
  ASSERT_EQ(m.uvs.size(), 5u);
  ASSERT_EQ(m.uv_indices.size(), m.face_indices.size());
  EXPECT_EQ(m.uv_indices[0], 4u);  // zero uv
  EXPECT_EQ(m.uv_indices[3], 0u);
  EXPECT_EQ(m.uv_indices[12], 3u);
  EXPECT_EQ(m.uvs[2].x, 1.0f);
  slim::MeshSummary s = slim::summarize(m);
  EXPECT_EQ(s.triangles, 3u);
  EXPECT_EQ(s.quads, 1u);
  EXPECT_EQ(s.ngons, 1u);
}

TEST(IoObj, PolygonWith300CornersAndNoNewlineAtEnd) {
  // tinyobjloader stores face sizes as unsigned char; the loader must not wrap at 256.
  TempDir d{"slimrt_io"};
  std::string obj;
  for (int i = 0; i < 300; ++i)
    obj += "v " + std::to_string(std::cos(i * 0.0209)) + " " +
           std::to_string(std::sin(i * 0.0209)) + " 0\n";
  obj += "f";
  for (int i = 1; i <= 300; ++i) obj.append(" ").append(std::to_string(i));
  obj += "\nf 1 2 3";  // last line without '\n'
  PolyMesh m = slim::load(d.write("ngon.obj", obj));
  ASSERT_EQ(m.face_count(), 2u);
  EXPECT_EQ(m.face_sizes[0], 300u);
  EXPECT_EQ(m.face_indices[299], 299u);
  EXPECT_EQ(m.fan_triangle_count(), 299u);
  EXPECT_TRUE(m.face_object.empty());
  EXPECT_EQ(m.object_names, (std::vector<std::string>{"default"}));
}

// save_obj writes what load reads back: positions bit for bit (9 digits; values no short
// decimal holds), polygons, per-corner normals and uvs, objects.
TEST(IoObj, SaveObjReadsBackTheSameMesh) {
  TempDir d{"slimrt_io"};
  PolyMesh m = slim::load(d.write("mixed.obj",
                                  "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 0.5 1.5 0\n"
                                  "vt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\nvn 0 0 1\nvn 0 0 -1\n"
                                  "f 1/1/1 2/2/1 3/3/1\no second\nf 1/1/2 2/2/2 3/3/2 4/4/2\n"
                                  "g third\nf 5/1/1 4/2/1 3/3/1 2/4/1 1/1/1\n"));
  m.positions[4] = slim::Vec3f(0.1f, 1.0f / 3.0f, -2.5e-7f);
  m.uvs[1].y = 0.7f;
  const std::string path = d.dir() + "/saved.obj";
  slim::save_obj(m, path);
  const PolyMesh r = slim::load(path);
  EXPECT_EQ(r.positions, m.positions);
  EXPECT_EQ(r.face_sizes, m.face_sizes);
  EXPECT_EQ(r.face_indices, m.face_indices);
  EXPECT_EQ(r.normals, m.normals);
  EXPECT_EQ(r.normal_indices, m.normal_indices);
  ASSERT_EQ(r.uvs.size(), m.uvs.size());
  for (size_t i = 0; i < m.uvs.size(); ++i) {
    EXPECT_EQ(r.uvs[i].x, m.uvs[i].x);
    EXPECT_EQ(r.uvs[i].y, m.uvs[i].y);
  }
  EXPECT_EQ(r.uv_indices, m.uv_indices);
  EXPECT_EQ(r.object_names, m.object_names);
  EXPECT_EQ(r.face_object, m.face_object);
  // A folder that does not exist: an error naming the path, nothing written.
  EXPECT_THROW(slim::save_obj(m, d.dir() + "/no/such/dir/x.obj"), slim::Error);
}

// What save_obj cannot keep as it was, as mesh.h says: objects come back numbered by first
// appearance (each face keeps its object's name), per-vertex normals per corner (the same
// values); a NaN coordinate is refused, nothing written.
TEST(IoObj, SaveObjObjectsPerVertexNormalsAndNaN) {
  TempDir d{"slimrt_io"};
  PolyMesh m;
  m.positions = {{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0}};
  m.face_sizes = {3, 3, 3};
  m.face_indices = {0, 1, 2, 0, 2, 3, 1, 2, 3};
  m.normals = {{0, 0, 1}, {0, 1, 0}, {1, 0, 0}, {0, 0, -1}};  // per vertex
  m.object_names = {"first", "second\nline"};
  m.face_object = {0, 1, 0};
  const PolyMesh r = slim::reorder_faces(m, std::vector<uint32_t>{1, 0, 2});
  const std::string path = d.dir() + "/objects.obj";
  slim::save_obj(r, path);
  const PolyMesh back = slim::load(path);
  EXPECT_EQ(back.face_indices, r.face_indices);
  ASSERT_EQ(back.face_object.size(), 3u);
  for (size_t f = 0; f < 3; ++f) {
    const std::string want = r.object_names[r.face_object[f]];
    EXPECT_EQ(back.object_names[back.face_object[f]],
              want == "second\nline" ? "second_line" : want);
  }
  ASSERT_EQ(back.normal_indices.size(), back.face_indices.size());
  for (size_t c = 0; c < back.face_indices.size(); ++c)
    EXPECT_EQ(back.normals[back.normal_indices[c]], m.normals[back.face_indices[c]]) << c;
  PolyMesh bad = m;
  bad.positions[2].y = std::nanf("");
  const std::string nan_path = d.dir() + "/nan.obj";
  try {
    slim::save_obj(bad, nan_path);
    ADD_FAILURE() << "a NaN vertex was written";
  } catch (const slim::Error& e) {
    EXPECT_NE(std::string(e.what()).find("vertex 2"), std::string::npos) << e.what();
  }
  EXPECT_FALSE(fs::exists(nan_path));
}

// reorder_faces moves each face with its corners, attribute indices and object; anything but a
// permutation of the faces is an error.
TEST(MeshReorder, FacesMoveWithTheirAttributes) {
  TempDir d{"slimrt_io"};
  const PolyMesh m = slim::load(d.write("mixed.obj",
                                        "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 0.5 1.5 0\n"
                                        "vt 0 0\nvt 1 0\nvt 1 1\nvn 0 0 1\nvn 0 0 -1\n"
                                        "f 1/1/1 2/2/1 3/3/1\no second\nf 1/1/2 2/2/2 3/3/2 4/1/2\n"
                                        "g third\nf 5/3/1 4/2/1 3/1/1\n"));
  const std::vector<uint32_t> order = {2, 0, 1};
  const PolyMesh r = slim::reorder_faces(m, order);
  EXPECT_EQ(r.positions, m.positions);
  EXPECT_EQ(r.face_sizes, (std::vector<uint32_t>{3, 3, 4}));
  EXPECT_EQ(face(r, 0), face(m, 2));
  EXPECT_EQ(face(r, 1), face(m, 0));
  EXPECT_EQ(face(r, 2), face(m, 1));
  EXPECT_EQ(r.normal_indices, (std::vector<uint32_t>{0, 0, 0, 0, 0, 0, 1, 1, 1, 1}));
  EXPECT_EQ(r.uv_indices, (std::vector<uint32_t>{2, 1, 0, 0, 1, 2, 0, 1, 2, 0}));
  EXPECT_EQ(r.face_object, (std::vector<uint32_t>{2, 0, 1}));
  EXPECT_EQ(r.object_names, m.object_names);
  const std::vector<std::vector<uint32_t>> bad = {{0, 1}, {0, 1, 1}, {0, 1, 3}};
  for (const std::vector<uint32_t>& b : bad)
    EXPECT_THROW(slim::reorder_faces(m, b), slim::Error) << b.size() << " " << b.back();
}

TEST(IoObj, TruncatedFile) {
  TempDir d{"slimrt_io"};
  std::string good = "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\nf 1/1/1 2/1/1 3/1/1\nf 2 4 3\n";
  good = "vt 0 0\nvn 0 0 1\n" + good;
  // Cut inside the last face: "f 2 4" -> a 2-vertex face on line 8.
  expect_load_error(d.write("cut1.obj", good.substr(0, good.size() - 3)),
                    {":8:", "2 vertices", "at least 3"});
  // Cut inside a corner: "f 1/1/1 2/1/1 3/" on line 7.
  std::string cut2 = good.substr(0, good.find("3/1/1") + 2);
  expect_load_error(d.write("cut2.obj", cut2), {":7:", "expected vertex references"});
  // Every prefix either loads or fails with a slim::Error naming the file.
  for (size_t n = 0; n <= good.size(); ++n)
    load_ok_or_error(d.write("prefix.obj", good.substr(0, n)));
}

TEST(IoObj, BadVertexLines) {
  TempDir d{"slimrt_io"};
  expect_load_error(d.write("v2.obj", "v 0 0 0\nv 1 0\n"), {":2:", "2 coordinates", "x y z"});
  expect_load_error(d.write("vx.obj", "v 0 0 0\nv 1 zero 0\n"), {":2:", "not a number"});
  expect_load_error(d.write("v0.obj", "\n\nv\n"), {":3:", "0 coordinates"});
}

TEST(IoObj, GarbageBytes) {
  TempDir d{"slimrt_io"};
  std::mt19937 rng(42);
  std::string junk = "v 0 0 0\nv 1 0 0\n" + std::string(
                                                "\x7f"
                                                "ELF\x02\x01\x01\x00",
                                                8);
  for (int i = 0; i < 4096; ++i) junk += char(rng() & 0xff);
  expect_load_error(d.write("junk.obj", junk), {":3:", "control byte", "expected text"});
}

TEST(IoObj, IndexOutOfRange) {
  TempDir d{"slimrt_io"};
  const std::string v = "v 0 0 0\nv 1 0 0\nv 0 1 0\n";
  expect_load_error(d.write("big.obj", v + "f 1 2 3\n\nf 1 2 4\n"),
                    {":6:", "vertex index out of range", "f 1 2 4"});
  expect_load_error(d.write("neg.obj", v + "f -4 1 2\n"), {":4:", "vertex index out of range"});
  expect_load_error(d.write("zero.obj", v + "f 0 1 2\n"), {":4:", "nonzero"});
  expect_load_error(d.write("normal.obj", v + "vn 0 0 1\nf 1//1 2//2 3//1\n"),
                    {":5:", "normal index out of range"});
  expect_load_error(d.write("uv.obj", v + "vt 0 0\nf 1/1 2/1 3/3\n"),
                    {":5:", "texture index out of range"});
}

TEST(IoObj, FacesWithFewerThanThreeVertices) {
  TempDir d{"slimrt_io"};
  const std::string v = "v 0 0 0\nv 1 0 0\nv 0 1 0\n";
  expect_load_error(d.write("two.obj", v + "f 1 2 3\nf 1 2\n"), {":5:", "face has 2 vertices"});
  expect_load_error(d.write("none.obj", v + "f\n"), {":4:", "face has 0 vertices"});
}

// tinyobjloader would read 1e39 as float infinity and the face would be dropped later without a
// word; a coordinate beyond the float range is an error naming the line, like a literal inf.
TEST(IoObj, FloatOverflowIsAnError) {
  TempDir d{"slimrt_io"};
  expect_error([&] { slim::load(d.write("inf.obj", "v 1 0 0\nv 0 1 0\nv 1e39 0 0\nf 1 2 3\n")); },
               {"inf.obj:3: ", "'1e39' overflows float"});
  expect_error([&] { slim::load(d.write("neg.obj", "v 0 0 -1e40\nv 0 1 0\nv 1 0 0\nf 1 2 3\n")); },
               {"neg.obj:1: ", "overflows float"});
}

// Empty meshes: a file that parses but has no faces loads with 0 faces (a point cloud or an
// empty export is valid input); deciding whether an empty scene is useful is left to the caller.
TEST(IoObj, EmptyMeshLoadsWithZeroFaces) {
  TempDir d{"slimrt_io"};
  PolyMesh m = slim::load(d.write("points.obj", "# only points\nv 0 0 0\nv 1 1 1\n"));
  EXPECT_EQ(m.face_count(), 0u);
  EXPECT_EQ(m.vertex_count(), 2u);
  EXPECT_TRUE(m.object_names.empty());
  EXPECT_EQ(slim::load(d.write("empty.obj", "")).face_count(), 0u);
}

// ---------------------------------------------------------------- PLY

TEST(IoPly, AsciiWithNormalsUvsAndSkippedProperties) {
  TempDir d{"slimrt_io"};
  std::string ply =
      "ply\r\nformat ascii 1.0\ncomment made by hand\n"
      "element vertex 5\nproperty float x\nproperty float y\nproperty float z\n"
      "property uchar red\nproperty float nx\nproperty float ny\nproperty float nz\n"
      "property float s\nproperty float t\n"
      "element face 2\nproperty uchar flags\nproperty list uchar int vertex_indices\n"
      "element edge 1\nproperty int vertex1\nproperty int vertex2\n"
      "end_header\n"
      "0 0 0 255 0 0 1 0 0\n1 0 0 255 0 0 1 1 0\n1 1 0 255 0 0 1 1 1\n"
      "0 1 0 255 0 0 1 0 1\n+2.5 -1e2 -0 7 0 0 1 0.5 0.5\n"
      "9 4 0 1 2 3\n9 3 1 4 2\n"
      "0 1\n";
  PolyMesh m = slim::load(d.write("a.ply", ply));
  ASSERT_EQ(m.vertex_count(), 5u);
  EXPECT_EQ(m.face_sizes, (std::vector<uint32_t>{4, 3}));
  EXPECT_EQ(m.face_indices, (std::vector<uint32_t>{0, 1, 2, 3, 1, 4, 2}));
  EXPECT_EQ(m.positions[4].x, 2.5f);
  EXPECT_EQ(m.positions[4].y, -100.0f);
  EXPECT_EQ(m.uvs[0].x, 0.0f);
  EXPECT_EQ(m.positions[4].z, 0.0f);
  ASSERT_EQ(m.normals.size(), 5u);
  EXPECT_TRUE(m.normal_indices.empty());
  EXPECT_EQ(m.normals[2], slim::Vec3f(0, 0, 1));
  ASSERT_EQ(m.uvs.size(), 5u);
  EXPECT_EQ(m.uvs[2].x, 1.0f);
  EXPECT_EQ(m.uvs[4].y, 0.5f);
}

// Overflow (1e999) is an error naming the line; underflow (1e-999) reads as 0.
TEST(IoPly, AsciiOverflowAndUnderflow) {
  TempDir d{"slimrt_io"};
  const std::string head =
      "ply\nformat ascii 1.0\nelement vertex 1\nproperty double x\nproperty double y\n"
      "property double z\nend_header\n";
  expect_error([&] { slim::load(d.write("o.ply", head + "1e999 0 0\n")); },
               {"o.ply:8: ", "'1e999' overflows double"});
  PolyMesh m = slim::load(d.write("u.ply", head + "1 1e-999 -1\n"));
  EXPECT_EQ(m.positions[0].y, 0.0f);
}

namespace {

// A binary PLY of a unit square (two triangles + one quad face over 5 vertices).
struct PlySpec {
  bool big_endian = false;
  std::string pos_type = "float";  // float, double, short, ...
  std::string count_type = "uchar", index_type = "int";
};

template <class T>
void put_as(Writer& w, const std::string& type, T v) {
  if (type == "float")
    w.put(float(v));
  else if (type == "double")
    w.put(double(v));
  else if (type == "char")
    w.put(int8_t(v));
  else if (type == "uchar")
    w.put(uint8_t(v));
  else if (type == "short")
    w.put(int16_t(v));
  else if (type == "ushort")
    w.put(uint16_t(v));
  else if (type == "int")
    w.put(int32_t(v));
  else if (type == "uint")
    w.put(uint32_t(v));
  else
    ADD_FAILURE() << type;
}

std::string binary_ply(const PlySpec& s, const std::vector<std::array<double, 3>>& v,
                       const std::vector<std::vector<int64_t>>& faces) {
  std::string h = "ply\nformat " +
                  std::string(s.big_endian ? "binary_big_endian" : "binary_little_endian") +
                  " 1.0\nelement vertex " + std::to_string(v.size()) + "\n";
  for (const char* c : {"x", "y", "z"}) h += "property " + s.pos_type + " " + c + "\n";
  h += "property ushort skipme\n";
  h += "element face " + std::to_string(faces.size()) + "\nproperty list " + s.count_type + " " +
       s.index_type + " vertex_index\nproperty list uchar float texcoord\n";
  h += "element material 1\nproperty list uint uchar name\nend_header\n";
  Writer w{s.big_endian};
  for (auto& p : v) {
    for (double c : p) put_as(w, s.pos_type, c);
    w.put(uint16_t(0xBEEF));
  }
  for (auto& f : faces) {
    put_as(w, s.count_type, f.size());
    for (int64_t i : f) put_as(w, s.index_type, i);
    w.put(uint8_t(2));
    w.put(0.5f), w.put(0.25f);
  }
  w.put(uint32_t(3));
  w.bytes += "abc";
  return h + w.bytes;
}

const std::vector<std::array<double, 3>> kSquare = {
    {0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0}, {0.5, 0.5, 1}};
const std::vector<std::vector<int64_t>> kSquareFaces = {{0, 1, 4}, {1, 2, 4}, {0, 1, 2, 3}};

}  // namespace

TEST(IoPly, BinaryEndiannessAndScalarTypes) {
  TempDir d{"slimrt_io"};
  int n = 0;
  for (bool be : {false, true})
    for (std::string pos : {"float", "double", "short", "uchar"})
      for (auto [ct, it] : std::vector<std::pair<std::string, std::string>>{{"uchar", "int"},
                                                                            {"ushort", "uint"},
                                                                            {"int", "ushort"},
                                                                            {"uint", "uchar"},
                                                                            {"char", "short"}}) {
        PlySpec s{be, pos, ct, it};
        SCOPED_TRACE(std::string(be ? "BE " : "LE ") + pos + " " + ct + " " + it);
        PolyMesh m = slim::load(
            d.write(std::to_string(n++) + "b.ply", binary_ply(s, kSquare, kSquareFaces)));
        ASSERT_EQ(m.vertex_count(), 5u);
        EXPECT_EQ(m.face_sizes, (std::vector<uint32_t>{3, 3, 4}));
        EXPECT_EQ(m.face_indices, (std::vector<uint32_t>{0, 1, 4, 1, 2, 4, 0, 1, 2, 3}));
        const float half = pos == "float" || pos == "double" ? 0.5f : 0.0f;
        EXPECT_EQ(m.positions[4], slim::Vec3f(half, half, 1));
        EXPECT_EQ(m.positions[2], slim::Vec3f(1, 1, 0));
        EXPECT_TRUE(m.normals.empty());
      }
}

TEST(IoPly, DoublePositionsKeepFloatPrecision) {
  TempDir d{"slimrt_io"};
  PlySpec s;
  s.pos_type = "double";
  auto v = kSquare;
  v[0] = {1.0 / 3, -1e30, 123456.789};
  PolyMesh m = slim::load(d.write("d.ply", binary_ply(s, v, kSquareFaces)));
  EXPECT_EQ(m.positions[0], slim::Vec3f(float(1.0 / 3), -1e30f, 123456.789f));
}

TEST(IoPly, HeaderCountLargerThanFile) {
  TempDir d{"slimrt_io"};
  // 2^40 vertices: must be refused from the file size, not allocated.
  std::string bin =
      "ply\nformat binary_little_endian 1.0\nelement vertex 1099511627776\n"
      "property float x\nproperty float y\nproperty float z\nend_header\n";
  size_t header = bin.size();
  bin += std::string(120, '\0');
  expect_load_error(d.write("huge.ply", bin),
                    {": byte " + std::to_string(header) + ":", "1099511627776", "120 bytes"});
  // Faces: each needs at least 1 + 3 * 4 bytes.
  std::string f = binary_ply({}, kSquare, kSquareFaces);
  size_t at = f.find("element face 3");
  f.replace(at, 14, "element face 300000000");
  expect_load_error(d.write("hugef.ply", f), {": byte ", "300000000 'face'"});
  std::string ascii =
      "ply\nformat ascii 1.0\nelement vertex 18446744073709551615\n"
      "property float x\nproperty float y\nproperty float z\nend_header\n0 0 0\n";
  expect_load_error(d.write("hugea.ply", ascii), {":3:", "18446744073709551615"});
  // A count that does not fit in 64 bits is a header syntax error.
  ascii.replace(ascii.find("18446744073709551615"), 20, "18446744073709551616");
  expect_load_error(d.write("overflow.ply", ascii), {":3:", "element <name> <count>"});
  // A list count larger than the rest of the file (binary).
  PlySpec s;
  s.count_type = "uint";
  std::string l = binary_ply(s, kSquare, {{0, 1, 2}});
  size_t body = l.find("end_header\n") + 11;
  size_t count_at = body + 5 * (12 + 2);
  std::memcpy(&l[count_at], "\xff\xff\xff\x7f", 4);
  expect_load_error(d.write("list.ply", l), {": byte " + std::to_string(count_at + 4) + ":",
                                             "file ends inside element 'face'"});
}

TEST(IoPly, TruncatedBinary) {
  TempDir d{"slimrt_io"};
  std::string good = binary_ply({}, kSquare, kSquareFaces);
  size_t body = good.find("end_header\n") + 11;
  // Cut in the middle of vertex 2: the element-size check fires at the body start.
  expect_load_error(d.write("t1.ply", good.substr(0, body + 30)),
                    {": byte " + std::to_string(body) + ":", "'vertex'", "30 bytes are left"});
  // Cut inside the last face's index list.
  size_t cut = body + 5 * 14 + 2 * (1 + 12 + 1 + 8) + 1 + 8;
  expect_load_error(d.write("t2.ply", good.substr(0, cut)),
                    {": byte ", "file ends inside element 'face' (record 2 of 3)"});
  // Every prefix is either complete enough or a slim::Error naming the file; never a crash.
  int ok = 0;
  for (size_t n = 0; n <= good.size(); ++n)
    ok += load_ok_or_error(d.write("p.ply", good.substr(0, n)));
  // The skipped trailing 'material' element is checked too, so only the full file loads.
  EXPECT_EQ(ok, 1);
}

TEST(IoPly, TruncatedAscii) {
  TempDir d{"slimrt_io"};
  // Blank-padded values, so that cuts pass the element-size check and end inside a record.
  std::string ply =
      "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
      "property float z\nelement face 1\nproperty list uchar uint vertex_indices\n"
      "end_header\n0.0 0.0 0.0\n1.0 0.0 0.0\n0.0 1.0 0.0\n3   0   1   2\n";
  EXPECT_EQ(slim::load(d.write("ok.ply", ply)).face_count(), 1u);
  expect_load_error(d.write("t.ply", ply.substr(0, ply.size() - 4)),
                    {":13:", "file ends inside element 'face' (record 0 of 1)"});
  expect_load_error(d.write("t2.ply", ply.substr(0, ply.find("0.0 1.0 0.0") + 7)),
                    {":12:", "file ends inside element 'vertex' (record 2 of 3)"});
  // Cut so short that the header's counts cannot fit: refused before reading.
  expect_load_error(d.write("t3.ply", ply.substr(0, ply.find("1.0 0.0 0.0"))),
                    {":3:", "header declares 3 'vertex' elements"});
  for (size_t n = 0; n <= ply.size(); ++n) load_ok_or_error(d.write("p.ply", ply.substr(0, n)));
}

TEST(IoPly, GarbageHeaderAndBytes) {
  TempDir d{"slimrt_io"};
  std::mt19937 rng(7);
  std::string junk;
  for (int i = 0; i < 1000; ++i) junk += char(rng() & 0xff);
  expect_load_error(d.write("junk.ply", junk), {":1:", "expected the PLY magic line 'ply'"});
  expect_load_error(d.write("kw.ply", "ply\nformat ascii 1.0\nelement vertex 1\nbogus line\n"),
                    {":4:", "unknown header keyword 'bogus'"});
  expect_load_error(d.write("fmt.ply", "ply\nformat binary_middle_endian 1.0\nend_header\n"),
                    {":2:", "unknown format"});
  expect_load_error(d.write("type.ply",
                            "ply\nformat ascii 1.0\nelement vertex 1\n"
                            "property float128 x\nend_header\n"),
                    {":4:", "unknown property type 'float128'"});
  expect_load_error(d.write("noend.ply", "ply\nformat ascii 1.0\nelement vertex 1\n"),
                    {":3:", "end_header"});
  expect_load_error(d.write("nox.ply",
                            "ply\nformat ascii 1.0\nelement vertex 1\nproperty float y"
                            "\nend_header\n1\n"),
                    {":3:", "no property x"});
  expect_load_error(d.write("ctl.ply", "ply\nformat ascii 1.0\n\x01\x02\nend_header\n"),
                    {":3:", "control byte"});
  expect_load_error(d.write("val.ply",
                            "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\n"
                            "property float y\nproperty float z\nend_header\n1 zz 3\n"),
                    {":8:", "expected a number, got 'zz'"});
  // Random bytes after a valid binary header: any outcome but a crash.
  std::string h = binary_ply({}, kSquare, kSquareFaces);
  h.resize(h.find("end_header\n") + 11);
  for (int t = 0; t < 50; ++t) {
    std::string body;
    for (int i = 0; i < int(rng() % 200); ++i) body += char(rng() & 0xff);
    load_ok_or_error(d.write("r.ply", h + body));
  }
}

TEST(IoPly, IndexOutOfRangeNegativeAndShortLists) {
  TempDir d{"slimrt_io"};
  // Writes the file; `at` = offset of the second face's count byte.
  auto with_faces = [&](const std::string& name, std::vector<std::vector<int64_t>> f, size_t& at,
                        const std::string& type = "int") {
    PlySpec s;
    s.index_type = type;
    std::string bytes = binary_ply(s, kSquare, f);
    at = bytes.find("end_header\n") + 11 + 5 * 14 + (1 + 12 + 1 + 8);
    return d.write(name, bytes);
  };
  size_t at = 0;
  std::string path = with_faces("r.ply", {{0, 1, 2}, {1, 2, 5}}, at);
  expect_load_error(path, {": byte " + std::to_string(at + 1 + 8) + ":", "face 1", "vertex index 5",
                           "0 <= index < 5"});
  path = with_faces("n.ply", {{0, 1, 2}, {1, -1, 3}}, at);
  expect_load_error(path, {": byte " + std::to_string(at + 1 + 4) + ":", "vertex index -1"});
  path = with_faces("u.ply", {{0, 1, 2}, {1, 4000000000, 3}}, at, "uint");
  expect_load_error(path,
                    {": byte " + std::to_string(at + 1 + 4) + ":", "vertex index 4000000000"});
  path = with_faces("s.ply", {{0, 1, 2}, {1, 2}}, at);
  expect_load_error(path,
                    {": byte " + std::to_string(at) + ":", "face 1 has 2 vertices", "at least 3"});
  std::string ascii =
      "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\n"
      "property float y\nproperty float z\nelement face 2\n"
      "property list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n"
      "0 1 0\n3 0 1 2\n";
  expect_load_error(d.write("ar.ply", ascii + "3 0 1 3\n"), {":14:", "vertex index 3"});
  expect_load_error(d.write("an.ply", ascii + "3 0 -1 2\n"), {":14:", "vertex index -1"});
  expect_load_error(d.write("as.ply", ascii + "2 0 1\n"), {":14:", "face 1 has 2 vertices"});
  expect_load_error(d.write("ac.ply", ascii + "-3 0 1 2\n"), {":14:", "out of range"});
  expect_load_error(d.write("ab.ply", ascii + "3 0 1\n\n\n"), {":14:", "file ends inside"});
}

// NaN and inf (binary or text) are refused naming the byte or line, like OBJ's "nan" and "inf":
// their faces would otherwise be dropped later without a word.
TEST(IoPly, NonFiniteValuesAreRefused) {
  TempDir d{"slimrt_io"};
  for (double bad :
       {std::numeric_limits<double>::quiet_NaN(), -std::numeric_limits<double>::infinity()}) {
    auto v = kSquare;
    v[1] = {0, bad, 0};
    expect_load_error(d.write("nan.ply", binary_ply({}, v, kSquareFaces)),
                      {"nan.ply: byte ", "vertex property 'y'", "expected a finite number"});
  }
  const std::string head =
      "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
      "property float z\nelement face 1\n"
      "property list uchar int vertex_indices\nend_header\n";
  for (const char* bad : {"nan", "inf", "-inf", "NaN", "infinity"}) {
    expect_load_error(d.write("t.ply", head + "0 0 0\n1 0 0\n0 " + bad + " 0\n3 0 1 2\n"),
                      {"t.ply:12: ", "vertex property 'y'", "'" + std::string(bad) + "'",
                       "expected a finite number"});
  }
}

TEST(IoPly, NoFaceElementLoadsWithZeroFaces) {
  TempDir d{"slimrt_io"};
  PolyMesh m = slim::load(d.write("pts.ply",
                                  "ply\nformat ascii 1.0\nelement vertex 2\n"
                                  "property double x\nproperty double y\n"
                                  "property double z\nend_header\n0 0 0\n1 2 3\n"));
  EXPECT_EQ(m.face_count(), 0u);
  EXPECT_EQ(m.vertex_count(), 2u);
  EXPECT_EQ(slim::load(d.write("empty.ply", binary_ply({}, kSquare, {}))).face_count(), 0u);
}

// ---------------------------------------------------------------- glTF

namespace {

// Buffer: 4 float3 positions of a unit square, 6 ushort indices, 4 float3 normals (+z).
std::string square_buffer() {
  Writer w;
  for (float p : {0.f, 0.f, 0.f, 1.f, 0.f, 0.f, 1.f, 1.f, 0.f, 0.f, 1.f, 0.f}) w.put(p);
  for (uint16_t i : {0, 1, 2, 0, 2, 3}) w.put(i);
  for (int k = 0; k < 4; ++k) w.put(0.f), w.put(0.f), w.put(1.f);
  return w.bytes;  // 48 + 12 + 48 = 108 bytes
}

std::string square_gltf_json(const std::string& buffer_json) {
  return R"({
  "asset": {"version": "2.0"},
  "scene": 0,
  "scenes": [{"nodes": [0, 3]}],
  "nodes": [
    {"name": "parent", "translation": [10, 0, 0], "children": [1, 2]},
    {"name": "scaled", "mesh": 0, "scale": [2, 2, 2],
     "rotation": [0, 0, 0.7071067811865476, 0.7071067811865476]},
    {"name": "matrix", "mesh": 1,
     "matrix": [1,0,0,0, 0,1,0,0, 0,0,1,0, 0,0,5,1]},
    {"name": "mirror", "mesh": 0, "scale": [-1, 1, 1]}
  ],
  "meshes": [
    {"name": "square", "primitives": [
      {"attributes": {"POSITION": 2, "NORMAL": 3}, "indices": 1, "mode": 4}]},
    {"name": "soup", "primitives": [
      {"attributes": {"POSITION": 0}},
      {"attributes": {"POSITION": 0}, "mode": 5},
      {"attributes": {"POSITION": 0}, "mode": 6},
      {"attributes": {"POSITION": 0}, "mode": 1}]}
  ],
  "accessors": [
    {"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3"},
    {"bufferView": 1, "componentType": 5123, "count": 6, "type": "SCALAR"},
    {"bufferView": 0, "componentType": 5126, "count": 4, "type": "VEC3"},
    {"bufferView": 2, "componentType": 5126, "count": 4, "type": "VEC3"}
  ],
  "bufferViews": [
    {"buffer": 0, "byteOffset": 0, "byteLength": 48},
    {"buffer": 0, "byteOffset": 48, "byteLength": 12},
    {"buffer": 0, "byteOffset": 60, "byteLength": 48}
  ],
  "buffers": [)" +
         buffer_json +
         R"(]
})";
}

std::string glb(const std::string& json, const std::string& bin) {
  std::string j = json;
  while (j.size() % 4) j += ' ';
  std::string b = bin;
  while (b.size() % 4) b += '\0';
  Writer w;
  w.put(uint32_t(0x46546C67));
  w.put(uint32_t(2));
  w.put(uint32_t(12 + 8 + j.size() + 8 + b.size()));
  w.put(uint32_t(j.size()));
  w.put(uint32_t(0x4E4F534A));
  w.bytes += j;
  w.put(uint32_t(b.size()));
  w.put(uint32_t(0x004E4942));
  w.bytes += b;
  return w.bytes;
}

void expect_near(slim::Vec3f a, slim::Vec3f b) {
  EXPECT_NEAR(a.x, b.x, 1e-5f);
  EXPECT_NEAR(a.y, b.y, 1e-5f);
  EXPECT_NEAR(a.z, b.z, 1e-5f);
}

}  // namespace

TEST(IoGltf, AsciiWithNodeTransformsAndTopologies) {
  TempDir d{"slimrt_io"};
  // Accessor 0: 3 positions (non-indexed "soup"), 2: all 4 (indexed square), 3: normals.
  std::string json =
      square_gltf_json(R"({"byteLength": 108, "uri": "data:application/octet-stream;base64,)" +
                       base64(square_buffer()) + "\"}");
  PolyMesh m = slim::load(d.write("scene.gltf", json));

  // Instances in scene order: scaled square (2 tris), matrix soup (1 + 1 + 1 tris), mirror square.
  ASSERT_EQ(m.face_count(), 2u + 3u + 2u);
  EXPECT_EQ(m.vertex_count(), 4u + 3 * 3u + 4u);
  EXPECT_EQ(m.object_names,
            (std::vector<std::string>{"square", "soup/0", "soup/1", "soup/2", "square"}));
  EXPECT_EQ(m.face_object, (std::vector<uint32_t>{0, 0, 1, 2, 3, 4, 4}));
  // scaled: parent T(10,0,0) * R(90 deg about z) * S(2): (1,0,0) -> (10, 2, 0).
  expect_near(m.positions[1], {10, 2, 0});
  expect_near(m.positions[2], {8, 2, 0});
  // matrix node: translation (0,0,5) under the parent: (1,1,0) -> (11, 1, 5).
  expect_near(m.positions[4 + 2], {11, 1, 5});
  // mirror: x -> -x, and the winding is flipped to keep the front face.
  expect_near(m.positions[13 + 1], {-1, 0, 0});
  EXPECT_EQ(face(m, 5), (std::vector<uint32_t>{13, 15, 14}));
  EXPECT_EQ(face(m, 0), (std::vector<uint32_t>{0, 1, 2}));
  // Strip of 3 vertices = 1 triangle; fan of 3 = 1 triangle (v1, v2, v0).
  EXPECT_EQ(face(m, 3), (std::vector<uint32_t>{7, 8, 9}));
  EXPECT_EQ(face(m, 4), (std::vector<uint32_t>{11, 12, 10}));
  // Normals: rotated +z stays +z; instances without NORMAL get zeros.
  ASSERT_EQ(m.normals.size(), m.positions.size());
  expect_near(m.normals[0], {0, 0, 1});
  expect_near(m.normals[5], {0, 0, 0});
  expect_near(m.normals[13], {0, 0, 1});
  EXPECT_NO_THROW(slim::check_mesh(m));
}

TEST(IoGltf, GlbWithByteIndicesAndExternalGltfBuffer) {
  TempDir d{"slimrt_io"};
  Writer w;
  for (float p : {0.f, 0.f, 0.f, 1.f, 0.f, 0.f, 1.f, 1.f, 0.f, 0.f, 1.f, 0.f}) w.put(p);
  for (uint8_t i : {0, 1, 2, 3}) w.put(i);
  const std::string json = R"({"asset": {"version": "2.0"},
    "meshes": [{"primitives": [{"attributes": {"POSITION": 0}, "indices": 1, "mode": 6}]}],
    "nodes": [{"mesh": 0, "translation": [0, 0, 1]}],
    "accessors": [
      {"bufferView": 0, "componentType": 5126, "count": 4, "type": "VEC3"},
      {"bufferView": 1, "componentType": 5121, "count": 4, "type": "SCALAR"}],
    "bufferViews": [{"buffer": 0, "byteLength": 48}, {"buffer": 0, "byteOffset": 48, "byteLength": 4}],
    "buffers": [{"byteLength": 52}]})";
  PolyMesh m = slim::load(d.write("fan.glb", glb(json, w.bytes)));
  ASSERT_EQ(m.face_count(), 2u);  // fan of 4 = 2 triangles
  EXPECT_EQ(face(m, 0), (std::vector<uint32_t>{1, 2, 0}));
  EXPECT_EQ(face(m, 1), (std::vector<uint32_t>{2, 3, 0}));
  expect_near(m.positions[2], {1, 1, 1});
  EXPECT_EQ(m.object_names, (std::vector<std::string>{"mesh0"}));
  EXPECT_TRUE(m.face_object.empty());

  // Same asset as .gltf with an external .bin next to it (base dir of the file).
  d.write("fan.bin", w.bytes);
  std::string ext = json;
  ext.replace(ext.find(R"({"byteLength": 52})"), 18, R"({"byteLength": 52, "uri": "fan.bin"})");
  EXPECT_EQ(slim::load(d.write("fan.gltf", ext)).face_count(), 2u);
}

TEST(IoGltf, BadInput) {
  TempDir d{"slimrt_io"};
  std::string buf = square_buffer();
  const std::string uri =
      R"({"byteLength": 108, "uri": "data:application/octet-stream;base64,)" + base64(buf) + "\"}";
  const std::string good = square_gltf_json(uri);
  // Accessor past its bufferView.
  expect_load_error(d.write("range.gltf", replaced(good, R"("count": 6)", R"("count": 7)")),
                    {"accessors[1]", "do not fit in bufferViews[1]"});
  // Index past the POSITION count (accessor 0 has 3 vertices; the square uses index 3).
  expect_load_error(d.write("index.gltf", replaced(good, R"("POSITION": 2, "NORMAL")",
                                                   R"("POSITION": 0, "NORMAL")")),
                    {"meshes[0].primitives[0]", "index 3", ">= vertex count 3"});
  // Node cycle, node out of range.
  expect_load_error(
      d.write("cycle.gltf", replaced(good, R"("children": [1, 2])", R"("children": [1, 0])")),
      {"nodes[0]", "reached twice"});
  expect_load_error(
      d.write("node.gltf", replaced(good, R"("children": [1, 2])", R"("children": [1, 9])")),
      {"node index 9 out of range"});
  expect_load_error(
      d.write("draco.gltf",
              replaced(good, R"("scene": 0,)",
                       R"("scene": 0, "extensionsRequired": ["KHR_draco_mesh_compression"],)")),
      {"KHR_draco_mesh_compression is not supported"});
  // JSON syntax error on line 3.
  expect_load_error(d.write("syntax.gltf", replaced(good, R"("scene": 0,)", R"("scene": 0,,)")),
                    {":3:", "invalid JSON"});
  // Accessor without bufferView claiming more elements than the file has bytes.
  expect_load_error(
      d.write("zeros.gltf",
              replaced(good, R"({"bufferView": 0, "componentType": 5126, "count": 3,)",
                       R"({"componentType": 5126, "count": 1000000000000,)")),
      {"accessors[0]", "exceeds the file size"});
  // GLB: truncated, wrong magic, chunk longer than the file.
  std::string g = glb(R"({"asset": {"version": "2.0"}, "buffers": [{"byteLength": 4}]})", "abcd");
  expect_load_error(d.write("t.glb", g.substr(0, g.size() - 2)), {": byte 8:", "truncated"});
  expect_load_error(d.write("m.glb", "GLTF" + g.substr(4)), {": byte 0:", "magic"});
  std::string c = g;
  c[12] = char(0x7f);
  expect_load_error(d.write("c.glb", c), {": byte 12:", "GLB chunk declares"});
  for (size_t n = 0; n <= g.size(); ++n) load_ok_or_error(d.write("p.glb", g.substr(0, n)));
}

// ---------------------------------------------------------------- .xz

TEST(IoXz, RoundTripObjPlyGltf) {
  TempDir d{"slimrt_io"};
  std::string obj = "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\nf 1 2 4 3\n";
  std::string ply = binary_ply({}, kSquare, kSquareFaces);
  const std::string uri = R"({"byteLength": 108, "uri": "data:application/octet-stream;base64,)" +
                          base64(square_buffer()) + "\"}";
  std::string gltf = square_gltf_json(uri);
  for (auto [name, bytes] : std::vector<std::pair<std::string, std::string>>{
           {"a.obj", obj}, {"b.ply", ply}, {"c.gltf", gltf}}) {
    PolyMesh plain = slim::load(d.write(name, bytes));
    PolyMesh packed = slim::load(d.write(name + ".XZ", xz_compress(bytes)));
    EXPECT_EQ(plain.face_indices, packed.face_indices) << name;
    EXPECT_EQ(plain.face_sizes, packed.face_sizes) << name;
    ASSERT_EQ(plain.positions.size(), packed.positions.size()) << name;
    for (size_t i = 0; i < plain.positions.size(); ++i)
      EXPECT_EQ(plain.positions[i], packed.positions[i]);
  }
  // Concatenated xz streams decode as one file.
  PolyMesh two = slim::load(
      d.write("two.obj.xz", xz_compress("v 0 0 0\nv 1 0 0\n") + xz_compress("v 0 1 0\nf 1 2 3\n")));
  EXPECT_EQ(two.face_count(), 1u);
}

TEST(IoXz, TruncatedAndGarbage) {
  TempDir d{"slimrt_io"};
  std::string obj;
  for (int i = 0; i < 2000; ++i)
    obj += "v " + std::to_string(i) + " 0 " + std::to_string(i * i) + "\n";
  std::string xz = xz_compress(obj);
  expect_load_error(d.write("cut.obj.xz", xz.substr(0, xz.size() / 2)),
                    {": byte ", "xz data ends early"});
  expect_load_error(d.write("plain.obj.xz", obj), {": byte 0:", "not xz data"});
  expect_load_error(d.write("empty.obj.xz", ""), {": byte 0:", "ends early"});
  std::string corrupt = xz;
  corrupt[corrupt.size() / 2] ^= 0x55;
  expect_load_error(d.write("bad.obj.xz", corrupt), {": byte ", "xz data"});
  // Every prefix of a small xz file is handled.
  std::string small = xz_compress("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n");
  int ok = 0;
  for (size_t n = 0; n <= small.size(); ++n)
    ok += load_ok_or_error(d.write("p.obj.xz", small.substr(0, n)));
  EXPECT_EQ(ok, 1);
}

// ---------------------------------------------------------------- load() dispatch

TEST(IoLoad, UnknownExtensionAndMissingFile) {
  TempDir d{"slimrt_io"};
  std::string stl = d.write("mesh.stl", "solid x\n");
  expect_load_error(stl, {"unknown extension '.stl'", ".obj, .ply, .gltf or .glb", ".xz"});
  expect_load_error(d.write("mesh.stl.xz", "x"), {"unknown extension '.stl'"});
  expect_load_error(d.write("noext", "x"), {"no file extension"});
  expect_load_error(d.path("missing.obj"), {"cannot open file", "No such file"});
  expect_load_error(d.path("missing.ply.xz"), {"cannot open file"});
  fs::create_directory(d.path("dir.obj"));
  expect_load_error(d.path("dir.obj"), {"not a regular file"});
}

TEST(IoLoad, ProceduralSizeIsParsedStrictly) {
  for (std::string bad :
       {"terrain:0", "terrain:", "terrain:abc", "canyon:-5", "canyon:+8", "terrain:08",
        "terrain:16385", "terrain:99999999999999999999", "terrain:12x", "terrain: 12"})
    expect_error([&] { slim::load(bad); }, {bad + ":", "integer from 1 to 16384"});
}

TEST(IoLoad, ProceduralScenes) {
  for (auto [scene, quads] : std::vector<std::pair<std::string, uint64_t>>{
           {"terrain:8", 64}, {"torus:8", 32}, {"canyon:6", 36}}) {
    PolyMesh m = slim::load(scene);
    slim::MeshSummary s = slim::summarize(m);
    EXPECT_EQ(s.quads, quads) << scene;
    EXPECT_EQ(s.faces, quads) << scene;
    EXPECT_FALSE(m.name.empty());
  }
}

TEST(IoLoad, UppercaseExtension) {
  TempDir d{"slimrt_io"};
  EXPECT_EQ(slim::load(d.write("A.OBJ", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")).face_count(), 1u);
}

// ---------------------------------------------------------------- random mutations

TEST(IoFuzz, MutatedFilesNeverCrash) {
  TempDir d{"slimrt_io"};
  std::mt19937 rng(1234);
  const std::string uri = R"({"byteLength": 108, "uri": "data:application/octet-stream;base64,)" +
                          base64(square_buffer()) + "\"}";
  std::string gltf = square_gltf_json(uri);
  std::vector<std::pair<std::string, std::string>> seeds = {
      {"f.obj",
       "o a\nv 0 0 0\nv 1 0 0\nv 0 1 0\nvn 0 0 1\nvt 0 0\nf 1/1/1 2/1/1 3/1/1\n"
       "g b\nf -1 -2 -3\n"},
      {"f.ply", binary_ply({}, kSquare, kSquareFaces)},
      {"g.ply", binary_ply({true, "double", "ushort", "uint"}, kSquare, kSquareFaces)},
      {"f.gltf", gltf},
      {"f.glb", glb(gltf, square_buffer())}};
  for (auto& [name, seed] : seeds)
    for (int t = 0; t < 300; ++t) {
      std::string s = seed;
      int edits = 1 + int(rng() % 4);
      for (int e = 0; e < edits; ++e) {
        size_t at = rng() % s.size();
        switch (rng() % 3) {
          case 0:
            s[at] = char(rng() & 0xff);
            break;
          case 1:
            s[at] = "0123456789-. /\n"[rng() % 15];
            break;
          default:
            s.erase(at, 1 + rng() % 8);
        }
        if (s.empty()) s.push_back('x');
      }
      load_ok_or_error(d.write(name, s));
    }
}

// ---------------------------------------------------------------- shared data (MANIFEST)

TEST(IoSharedData, CountsMatchManifest) {
  const std::string dir = SLIM_SHARED_DATA;
  SLIM_REQUIRE_SHARED_DATA();
  struct Row {
    const char* file;
    uint64_t vertices, faces, tris, quads, ngons, fan_tris;
    size_t objects;  // OBJ: distinct 'o'/'g' names (or 1 "default"); PLY: none
  };
  // From ../shared/data/MANIFEST. The cruiser's 59 'o' lines use 56 distinct names
  // ("beacons-mast" four times): statements with the same name add to the same object.
  const Row rows[] = {
      {"stanford_bunny.obj.xz", 35947, 69451, 69451, 0, 0, 69451, 1},
      {"spot_quadrangulated.obj", 2930, 2928, 0, 2928, 0, 5856, 1},
      {"spot_control_mesh.obj", 188, 180, 4, 160, 16, 372, 1},
      {"beast.obj.xz", 32311, 32364, 124, 32228, 12, 64618, 1},
      {"sword_quad_dominant.obj.xz", 22293, 22465, 348, 22117, 0, 44582, 1},
      {"fg_cg57_cruiser.obj.xz", 112794, 86375, 6037, 77396, 2942, 180063, 56},
      {"fg_c172p_aircraft.obj.xz", 54467, 47769, 5741, 41284, 744, 98425, 240},
      {"nefertiti.obj.xz", 49971, 99938, 99938, 0, 0, 99938, 1},
      {"ogre.obj.xz", 62194, 124008, 124008, 0, 0, 124008, 1},
      {"koala.obj.xz", 49999, 99994, 99994, 0, 0, 99994, 1},
      {"igea.ply.xz", 134345, 268686, 268686, 0, 0, 268686, 0},
      {"fg_terrain_hawaii.ply.xz", 1056077, 1978330, 1978330, 0, 0, 1978330, 0},
  };
  for (const Row& r : rows) {
    SCOPED_TRACE(r.file);
    const std::string path = dir + "/" + r.file;
    if (!fs::exists(path)) {
      ADD_FAILURE() << "missing " << path;
      continue;
    }
    auto t0 = std::chrono::steady_clock::now();
    PolyMesh m = slim::load(path);
    double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    std::cout << "  load " << r.file << ": " << s << " s\n";
    slim::MeshSummary sum = slim::summarize(m);
    EXPECT_EQ(sum.vertices, r.vertices);
    EXPECT_EQ(sum.faces, r.faces);
    EXPECT_EQ(sum.triangles, r.tris);
    EXPECT_EQ(sum.quads, r.quads);
    EXPECT_EQ(sum.ngons, r.ngons);
    EXPECT_EQ(sum.fan_triangles, r.fan_tris);
    EXPECT_EQ(sum.nonfinite_vertices, 0u);  // the MANIFEST checker found no NaN/Inf
    EXPECT_EQ(m.object_names.size(), r.objects);
    if (r.objects > 1) {
      ASSERT_EQ(m.face_object.size(), m.face_count());
      std::vector<bool> used(r.objects, false);
      for (uint32_t o : m.face_object) used.at(o) = true;
      EXPECT_EQ(std::count(used.begin(), used.end(), true), int64_t(r.objects));
    }
    EXPECT_FALSE(sum.bounds.empty());
  }
}
