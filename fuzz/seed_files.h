// Small valid input files of every format slim::load() reads, generated in memory: the seed
// corpus of the fuzz targets (fuzz/make_seeds.cpp writes them at run time; no mesh file is kept
// in git) and the inputs of the truncation sweep (tests/test_robust_io.cpp).
//
//   for (const slim::seeds::SeedFile& f : slim::seeds::all_seeds())
//     write(f.name, f.bytes);    // f.name carries the extension that picks the loader
//
// Each file is tiny (under 2 KiB) but touches most of its reader: attributes, groups, negative
// indices and n-gons (OBJ); every scalar type, both endiannesses, skipped properties and elements
// (PLY); node transforms, several topologies, byte/short indices and a data: URI (glTF); the GLB
// container; concatenated xz streams.
#pragma once

#include <lzma.h>

#include <algorithm>
#include <array>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <stdexcept>
#include <string>
#include <vector>

namespace slim::seeds {

struct SeedFile {
  std::string name;   // file name: the extension selects the loader ("a.obj", "b.ply.xz", ...)
  std::string bytes;  // file content
};

// Little- or big-endian byte writer.
struct ByteWriter {
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

inline std::string base64(const std::string& in) {
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

// xz (CRC64, `preset` 0-9) of `in`. Throws std::runtime_error if liblzma fails (it does not on
// these sizes). Preset 6 is xz's default; preset 0 needs 3 MiB instead of 94 MiB to encode.
inline std::string xz_compress(const std::string& in, uint32_t preset = 6) {
  std::string out(lzma_stream_buffer_bound(in.size()), '\0');
  size_t pos = 0;
  if (lzma_easy_buffer_encode(preset, LZMA_CHECK_CRC64, nullptr,
                              reinterpret_cast<const uint8_t*>(in.data()), in.size(),
                              reinterpret_cast<uint8_t*>(out.data()), &pos, out.size()) != LZMA_OK)
    throw std::runtime_error("lzma_easy_buffer_encode failed");
  out.resize(pos);
  return out;
}

// ---- OBJ ----------------------------------------------------------------------------------------

// A closed cube (6 quads) with uvs, normals, two groups, a triangle fan face, negative indices.
inline std::string obj_cube() {
  return "# cube\n"
         "o box\n"
         "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 0 0 1\nv 1 0 1\nv 1 1 1\nv 0 1 1\n"
         "vt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\n"
         "vn 0 0 -1\nvn 0 0 1\nvn 0 -1 0\nvn 1 0 0\nvn 0 1 0\nvn -1 0 0\n"
         "f 1/1/1 4/4/1 3/3/1 2/2/1\n"
         "f 5/1/2 6/2/2 7/3/2 8/4/2\n"
         "g sides\n"
         "f 1//3 2//3 6//3 5//3\n"
         "f 2/2 3/3 7/3 6/2\n"
         "f -5 -1 -2 -6\r\n"
         "f 1 5 8 4\n"
         "s off\n"
         "l 1 2\n";
}

// ---- PLY ----------------------------------------------------------------------------------------

// The unit square as 5 vertices (a centre point) and 4 triangles, plus one quad face, in any
// PLY encoding: ascii or binary, any position / list count / index type.
struct PlyLayout {
  enum Format { Ascii, BinaryLE, BinaryBE } format = BinaryLE;
  std::string pos_type = "float";  // float, double, short, int, ...
  std::string count_type = "uchar", index_type = "int";
  bool normals = true, uvs = true;
};

inline std::string ply_square(const PlyLayout& L) {
  const std::array<std::array<double, 3>, 5> v = {
      {{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0}, {0.5, 0.5, 0}}};
  const std::vector<std::vector<int>> faces = {
      {0, 1, 4}, {1, 2, 4}, {2, 3, 4}, {3, 0, 4}, {0, 1, 2, 3}};
  const char* fmt = L.format == PlyLayout::Ascii      ? "ascii"
                    : L.format == PlyLayout::BinaryLE ? "binary_little_endian"
                                                      : "binary_big_endian";
  std::string h =
      std::string("ply\nformat ") + fmt + " 1.0\ncomment slimrt seed\n" + "element vertex 5\n";
  for (const char* c : {"x", "y", "z"}) h += "property " + L.pos_type + " " + c + "\n";
  h += "property uchar red\n";
  if (L.normals) h += "property float nx\nproperty float ny\nproperty float nz\n";
  if (L.uvs) h += "property float s\nproperty float t\n";
  h += "element face 5\nproperty list " + L.count_type + " " + L.index_type +
       " vertex_indices\nproperty short flags\n";
  h += "element material 1\nproperty float shine\nend_header\n";

  ByteWriter w;
  w.big_endian = L.format == PlyLayout::BinaryBE;
  auto put_as = [&](const std::string& t, double x) {
    if (L.format == PlyLayout::Ascii) {
      char buf[32];
      std::snprintf(buf, sizeof buf, t == "float" || t == "double" ? "%g " : "%.0f ", x);
      w.bytes += buf;
      return;
    }
    if (t == "float")
      w.put(float(x));
    else if (t == "double")
      w.put(double(x));
    else if (t == "char")
      w.put(int8_t(x));
    else if (t == "uchar")
      w.put(uint8_t(x));
    else if (t == "short")
      w.put(int16_t(x));
    else if (t == "ushort")
      w.put(uint16_t(x));
    else if (t == "int")
      w.put(int32_t(x));
    else
      w.put(uint32_t(x));
  };
  auto eol = [&] {
    if (L.format == PlyLayout::Ascii) w.bytes.back() = '\n';
  };
  const bool integer_pos = L.pos_type != "float" && L.pos_type != "double";
  for (const auto& p : v) {
    for (double c : p) put_as(L.pos_type, integer_pos ? c * 2 : c);
    put_as("uchar", 200);
    if (L.normals) put_as("float", 0), put_as("float", 0), put_as("float", 1);
    if (L.uvs) put_as("float", p[0]), put_as("float", p[1]);
    eol();
  }
  for (const auto& f : faces) {
    put_as(L.count_type, double(f.size()));
    for (int i : f) put_as(L.index_type, i);
    put_as("short", -3);
    eol();
  }
  put_as("float", 0.25);
  eol();
  return h + w.bytes;
}

// ---- glTF / GLB ---------------------------------------------------------------------------------

// Buffer: 4 float3 positions of a unit square (48 B), 6 ushort indices (12 B), 4 float3 normals
// (48 B), 4 uint8 fan indices (4 B): 112 bytes.
inline std::string gltf_buffer() {
  ByteWriter w;
  for (float p : {0.f, 0.f, 0.f, 1.f, 0.f, 0.f, 1.f, 1.f, 0.f, 0.f, 1.f, 0.f}) w.put(p);
  for (uint16_t i : {0, 1, 2, 0, 2, 3}) w.put(i);
  for (int k = 0; k < 4; ++k) w.put(0.f), w.put(0.f), w.put(1.f);
  for (uint8_t i : {0, 1, 2, 3}) w.put(i);
  return w.bytes;
}

// A scene with TRS, matrix and mirrored nodes, indexed triangles, a non-indexed soup, a strip, a
// byte-indexed fan and a line primitive (skipped). `buffer_json` is the one buffer entry.
inline std::string gltf_json(const std::string& buffer_json) {
  return R"({
  "asset": {"version": "2.0"},
  "scene": 0,
  "scenes": [{"nodes": [0, 3]}],
  "nodes": [
    {"name": "parent", "translation": [10, 0, 0], "children": [1, 2]},
    {"name": "scaled", "mesh": 0, "scale": [2, 2, 2],
     "rotation": [0, 0, 0.7071067811865476, 0.7071067811865476]},
    {"name": "matrix", "mesh": 1, "matrix": [1,0,0,0, 0,1,0,0, 0,0,1,0, 0,0,5,1]},
    {"name": "mirror", "mesh": 0, "scale": [-1, 1, 1]}
  ],
  "meshes": [
    {"name": "square", "primitives": [
      {"attributes": {"POSITION": 2, "NORMAL": 3}, "indices": 1, "mode": 4}]},
    {"name": "soup", "primitives": [
      {"attributes": {"POSITION": 0}},
      {"attributes": {"POSITION": 2}, "mode": 5},
      {"attributes": {"POSITION": 2}, "indices": 4, "mode": 6},
      {"attributes": {"POSITION": 0}, "mode": 1}]}
  ],
  "accessors": [
    {"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3"},
    {"bufferView": 1, "componentType": 5123, "count": 6, "type": "SCALAR"},
    {"bufferView": 0, "componentType": 5126, "count": 4, "type": "VEC3",
     "min": [0, 0, 0], "max": [1, 1, 0]},
    {"bufferView": 2, "componentType": 5126, "count": 4, "type": "VEC3"},
    {"bufferView": 3, "componentType": 5121, "count": 4, "type": "SCALAR"}
  ],
  "bufferViews": [
    {"buffer": 0, "byteOffset": 0, "byteLength": 48},
    {"buffer": 0, "byteOffset": 48, "byteLength": 12},
    {"buffer": 0, "byteOffset": 60, "byteLength": 48},
    {"buffer": 0, "byteOffset": 108, "byteLength": 4}
  ],
  "buffers": [)" +
         buffer_json + R"(]
})";
}

// The .gltf seed: its buffer inline as a base64 data: URI.
inline std::string gltf_embedded() {
  const std::string b = gltf_buffer();
  return gltf_json(R"({"byteLength": )" + std::to_string(b.size()) +
                   R"(, "uri": "data:application/octet-stream;base64,)" + base64(b) + "\"}");
}

