// glTF 2.0 reader through tinygltf (Debian libtinygltf-dev). Only geometry is needed, so images
// are never decoded: TINYGLTF_NO_STB_IMAGE(_WRITE) keeps stb out of this translation unit (the
// renderer owns the stb implementation) and a no-op image loader accepts embedded images.
//
// tinygltf checks the JSON structure but not the ranges of accessors, buffer views and node
// references, so every one is checked here before any allocation, and the node graph is walked
// with an explicit stack that rejects cycles and shared children (glTF nodes form a tree).
#define TINYGLTF_IMPLEMENTATION
#define TINYGLTF_NO_STB_IMAGE
#define TINYGLTF_NO_STB_IMAGE_WRITE
#define TINYGLTF_NO_EXTERNAL_IMAGE
#include <tiny_gltf.h>

#include "io/gltf.h"

#include <algorithm>
#include <bit>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <string_view>
#include <vector>

#include "io/float_range.h"
#include "slimrt/error.h"
#include "slimrt/output.h"

namespace slim::detail {
namespace {

static_assert(std::endian::native == std::endian::little, "glTF buffers are little-endian");

constexpr uint32_t kGlbMagic = 0x46546C67;      // "glTF"
constexpr uint32_t kGlbChunkJson = 0x4E4F534A;  // "JSON"

// Column-major 4x4 matrix, as glTF stores it: m[col * 4 + row].
struct Mat4 {
  double m[16] = {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1};
  double operator()(int row, int col) const { return m[col * 4 + row]; }
};

Mat4 mul(const Mat4& a, const Mat4& b) {
  Mat4 r;
  for (int c = 0; c < 4; ++c)
    for (int rr = 0; rr < 4; ++rr) {
      double s = 0;
      for (int k = 0; k < 4; ++k) s += a(rr, k) * b(k, c);
      r.m[c * 4 + rr] = s;
    }
  return r;
}

bool bad_image_loader(tinygltf::Image*, const int, std::string*, std::string*, int, int,
                      const unsigned char*, int, void*) {
  return true;  // geometry only: images are kept undecoded
}

// External buffers (uri = a file beside the .gltf), read by slimrt instead of tinygltf: its reader
// sizes the buffer by seeking to the end, which for a directory gives 2^63 - 1 on ext4 (fuzz_gltf
// finding: a URI decoding to "./" asked for a 2^63-byte allocation). Only regular files of at
// most kMaxExternalBuffer bytes are read (larger ones, or special files such as /proc/kcore that
// report 128 TiB, are refused before any allocation).
constexpr uintmax_t kMaxExternalBuffer = uintmax_t(1) << 32;  // 4 GiB, as the JSON and GLB
bool read_external_file(std::vector<unsigned char>* out, std::string* err, const std::string& path,
                        void*) {
  auto fail = [&](const std::string& why) {
    if (err) *err += why + "\n";
    return false;
  };
  std::error_code ec;
  if (!std::filesystem::is_regular_file(path, ec))
    return fail(
        "exists but is not a regular file (a folder or device); expected a binary buffer "
        "file");
  const uintmax_t size = std::filesystem::file_size(path, ec);
  if (ec) return fail(ec.message());
  if (size > kMaxExternalBuffer)
    return fail("is " + std::to_string(size) + " bytes; expected at most 4 GiB");
  std::ifstream f(path, std::ios::binary);
  if (!f) return fail("cannot be opened");
  out->resize(size_t(size));
  if (size && !f.read(reinterpret_cast<char*>(out->data()), std::streamsize(size)))
    return fail("read error");
  return true;
}

// tinygltf's FileExists opens the file; this one only asks whether the name exists, so a file
// that exists but is refused is reported by read_external_file with the reason instead of
// "File not found".
bool external_file_exists(const std::string& path, void*) {
  std::error_code ec;
  return std::filesystem::exists(path, ec);
}

uint32_t load_u32(const uint8_t* p) {
  uint32_t v;
  std::memcpy(&v, p, 4);
  return v;
}

// Checks the GLB container (header and chunk lengths) with byte offsets; tinygltf trusts the BIN
// chunk length by up to 8 bytes. Returns the length declared in the header.
uint32_t check_glb(const std::string& src, std::string_view data) {
  const auto* p = reinterpret_cast<const uint8_t*>(data.data());
  if (data.size() < 12) throw_at_byte(src, 0, "file too short for the 12-byte GLB header");
  if (load_u32(p) != kGlbMagic) throw_at_byte(src, 0, "expected the GLB magic 'glTF'");
  if (load_u32(p + 4) != 2)
    throw_at_byte(src, 4, "GLB version " + std::to_string(load_u32(p + 4)) + "; expected 2");
  const uint32_t length = load_u32(p + 8);
  if (length > data.size())
    throw_at_byte(src, 8,
                  "GLB header declares " + std::to_string(length) + " bytes but the file has " +
                      std::to_string(data.size()) + " (truncated file)");
  uint64_t off = 12;
  for (int chunk = 0; off < length; ++chunk) {
    if (length - off < 8)
      throw_at_byte(src, off, "file ends inside a GLB chunk header; expected 8 bytes");
    const uint32_t chunk_len = load_u32(p + off), chunk_type = load_u32(p + off + 4);
    if (chunk_len > length - off - 8)
      throw_at_byte(src, off,
                    "GLB chunk declares " + std::to_string(chunk_len) + " bytes but only " +
                        std::to_string(length - off - 8) + " are left");
    if (chunk == 0 && chunk_type != kGlbChunkJson)
      throw_at_byte(src, off + 4, "first GLB chunk must be of type JSON");
    off += 8 + uint64_t(chunk_len);
  }
  if (length < 20) throw_at_byte(src, 12, "GLB has no JSON chunk");
  return length;
}

// Deepest nesting of JSON arrays and objects accepted. nlohmann's DOM and tinygltf's conversion
// of `extras` into tinygltf::Value recurse once per level, so a deep enough file (about 20,000
// levels on an 8 MiB stack) overflows the call stack; real glTF files nest a few tens of levels.
constexpr uint32_t kMaxJsonDepth = 1000;

// glTF properties that tinygltf reads into an int (glTF 2.0: indices and enums). Its reader
// converts a larger number by wrapping (a node's "mesh": 4294967296 became mesh 0) and skips a
// non-integer one ("mesh": 1e10 dropped the mesh without a word), so these are checked first.
bool is_int_property(std::string_view key) {
  static constexpr std::string_view kKeys[] = {
      "mesh",    "scene",         "nodes", "children", "buffer", "bufferView", "byteStride",
      "indices", "componentType", "mode",  "material", "skin",   "camera",     "target"};
  for (std::string_view k : kKeys)
    if (k == key) return true;
  return false;
}

// One pass over JSON text, without recursion, before the recursive parser sees it: checks the
// nesting depth (kMaxJsonDepth) and that the glTF int properties (is_int_property, and the values
// of "attributes" and morph "targets") are integers in the int range. Strings are skipped with
// their escapes; "extras" and "extensions" are not looked into (user data). `first_byte` is the
// offset of `json` in the file, for the message.
void check_json(const std::string& src, std::string_view json, bool binary, uint64_t first_byte) {
  struct Frame {
    bool object;
    bool int_values;  // values of this object (attributes) or items of this array are ints
    bool skip;        // inside extras/extensions
    std::string key;  // the key this container is the value of
  };
  std::vector<Frame> stack;
  std::string key;  // last key read in the innermost object
  bool expect_key = false;
  uint64_t line = 1;
  auto fail = [&](size_t i, const std::string& what) {
    if (binary) throw_at_byte(src, first_byte + i, what);
    throw_at_line(src, line, what);
  };
  for (size_t i = 0; i < json.size(); ++i) {
    const char c = json[i];
    if (c == '\n') {
      ++line;
    } else if (c == '"') {
      const size_t start = ++i;
      for (; i < json.size() && json[i] != '"'; ++i) {
        if (json[i] == '\\')
          ++i;
        else if (json[i] == '\n')
          ++line;
      }
      if (expect_key && !stack.empty() && stack.back().object) {
        key.assign(json.substr(start, std::min<size_t>(i - start, 64)));
        expect_key = false;
      }
    } else if (c == ',') {
      expect_key = !stack.empty() && stack.back().object;
    } else if (c == '[' || c == '{') {
      if (stack.size() >= kMaxJsonDepth)
        fail(i, "JSON nests arrays/objects more than " + std::to_string(kMaxJsonDepth) +
                    " levels deep; expected at most " + std::to_string(kMaxJsonDepth));
      Frame f{c == '{', false, false, {}};
      if (!stack.empty()) {
        const Frame& top = stack.back();
        f.key = top.object ? key : top.key;
        f.skip = top.skip || (top.object && (key == "extras" || key == "extensions"));
      }
      f.int_values =
          f.key == "attributes" || f.key == "targets" || (!f.object && is_int_property(f.key));
      stack.push_back(std::move(f));
      expect_key = c == '{';
    } else if (c == ']' || c == '}') {
      if (!stack.empty()) stack.pop_back();
      expect_key = false;
    } else if (c == '-' || (c >= '0' && c <= '9')) {
      size_t j = i;
      while (j < json.size() &&
             std::string_view("+-.0123456789eE").find(json[j]) != std::string_view::npos)
        ++j;
      const std::string_view number = json.substr(i, j - i);
      i = j - 1;
      if (stack.empty() || stack.back().skip) continue;
      const Frame& top = stack.back();
      const bool checked = top.object ? (top.int_values || is_int_property(key)) : top.int_values;
      if (!checked) continue;
      const std::string name = top.object ? key : top.key;
      int64_t v = 0;
      auto [end, ec] = std::from_chars(number.data(), number.data() + number.size(), v);
      if (ec != std::errc() || end != number.data() + number.size() || v < INT32_MIN ||
          v > INT32_MAX)
        fail(i, "\"" + name + "\" is " + std::string(number.substr(0, 40)) +
                    "; expected an integer from 0 to 2147483647 (a glTF index or enum)");
    }
  }
}

// tinygltf messages that quote a whole data: URI or state the wrong rule are replaced by what was
// expected and what was found.
std::string explain_tinygltf(const std::string& line) {
  auto starts = [&](const char* p) { return line.rfind(p, 0) == 0; };
  if (starts("Invalid `byteStride' value")) {
    const size_t colon = line.rfind(':');
    const std::string found = colon == std::string::npos ? "?" : line.substr(colon + 2);
    return "a bufferView has byteStride " + found +
           "; expected a multiple of 4 from 4 to 252 (glTF 2.0 bufferView.byteStride)";
  }
  if (starts("Failed to decode 'uri'"))
    return "a buffer's data: URI does not decode to its byteLength bytes; expected base64 data "
           "(application/octet-stream or application/gltf-buffer) of at least byteLength bytes";
  if (starts("File size mismatch")) return line.substr(0, 300);
  return line;
}

[[noreturn]] void throw_tinygltf(const std::string& src, const std::string& err, bool binary) {
  std::string msg = explain_tinygltf(err.substr(0, err.find('\n')));
  if (msg.size() > 300) msg = msg.substr(0, 300) + "...";  // URIs can be huge
  size_t at = msg.find("at line ");
  if (at != std::string::npos) {
    uint64_t line = std::strtoull(msg.c_str() + at + 8, nullptr, 10);
    std::string rest = msg.substr(at + 3);
    if (binary) throw_at_byte(src, 20, "invalid JSON chunk: " + rest);
    if (line > 0) throw_at_line(src, line, "invalid JSON: " + msg);
  }
  if (msg.empty()) msg = "unknown error";
  if (binary) throw_at_byte(src, 20, "invalid glTF: " + msg);
  throw Error(src + ": invalid glTF: " + msg);
}

class Flattener {
 public:
  Flattener(const std::string& src, const tinygltf::Model& model, size_t input_bytes, PolyMesh& out)
      : src_(src), m_(model), input_bytes_(input_bytes), out_(out) {}