// The GLB container: header, JSON chunk (space-padded), BIN chunk (zero-padded).
inline std::string glb_container(const std::string& json, const std::string& bin) {
  std::string j = json, b = bin;
  while (j.size() % 4) j += ' ';
  while (b.size() % 4) b += '\0';
  ByteWriter w;
  w.put(uint32_t(0x46546C67));  // "glTF"
  w.put(uint32_t(2));
  w.put(uint32_t(12 + 8 + j.size() + (b.empty() ? 0 : 8 + b.size())));
  w.put(uint32_t(j.size()));
  w.put(uint32_t(0x4E4F534A));  // "JSON"
  w.bytes += j;
  if (!b.empty()) {
    w.put(uint32_t(b.size()));
    w.put(uint32_t(0x004E4942));  // "BIN\0"
    w.bytes += b;
  }
  return w.bytes;
}

// The .glb seed: the same scene with its buffer in the BIN chunk.
inline std::string glb_scene() {
  const std::string b = gltf_buffer();
  return glb_container(gltf_json(R"({"byteLength": )" + std::to_string(b.size()) + "}"), b);
}

// ---- everything ---------------------------------------------------------------------------------

// One small valid file per input format (the truncation sweep's inputs), in this order: OBJ,
// PLY ascii, PLY binary LE, PLY binary BE, glTF, GLB, OBJ.xz, PLY.xz, GLB.xz.
inline std::vector<SeedFile> one_per_format() {
  PlyLayout le, be, ascii;
  be.format = PlyLayout::BinaryBE;
  ascii.format = PlyLayout::Ascii;
  return {{"cube.obj", obj_cube()},
          {"square_ascii.ply", ply_square(ascii)},
          {"square_le.ply", ply_square(le)},
          {"square_be.ply", ply_square(be)},
          {"scene.gltf", gltf_embedded()},
          {"scene.glb", glb_scene()},
          {"cube.obj.xz", xz_compress(obj_cube())},
          {"square_le.ply.xz", xz_compress(ply_square(le))},
          {"scene.glb.xz", xz_compress(glb_scene())}};
}

// The seed corpus: one_per_format() plus PLY variants of every scalar type and a few edge files
// (empty mesh, vertices only, concatenated xz streams).
inline std::vector<SeedFile> all_seeds() {
  std::vector<SeedFile> s = one_per_format();
  const char* types[][3] = {{"double", "ushort", "uint"},
                            {"short", "char", "short"},
                            {"int", "uint", "ushort"},
                            {"float", "int", "uchar"}};
  int k = 0;
  for (auto fmt : {PlyLayout::Ascii, PlyLayout::BinaryLE, PlyLayout::BinaryBE})
    for (auto& t : types) {
      PlyLayout L;
      L.format = fmt;
      L.pos_type = t[0];
      L.count_type = t[1];
      L.index_type = t[2];
      L.normals = (k & 1) != 0;
      L.uvs = (k & 2) != 0;
      s.push_back({"types" + std::to_string(k++) + ".ply", ply_square(L)});
    }
  s.push_back({"empty.obj", "# nothing\n"});
  s.push_back({"points.obj", "v 1 2 3\nv 4 5 6\nv 1e30 -1e-30 nan\n"});
  s.push_back({"ngon.obj", "v 0 0 0\nv 2 0 0\nv 2 2 0\nv 1 1 0\nv 0 2 0\nf 1 2 3 4 5\n"});
  s.push_back({"verts.ply",
               "ply\nformat ascii 1.0\nelement vertex 2\nproperty double x\nproperty double y\n"
               "property double z\nend_header\n0 0 0\n1 2 3\n"});
  s.push_back({"minimal.gltf", R"({"asset": {"version": "2.0"}})"});
  s.push_back({"minimal.glb", glb_container(R"({"asset": {"version": "2.0"}})", "")});
  s.push_back(
      {"two.obj.xz", xz_compress("v 0 0 0\nv 1 0 0\n") + xz_compress("v 0 1 0\nf 1 2 3\n")});
  return s;
}

}  // namespace slim::seeds