  void run() {
    collect_instances();
    for (const Instance& in : instances_)
      for (const tinygltf::Primitive& p : m_.meshes[in.mesh].primitives) {
        if (!is_surface(p.mode)) continue;
        any_normals_ |= p.attributes.count("NORMAL") > 0;
        any_uvs_ |= p.attributes.count("TEXCOORD_0") > 0;
      }
    check_expansion();
    // Sized once: push_back's doubling would hold up to twice the scene (and copy it).
    out_.positions.reserve(size_t(vertices_));
    if (any_normals_) out_.normals.reserve(size_t(vertices_));
    if (any_uvs_) out_.uvs.reserve(size_t(vertices_));
    out_.face_indices.reserve(size_t(indices_));
    out_.face_sizes.reserve(size_t(indices_ / 3));
    out_.face_object.reserve(size_t(indices_ / 3));
    for (const Instance& in : instances_)
      for (size_t p = 0; p < m_.meshes[in.mesh].primitives.size(); ++p) emit(in, p);
    if (out_.object_names.size() <= 1) out_.face_object.clear();
  }

 private:
  struct Instance {
    int mesh;
    Mat4 world;
    int node = -1;  // -1: a mesh drawn without nodes (identity transform)
  };

  static bool is_surface(int mode) { return mode >= 4 && mode <= 6; }

  // Every node that references a mesh gets its own copy of the mesh (the PolyMesh has no
  // instances), so a small file with many nodes on one big mesh expands without bound. The
  // expansion is sized from the accessor counts before anything is copied and must fit the
  // memory budget (slim::memory_budget(): half the machine's memory) and 2^32-1 vertices.
  void check_expansion() {
    const uint64_t per_vertex = 12 + (any_normals_ ? 12 : 0) + (any_uvs_ ? 8 : 0);
    uint64_t& vertices = vertices_;
    uint64_t& indices = indices_;
    auto add = [](uint64_t& sum, uint64_t v) {
      sum = v > UINT64_MAX / 64 - sum ? UINT64_MAX / 64 : sum + v;
    };
    for (const Instance& in : instances_)
      for (const tinygltf::Primitive& p : m_.meshes[in.mesh].primitives) {
        if (!is_surface(p.mode)) continue;
        // The same range checks as read(), so a bad accessor is reported as such.
        auto pos = p.attributes.find("POSITION");
        const uint64_t nv =
            pos == p.attributes.end() ? 0 : locate(pos->second, 3, "POSITION", false).count;
        add(vertices, nv);
        const uint64_t ni = p.indices >= 0 ? locate(p.indices, 1, "indices", true).count : nv;
        add(indices, p.mode == TINYGLTF_MODE_TRIANGLES ? ni : 3 * ni);
      }
    // face_indices (4 bytes per index) + face_sizes and face_object (8 bytes per triangle).
    const uint64_t bytes = vertices * per_vertex + indices * 4 + indices / 3 * 8;
    const uint64_t budget = memory_budget();
    const std::string what = std::to_string(instances_.size()) +
                             " mesh instances (nodes referencing meshes) expand to " +
                             std::to_string(vertices) + " vertices and " +
                             std::to_string(indices / 3) + " triangles";
    if (vertices > UINT32_MAX)
      throw Error(src_ + ": " + what + "; expected at most 2^32-1 vertices in the flattened scene");
    if (bytes > budget)
      throw Error(src_ + ": " + what + ", about " + format_bytes(bytes) + "; expected at most " +
                  format_bytes(budget) + " (half of this machine's memory)");
  }

  [[noreturn]] void fail(const std::string& where, const std::string& what) const {
    throw Error(src_ + ": " + where + ": " + what);
  }

  Mat4 local(int n) const {
    const tinygltf::Node& node = m_.nodes[n];
    const std::string where = "nodes[" + std::to_string(n) + "]";
    Mat4 r;
    if (!node.matrix.empty()) {
      if (node.matrix.size() != 16) fail(where, "matrix must have 16 numbers");
      std::copy(node.matrix.begin(), node.matrix.end(), r.m);
      return r;
    }
    if (!node.translation.empty() && node.translation.size() != 3)
      fail(where, "translation must have 3 numbers");
    if (!node.rotation.empty() && node.rotation.size() != 4)
      fail(where, "rotation must have 4 numbers (quaternion x, y, z, w)");
    if (!node.scale.empty() && node.scale.size() != 3) fail(where, "scale must have 3 numbers");
    double s[3] = {1, 1, 1}, q[4] = {0, 0, 0, 1};
    if (!node.scale.empty()) std::copy(node.scale.begin(), node.scale.end(), s);
    if (!node.rotation.empty()) std::copy(node.rotation.begin(), node.rotation.end(), q);
    double len = std::sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]);
    if (len > 0)
      for (double& c : q) c /= len;
    const double x = q[0], y = q[1], z = q[2], w = q[3];
    const double rot[3][3] = {{1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)},
                              {2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)},
                              {2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)}};
    for (int c = 0; c < 3; ++c)
      for (int rr = 0; rr < 3; ++rr) r.m[c * 4 + rr] = rot[rr][c] * s[c];  // R * S
    if (!node.translation.empty())
      for (int k = 0; k < 3; ++k) r.m[12 + k] = node.translation[k];  // T * (R * S)
    return r;
  }

  void check_node(int n, const std::string& where) const {
    if (n < 0 || size_t(n) >= m_.nodes.size())
      fail(where, "node index " + std::to_string(n) + " out of range (" +
                      std::to_string(m_.nodes.size()) + " nodes)");
  }

  void collect_instances() {
    std::vector<int> roots;
    if (!m_.scenes.empty()) {
      int s =
          m_.defaultScene >= 0 && size_t(m_.defaultScene) < m_.scenes.size() ? m_.defaultScene : 0;
      roots = m_.scenes[s].nodes;
      for (int r : roots) check_node(r, "scenes[" + std::to_string(s) + "]");
    } else if (!m_.nodes.empty()) {
      std::vector<uint8_t> is_child(m_.nodes.size(), 0);
      for (size_t n = 0; n < m_.nodes.size(); ++n)
        for (int c : m_.nodes[n].children) {
          check_node(c, "nodes[" + std::to_string(n) + "].children");
          is_child[c] = 1;
        }
      for (size_t n = 0; n < m_.nodes.size(); ++n)
        if (!is_child[n]) roots.push_back(int(n));
    } else {
      for (size_t i = 0; i < m_.meshes.size(); ++i) instances_.push_back({int(i), Mat4{}, -1});
      return;
    }
    // Explicit stack: a 100000-deep chain of nodes must not overflow the call stack.
    std::vector<uint8_t> seen(m_.nodes.size(), 0);
    std::vector<std::pair<int, Mat4>> stack;
    for (auto it = roots.rbegin(); it != roots.rend(); ++it) stack.push_back({*it, Mat4{}});
    while (!stack.empty()) {
      auto [n, parent] = stack.back();
      stack.pop_back();
      const std::string where = "nodes[" + std::to_string(n) + "]";
      if (seen[n])
        fail(where, "node is reached twice (a cycle or a shared child); glTF nodes form a tree");
      seen[n] = 1;
      const tinygltf::Node& node = m_.nodes[n];
      Mat4 world = mul(parent, local(n));
      if (node.mesh >= 0) {
        if (size_t(node.mesh) >= m_.meshes.size())
          fail(where, "mesh index " + std::to_string(node.mesh) + " out of range (" +
                          std::to_string(m_.meshes.size()) + " meshes)");
        instances_.push_back({node.mesh, world, n});
      } else if (node.mesh < -1) {
        fail(where, "negative mesh index");
      }
      for (auto it = node.children.rbegin(); it != node.children.rend(); ++it) {
        check_node(*it, where + ".children");
        stack.push_back({*it, world});
      }
    }
  }

  // Where accessor `index` lies, every range checked (no allocation).
  struct Located {
    const uint8_t* base = nullptr;  // null: no bufferView (zeros)
    size_t stride = 0, elem = 0, count = 0;
    int ct = 0, csize = 0;
    std::string where;
  };
  Located locate(int index, int ncomp, const std::string& what, bool integer_only) const {
    Located L;
    L.where = "accessors[" + std::to_string(index) + "] (" + what + ")";
    const std::string& where = L.where;
    if (index < 0 || size_t(index) >= m_.accessors.size())
      fail(what, "accessor index " + std::to_string(index) + " out of range (" +
                     std::to_string(m_.accessors.size()) + " accessors)");
    const tinygltf::Accessor& a = m_.accessors[index];
    if (tinygltf::GetNumComponentsInType(uint32_t(a.type)) != ncomp)
      fail(where, "expected " + std::string(ncomp == 1 ? "SCALAR" : "VEC" + std::to_string(ncomp)));
    const int csize = tinygltf::GetComponentSizeInBytes(uint32_t(a.componentType));
    if (csize <= 0) fail(where, "unknown componentType " + std::to_string(a.componentType));
    const int ct = a.componentType;
    if (integer_only && ct != TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE &&
        ct != TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT && ct != TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT)
      fail(where, "indices must be unsigned byte, short or int");
    const size_t elem = size_t(csize) * ncomp;
    const size_t count = a.count;
    L.ct = ct, L.csize = csize, L.elem = elem, L.count = count, L.stride = elem;
    if (count == 0) return L;

    if (a.bufferView >= 0) {
      std::string_view span = view(a.bufferView, where);
      const tinygltf::BufferView& bv = m_.bufferViews[a.bufferView];
      if (bv.byteStride != 0) L.stride = bv.byteStride;
      const size_t stride = L.stride;
      if (stride < elem)
        fail(where, "byteStride " + std::to_string(stride) + " is smaller than an element (" +
                        std::to_string(elem) + " bytes)");
      if (a.byteOffset > span.size() || elem > span.size() - a.byteOffset ||
          count - 1 > (span.size() - a.byteOffset - elem) / stride)
        fail(where, std::to_string(count) + " elements from byteOffset " +
                        std::to_string(a.byteOffset) + " do not fit in bufferViews[" +
                        std::to_string(a.bufferView) + "] (" + std::to_string(span.size()) +
                        " bytes)");
      L.base = reinterpret_cast<const uint8_t*>(span.data()) + a.byteOffset;
    } else if (a.bufferView < -1) {
      fail(where, "negative bufferView index");
    } else if (count > input_bytes_) {
      // No bufferView means all zeros: nothing in the file bounds the count, so cap it by the
      // file size instead of allocating whatever the JSON claims.
      fail(where, "count " + std::to_string(count) + " without a bufferView exceeds the file size");
    }
    return L;
  }

  // Reads accessor `index` as count x ncomp values of T (conv converts one component).
  template <class T, class Conv>
  std::vector<T> read(int index, int ncomp, const std::string& what, Conv conv,
                      bool integer_only = false) const {
    const Located L = locate(index, ncomp, what, integer_only);
    const tinygltf::Accessor& a = m_.accessors[index];
    const std::string& where = L.where;
    const uint8_t* base = L.base;
    const size_t stride = L.stride, elem = L.elem, count = L.count;
    const int ct = L.ct, csize = L.csize;
    std::vector<T> out;
    if (count == 0) return out;

    out.assign(count * ncomp, T{});
    if (base)
      for (size_t i = 0; i < count; ++i)
        for (int c = 0; c < ncomp; ++c)
          out[i * ncomp + c] = conv(base + i * stride + size_t(c) * csize, ct, a.normalized);

    if (a.sparse.isSparse) {
      const auto& sp = a.sparse;
      if (sp.count <= 0 || size_t(sp.count) > count)
        fail(where, "sparse.count must be 1.." + std::to_string(count));
      const size_t n = size_t(sp.count);
      const int ict = sp.indices.componentType;
      const int isize = tinygltf::GetComponentSizeInBytes(uint32_t(ict));
      if (ict != TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE &&
          ict != TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT &&
          ict != TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT)
        fail(where, "sparse indices must be unsigned byte, short or int");
      std::string_view iv = view(sp.indices.bufferView, where + ".sparse.indices");
      std::string_view vv = view(sp.values.bufferView, where + ".sparse.values");
      if (sp.indices.byteOffset < 0 || size_t(sp.indices.byteOffset) > iv.size() ||
          n > (iv.size() - size_t(sp.indices.byteOffset)) / size_t(isize))
        fail(where, "sparse indices do not fit in their bufferView");
      if (sp.values.byteOffset < 0 || size_t(sp.values.byteOffset) > vv.size() ||
          n > (vv.size() - size_t(sp.values.byteOffset)) / elem)
        fail(where, "sparse values do not fit in their bufferView");
      const auto* ip = reinterpret_cast<const uint8_t*>(iv.data()) + sp.indices.byteOffset;
      const auto* vp = reinterpret_cast<const uint8_t*>(vv.data()) + sp.values.byteOffset;
      for (size_t k = 0; k < n; ++k) {
        uint64_t i = uint64_t(conv_uint(ip + k * isize, ict));
        if (i >= count)
          fail(where, "sparse index " + std::to_string(i) + " >= count " + std::to_string(count));
        for (int c = 0; c < ncomp; ++c)
          out[i * ncomp + c] = conv(vp + k * elem + size_t(c) * csize, ct, a.normalized);
      }
    }
    return out;
  }

  // The bytes of buffer view `index`, range-checked against its buffer.
  std::string_view view(int index, const std::string& where) const {
    if (index < 0 || size_t(index) >= m_.bufferViews.size())
      fail(where, "bufferView index " + std::to_string(index) + " out of range (" +
                      std::to_string(m_.bufferViews.size()) + " bufferViews)");
    const tinygltf::BufferView& bv = m_.bufferViews[index];
    const std::string vwhere = "bufferViews[" + std::to_string(index) + "]";
    if (bv.buffer < 0 || size_t(bv.buffer) >= m_.buffers.size())
      fail(vwhere, "buffer index " + std::to_string(bv.buffer) + " out of range");
    const auto& data = m_.buffers[bv.buffer].data;
    if (bv.byteOffset > data.size() || bv.byteLength > data.size() - bv.byteOffset)
      fail(vwhere, "byteOffset " + std::to_string(bv.byteOffset) + " + byteLength " +
                       std::to_string(bv.byteLength) + " exceeds buffers[" +
                       std::to_string(bv.buffer) + "] (" + std::to_string(data.size()) + " bytes)");
    return {reinterpret_cast<const char*>(data.data()) + bv.byteOffset, bv.byteLength};
  }

  static uint32_t conv_uint(const uint8_t* p, int ct) {
    switch (ct) {
      case TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE:
        return p[0];
      case TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT: {
        uint16_t v;
        std::memcpy(&v, p, 2);
        return v;
      }
      default:
        return load_u32(p);
    }
  }

  static float conv_float(const uint8_t* p, int ct, bool normalized) {
    switch (ct) {
      case TINYGLTF_COMPONENT_TYPE_FLOAT: {
        float v;
        std::memcpy(&v, p, 4);
        return v;
      }
      case TINYGLTF_COMPONENT_TYPE_DOUBLE: {
        double v;
        std::memcpy(&v, p, 8);
        return float(v);
      }
      case TINYGLTF_COMPONENT_TYPE_BYTE: {
        double v = int8_t(p[0]);
        return float(normalized ? std::max(v / 127.0, -1.0) : v);
      }
      case TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE:
        return normalized ? p[0] / 255.0f : p[0];
      case TINYGLTF_COMPONENT_TYPE_SHORT: {
        int16_t s;
        std::memcpy(&s, p, 2);
        return float(normalized ? std::max(s / 32767.0, -1.0) : s);
      }
      case TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT: {
        uint16_t s;
        std::memcpy(&s, p, 2);
        return float(normalized ? s / 65535.0 : s);
      }
      case TINYGLTF_COMPONENT_TYPE_INT: {
        int32_t s;
        std::memcpy(&s, p, 4);
        return float(s);
      }
      default:
        return float(normalized ? load_u32(p) / 4294967295.0 : load_u32(p));
    }
  }

  void emit(const Instance& in, size_t prim) {
    const tinygltf::Mesh& mesh = m_.meshes[in.mesh];
    const tinygltf::Primitive& p = mesh.primitives[prim];
    const std::string where =
        "meshes[" + std::to_string(in.mesh) + "].primitives[" + std::to_string(prim) + "]";
    if (p.mode >= 0 && p.mode <= 3) return;  // points and lines: no surface to trace
    if (!is_surface(p.mode)) fail(where, "unknown mode " + std::to_string(p.mode));
    auto pos_it = p.attributes.find("POSITION");
    if (pos_it == p.attributes.end()) fail(where, "no POSITION attribute");

    std::vector<float> pos = read<float>(pos_it->second, 3, where + ".POSITION", conv_float);
    const size_t nv = pos.size() / 3;
    std::vector<uint32_t> idx;
    if (p.indices >= 0) {
      idx = read<uint32_t>(
          p.indices, 1, where + ".indices",
          [](const uint8_t* q, int ct, bool) { return conv_uint(q, ct); }, true);
      for (size_t i = 0; i < idx.size(); ++i)
        if (idx[i] >= nv)
          fail(where, "index " + std::to_string(idx[i]) + " at position " + std::to_string(i) +
                          " >= vertex count " + std::to_string(nv));
    } else {
      if (p.indices < -1) fail(where, "negative indices accessor");
      idx.resize(nv);
      for (size_t i = 0; i < nv; ++i) idx[i] = uint32_t(i);
    }
    std::vector<float> nrm, uv;
    if (auto it = p.attributes.find("NORMAL"); it != p.attributes.end()) {
      nrm = read<float>(it->second, 3, where + ".NORMAL", conv_float);
      if (nrm.size() != pos.size()) fail(where, "NORMAL count differs from POSITION count");
    }
    if (auto it = p.attributes.find("TEXCOORD_0"); it != p.attributes.end()) {
      uv = read<float>(it->second, 2, where + ".TEXCOORD_0", conv_float);
      if (uv.size() / 2 != nv) fail(where, "TEXCOORD_0 count differs from POSITION count");
    }

    // Triangles (glTF 2.0 spec, 3.7.2.1 "Topology types").
    std::vector<uint32_t> tri;
    const size_t n = idx.size();
    if (p.mode == TINYGLTF_MODE_TRIANGLES) {
      if (n % 3 != 0)
        fail(where, std::to_string(n) + " triangle indices; expected a multiple of 3");
      tri = std::move(idx);
    } else {
      // Strips and fans: joins made of repeated indices are dropped (zero area by construction).
      for (size_t i = 0; i + 2 < n; ++i) {
        uint32_t a, b, c;
        if (p.mode == TINYGLTF_MODE_TRIANGLE_STRIP) {
          a = idx[i];
          b = idx[i + 1 + i % 2];
          c = idx[i + 2 - i % 2];
        } else {
          a = idx[i + 1];
          b = idx[i + 2];
          c = idx[0];
        }
        if (a == b || b == c || a == c) continue;
        tri.insert(tri.end(), {a, b, c});
      }
    }

    const uint64_t base = out_.positions.size();
    if (base + nv > UINT32_MAX) fail(where, "the flattened scene exceeds 2^32-1 vertices");
    const Mat4& w = in.world;
    // A non-finite coordinate, in the accessor or after the node's world transform (a finite
    // vertex times a huge matrix overflows float), would make its faces be dropped later without
    // a word: refused here, naming the node, the vertex and the value.
    for (size_t i = 0; i < nv; ++i) {
      const double x = pos[3 * i], y = pos[3 * i + 1], z = pos[3 * i + 2];
      const double t[3] = {w(0, 0) * x + w(0, 1) * y + w(0, 2) * z + w(0, 3),
                           w(1, 0) * x + w(1, 1) * y + w(1, 2) * z + w(1, 3),
                           w(2, 0) * x + w(2, 1) * y + w(2, 2) * z + w(2, 3)};
      for (int k = 0; k < 6; ++k) {
        // k < 3: the accessor's value; k >= 3: the transformed one.
        const double v = k < 3 ? double(pos[3 * i + k]) : t[k - 3];
        if (rounds_to_finite_float(v)) continue;
        char value[64];
        std::snprintf(value, sizeof value, "%.9g", v);
        fail(where + ".POSITION",
             "vertex " + std::to_string(i) + " coordinate " + "xyz"[k % 3] + " is " + value +
                 (k < 3 ? " in the accessor"
                  : in.node >= 0
                      ? " after the world transform of nodes[" + std::to_string(in.node) + "]"
                      : "") +
                 "; expected a finite number of magnitude at most 3.4e38");
      }
      out_.positions.push_back({float(t[0]), float(t[1]), float(t[2])});
    }
    // Normals go through the cofactor matrix (det * inverse transpose), sign-corrected.
    const double cof[3][3] = {
        {w(1, 1) * w(2, 2) - w(1, 2) * w(2, 1), w(1, 2) * w(2, 0) - w(1, 0) * w(2, 2),
         w(1, 0) * w(2, 1) - w(1, 1) * w(2, 0)},
        {w(0, 2) * w(2, 1) - w(0, 1) * w(2, 2), w(0, 0) * w(2, 2) - w(0, 2) * w(2, 0),
         w(0, 1) * w(2, 0) - w(0, 0) * w(2, 1)},
        {w(0, 1) * w(1, 2) - w(0, 2) * w(1, 1), w(0, 2) * w(1, 0) - w(0, 0) * w(1, 2),
         w(0, 0) * w(1, 1) - w(0, 1) * w(1, 0)}};
    const double det = w(0, 0) * cof[0][0] + w(0, 1) * cof[0][1] + w(0, 2) * cof[0][2];
    if (any_normals_) {
      for (size_t i = 0; i < nv; ++i) {
        if (nrm.empty()) {
          out_.normals.push_back({0, 0, 0});
          continue;
        }
        const double x = nrm[3 * i], y = nrm[3 * i + 1], z = nrm[3 * i + 2];
        double t[3];
        for (int r = 0; r < 3; ++r) t[r] = cof[r][0] * x + cof[r][1] * y + cof[r][2] * z;
        double len = std::sqrt(t[0] * t[0] + t[1] * t[1] + t[2] * t[2]);
        double s = len > 0 ? (det < 0 ? -1.0 : 1.0) / len : 0.0;
        out_.normals.push_back({float(t[0] * s), float(t[1] * s), float(t[2] * s)});
      }
    }
    if (any_uvs_)
      for (size_t i = 0; i < nv; ++i)
        out_.uvs.push_back(uv.empty() ? Vec2f{} : Vec2f{uv[2 * i], uv[2 * i + 1]});

    // A mirroring transform flips the winding; swap two corners to keep the front face.
    const bool flip = det < 0;
    const uint32_t object = uint32_t(out_.object_names.size());
    std::string name = mesh.name.empty() ? "mesh" + std::to_string(in.mesh) : mesh.name;
    if (mesh.primitives.size() > 1) name += "/" + std::to_string(prim);
    out_.object_names.push_back(name);
    for (size_t t = 0; t + 2 < tri.size(); t += 3) {
      out_.face_sizes.push_back(3);
      out_.face_indices.push_back(uint32_t(base + tri[t]));
      out_.face_indices.push_back(uint32_t(base + tri[t + (flip ? 2 : 1)]));
      out_.face_indices.push_back(uint32_t(base + tri[t + (flip ? 1 : 2)]));
      out_.face_object.push_back(object);
    }
  }

  const std::string& src_;
  const tinygltf::Model& m_;
  size_t input_bytes_;
  PolyMesh& out_;
  std::vector<Instance> instances_;
  bool any_normals_ = false, any_uvs_ = false;
  uint64_t vertices_ = 0, indices_ = 0;  // of the flattened scene (upper bounds for strips/fans)
};

}  // namespace

PolyMesh read_gltf(const std::string& src, std::string_view data, bool binary,
                   const std::string& base_dir) {
  tinygltf::Model model;
  tinygltf::TinyGLTF loader;
  loader.SetImageLoader(bad_image_loader, nullptr);
  loader.SetFsCallbacks({&external_file_exists, &tinygltf::ExpandFilePath, &read_external_file,
                         &tinygltf::WriteWholeFile, nullptr});
  std::string err, warn;
  bool ok = false;
  try {
    if (binary) {
      uint32_t length = check_glb(src, data);
      check_json(src, data.substr(20, load_u32(reinterpret_cast<const uint8_t*>(data.data()) + 12)),
                 true, 20);
      ok = loader.LoadBinaryFromMemory(&model, &err, &warn,
                                       reinterpret_cast<const unsigned char*>(data.data()), length,
                                       base_dir);
    } else {
      if (data.size() > UINT32_MAX) throw Error(src + ": glTF JSON larger than 4 GiB");
      check_json(src, data, false, 0);
      ok = loader.LoadASCIIFromString(&model, &err, &warn, data.data(),
                                      static_cast<unsigned int>(data.size()), base_dir);
    }
  } catch (const Error&) {
    throw;
  } catch (const std::bad_alloc&) {
    throw Error(src + ": out of memory while parsing the glTF JSON and buffers (" +
                std::to_string(data.size()) + " bytes of file)");
  } catch (const std::exception& e) {
    throw_tinygltf(src, e.what(), binary);
  }
  if (!ok) throw_tinygltf(src, err, binary);

  // Extensions that change where or how geometry is stored; without them the accessors would
  // read as zeros or garbage, so refuse the file instead.
  for (const std::string& ext : model.extensionsRequired)
    if (ext == "KHR_draco_mesh_compression" || ext == "EXT_meshopt_compression" ||
        ext == "EXT_mesh_gpu_instancing")
      throw Error(src + ": extensionsRequired: " + ext + " is not supported");

  PolyMesh mesh;
  size_t input_bytes = data.size();
  for (const auto& b : model.buffers) input_bytes += b.data.size();
  Flattener(src, model, input_bytes, mesh).run();
  return mesh;
}

}  // namespace slim::detail
