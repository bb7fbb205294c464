// Wavefront OBJ reader on top of tinyobjloader (Debian libtinyobjloader-dev, header only here).
//
// tinyobjloader parses the numbers; this file adds what it leaves out for untrusted input:
// - a pre-scan with the same line splitting as tinyobjloader's safeGetline (\n, \r\n or \r) that
//   counts the corners of every 'f' line: faces with fewer than 3 corners are an error here
//   (tinyobjloader drops them with a warning), and the counts replace tinyobjloader's per-face
//   sizes, which are stored as unsigned char and wrap for polygons of 256+ corners;
// - control bytes (NUL etc.) are rejected, so binary garbage is not read as an empty mesh, and
//   'v' lines must have 3 numeric coordinates (tinyobjloader reads missing or bad ones as 0);
// - every position, normal and uv index is checked (tinyobjloader only warns), and the error
//   names the line of the offending face.
#define TINYOBJLOADER_IMPLEMENTATION
#include <tiny_obj_loader.h>

#include "io/obj.h"

#include <algorithm>
#include <cfloat>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <memory>
#include <streambuf>
#include <unordered_map>

#include "io/byte_window.h"
#include "io/face_stream.h"
#include "io/float_range.h"
#include "io/xz.h"
#include "slimrt/error.h"

namespace slim::detail {
namespace {

// Read-only std::streambuf over a memory buffer, so tinyobjloader parses without a copy.
struct MemoryBuf : std::streambuf {
  MemoryBuf(const char* data, size_t size) {
    char* p = const_cast<char*>(data);  // get area only: never written through
    setg(p, p, p + size);
  }
};

// Calls fn(line_number, text) for every line, split exactly like tinyobjloader's safeGetline so
// that line numbers agree with its messages. fn returns false to stop.
template <class Fn>
void for_each_line(std::string_view d, Fn&& fn) {
  size_t i = 0;
  uint64_t line = 0;
  while (i < d.size()) {
    size_t j = i;
    while (j < d.size() && d[j] != '\n' && d[j] != '\r') ++j;
    if (!fn(++line, d.substr(i, j - i))) return;
    i = (j + 1 < d.size() && d[j] == '\r' && d[j + 1] == '\n') ? j + 2 : j + 1;
  }
}

// True if `s` is statement `kw` ("f", "v"): the keyword after optional blanks, then a blank or
// the end of the line (tinyobjloader's rule, except that a bare keyword counts too, so that "f"
// alone is reported instead of skipped). `rest` gets what follows the keyword.
bool statement(std::string_view s, char kw, std::string_view& rest) {
  size_t i = 0;
  while (i < s.size() && (s[i] == ' ' || s[i] == '\t')) ++i;
  if (i >= s.size() || s[i] != kw) return false;
  ++i;
  if (i < s.size() && s[i] != ' ' && s[i] != '\t') return false;
  rest = s.substr(i);
  return true;
}

// 'vw' statement (tinyobjloader's vertex weights extension): rest = after the keyword.
bool vertex_weight_statement(std::string_view s, std::string_view& rest) {
  size_t i = 0;
  while (i < s.size() && (s[i] == ' ' || s[i] == '\t')) ++i;
  if (s.size() < i + 3 || s[i] != 'v' || s[i + 1] != 'w' || (s[i + 2] != ' ' && s[i + 2] != '\t'))
    return false;
  rest = s.substr(i + 2);
  return true;
}

// Splits at blanks (spaces and tabs), as tinyobjloader does within a line.
template <class Fn>
int64_t for_each_token(std::string_view s, Fn&& fn) {
  int64_t n = 0;
  size_t i = 0;
  while (i < s.size()) {
    while (i < s.size() && (s[i] == ' ' || s[i] == '\t')) ++i;
    if (i == s.size()) break;
    size_t j = i;
    while (j < s.size() && s[j] != ' ' && s[j] != '\t') ++j;
    fn(n++, s.substr(i, j - i));
    i = j;
  }
  return n;
}

// Number of corners if `s` is a face line, else -1.
int64_t face_corners(std::string_view s) {
  std::string_view rest;
  if (!statement(s, 'f', rest)) return -1;
  return for_each_token(rest, [](int64_t, std::string_view) {});
}

std::string excerpt(std::string_view s) {
  constexpr size_t kMax = 60;
  std::string out = "'";
  for (char c : s.substr(0, kMax)) out += (c >= 32 && c < 127) ? c : '?';
  if (s.size() > kMax) out += "...";
  return out + "'";
}

// Line number and text of face number `face` (0-based, in file order).
std::pair<uint64_t, std::string_view> face_line(std::string_view data, uint64_t face) {
  std::pair<uint64_t, std::string_view> found{0, {}};
  uint64_t f = 0;
  for_each_line(data, [&](uint64_t line, std::string_view text) {
    if (face_corners(text) < 0) return true;
    if (f++ != face) return true;
    found = {line, text};
    return false;
  });
  return found;
}

// Last "line N" in a tinyobjloader message, 0 if none.
uint64_t line_in_message(const std::string& msg) {
  size_t p = msg.rfind("line ");
  if (p == std::string::npos) return 0;
  uint64_t n = 0;
  for (size_t i = p + 5; i < msg.size() && msg[i] >= '0' && msg[i] <= '9'; ++i)
    n = n * 10 + uint64_t(msg[i] - '0');
  return n;
}

std::string trim(const std::string& s) {
  size_t b = s.find_first_not_of(" \t");
  if (b == std::string::npos) return {};
  return s.substr(b, s.find_last_not_of(" \t") + 1 - b);
}

// Statement with a two-letter keyword ("vn", "vt"): rest = after the keyword.
bool statement2(std::string_view s, const char* kw, std::string_view& rest) {
  size_t i = 0;
  while (i < s.size() && (s[i] == ' ' || s[i] == '\t')) ++i;
  if (s.size() < i + 3 || s[i] != kw[0] || s[i + 1] != kw[1] ||
      (s[i + 2] != ' ' && s[i + 2] != '\t'))
    return false;
  rest = s.substr(i + 2);
  return true;
}

// Checks the numbers of a v, vn or vt line: tinyobjloader parses them as double and stores float,
// so a value beyond the float range (1e39) would become inf and its faces be dropped later
// without a word. Such a value is refused here, like a literal inf.
void check_floats(const std::string& src, uint64_t line, std::string_view rest, const char* kw) {
  for_each_token(rest, [&](int64_t, std::string_view t) {
    if (std::string_view("+-.0123456789").find(t[0]) == t.npos) return;  // handled elsewhere
    const std::string tok(t.substr(0, 400));
    const double v = std::strtod(tok.c_str(), nullptr);
    if (!rounds_to_finite_float(v))
      throw_at_line(src, line,
                    std::string(kw) + " value " + excerpt(t) +
                        " overflows float; expected a finite number of magnitude at most 3.4e38");
  });
}

// Refuses a number whose exponent lies beyond +-kMaxExponent, in any token of the lines whose
// numbers tinyobjloader parses (v, vt, vn, vw, t). Its parser is not strtod: it multiplies the
// exponent by 10 per digit in an int with a check that still lets 2147483640 + 9 overflow, and it
// computes mantissa * 5^e, which is 0 * inf = NaN for "0e3805" (a zero to strtod); a NaN joint id
// of a 'vw' line is then converted to int (both undefined behaviour, found by fuzz/fuzz_obj.cpp).
// Up to 400 every such product is finite, and float's range ends near 1e38 and 1e-45 anyway.
constexpr int kMaxExponent = 400;
// The exponent tinyobjloader's parser would read from token t (its grammar: [sign] digits
// [. digits] [e [sign] digits], or [sign] . digits ...), saturated at kMaxExponent + 1; 0 where
// the token does not start like a number or has no exponent, so that names ("t file1000 ...")
// are not numbers here either.
int tinyobj_exponent(std::string_view t) {
  auto digit = [&](size_t i) { return i < t.size() && t[i] >= '0' && t[i] <= '9'; };
  size_t i = (!t.empty() && (t[0] == '+' || t[0] == '-')) ? 1 : 0;
  if (!digit(i) && !(i < t.size() && t[i] == '.')) return 0;
  while (digit(i)) ++i;
  if (i < t.size() && t[i] == '.')
    for (++i; digit(i);) ++i;
  if (i >= t.size() || (t[i] != 'e' && t[i] != 'E')) return 0;
  ++i;
  if (i < t.size() && (t[i] == '+' || t[i] == '-')) ++i;
  int exponent = 0;
  for (; digit(i); ++i) exponent = std::min(exponent * 10 + (t[i] - '0'), kMaxExponent + 1);
  return exponent;
}
void check_exponents(const std::string& src, uint64_t line, std::string_view rest) {
  for_each_token(rest, [&](int64_t, std::string_view t) {
    if (tinyobj_exponent(t) > kMaxExponent)
      throw_at_line(src, line,
                    "number " + excerpt(t) + " has an exponent beyond " +
                        std::to_string(kMaxExponent) + "; expected one from -" +
                        std::to_string(kMaxExponent) + " to " + std::to_string(kMaxExponent));
  });
}

// Checks one face corner "v", "v/t", "v//n" or "v/t/n" of face line `text` against the counts of
// v, vt and vn lines read so far (OBJ indices: 1..N, or -N..-1 counting back from the last one).
// tinyobjloader reads them into int, so 4294967297 would wrap around to 1.
void check_corner(const std::string& src, uint64_t line, std::string_view text,
                  std::string_view corner, const uint64_t defined[3]) {
  static const char* const kWhat[3] = {"vertex", "texture", "normal"};
  static const char* const kKeyword[3] = {"v", "vt", "vn"};
  static const char* const kForms =
      "; expected vertex references v, v/t, v//n or v/t/n with nonzero integers";
  std::string_view part[3];
  int parts = 0;
  size_t b = 0;
  for (size_t i = 0; i <= corner.size(); ++i)
    if (i == corner.size() || corner[i] == '/') {
      if (parts == 3)
        throw_at_line(src, line,
                      "corner " + excerpt(corner) + " has more than 3 parts in face " +
                          excerpt(text) + kForms);
      part[parts++] = corner.substr(b, i - b);
      b = i + 1;
    }
  for (int k = 0; k < parts; ++k) {
    std::string_view d = part[k];
    if (d.empty()) {
      if (k == 1 && parts == 3) continue;  // v//n
      throw_at_line(
          src, line,
          "corner " + excerpt(corner) + " has an empty index in face " + excerpt(text) + kForms);
    }
    if (d[0] == '-' || d[0] == '+') d.remove_prefix(1);
    uint64_t value = 0;
    bool digits = !d.empty(), big = false;
    for (char c : d) {
      if (c < '0' || c > '9') {
        digits = false;
        break;
      }
      if (value > (uint64_t(1) << 40))
        big = true;
      else
        value = value * 10 + uint64_t(c - '0');
    }
    if (!digits)
      throw_at_line(src, line,
                    std::string(kWhat[k]) + " index " + excerpt(part[k]) +
                        " is not an integer in face " + excerpt(text) + kForms);
    if (big || value == 0 || value > defined[k])
      throw_at_line(src, line,
                    std::string(kWhat[k]) + " index out of range: " + excerpt(part[k]) +
                        " in face " + excerpt(text) + "; expected a nonzero index from 1 to " +
                        std::to_string(defined[k]) + " or from -" + std::to_string(defined[k]) +
                        " to -1 (" + std::to_string(defined[k]) + " '" + kKeyword[k] +
                        "' lines before this face)");
  }
}

// The checks of one line, shared by read_obj and the face stream: control bytes, 'v' lines with 3
// numeric coordinates, float overflow, exponents tinyobjloader cannot take, and every face corner
// against the v/vt/vn lines before it (`defined`, updated here). Returns the number of corners of
// a face line (>= 3), -1 for any other line.
int64_t prescan_line(const std::string& src, uint64_t line, std::string_view text,
                     uint64_t defined[3]) {
  for (char c : text) {
    unsigned char u = static_cast<unsigned char>(c);
    if (u < 32 && c != '\t' && c != '\v' && c != '\f' && u != 0x1a)
      throw_at_line(src, line,
                    "control byte " + std::to_string(u) + " in an OBJ file; expected text");
  }
  std::string_view rest;
  if (statement(text, 'v', rest)) {
    // tinyobjloader reads a missing or non-numeric coordinate as 0: refuse it here.
    int64_t bad = -1;
    int64_t coords = for_each_token(rest, [&](int64_t k, std::string_view t) {
      if (k < 3 && bad < 0 && std::string_view("+-.0123456789").find(t[0]) == t.npos) bad = k;
    });
    if (coords < 3)
      throw_at_line(src, line,
                    "vertex has " + std::to_string(coords) + " coordinates; expected x y z");
    if (bad >= 0) throw_at_line(src, line, "vertex coordinate is not a number; expected x y z");
    check_exponents(src, line, rest);
    check_floats(src, line, rest, "vertex coordinate");
    ++defined[0];
    return -1;
  }
  if (statement2(text, "vt", rest)) {
    check_exponents(src, line, rest);
    check_floats(src, line, rest, "texture coordinate");
    ++defined[1];
    return -1;
  }
  if (statement2(text, "vn", rest)) {
    check_exponents(src, line, rest);
    check_floats(src, line, rest, "normal coordinate");
    ++defined[2];
    return -1;
  }
  if (vertex_weight_statement(text, rest)) {
    // tinyobjloader converts the joint ids of 'vw' lines from float to int unchecked (undefined
    // behaviour for huge values, found by fuzz/fuzz_obj.cpp); slimrt ignores vertex weights, so
    // numbers beyond 1e9 are refused here. The margin below 2^31 covers tinyobjloader's own
    // rounding: it parses to double, then rounds to float (2147483600 becomes 2^31).
    check_exponents(src, line, rest);
    for_each_token(rest, [&](int64_t, std::string_view t) {
      const std::string tok(t.substr(0, 64));
      const double v = std::strtod(tok.c_str(), nullptr);
      if (t.size() > 32 || !(std::fabs(v) <= 1e9))
        throw_at_line(src, line, "vertex weight line has a number out of range: " + excerpt(t));
    });
    return -1;
  }
  if (statement(text, 't', rest)) {  // tinyobjloader's tags: "t name ints/reals/strings ..."
    check_exponents(src, line, rest);
    return -1;
  }
  int64_t n = face_corners(text);
  if (n < 0) return -1;
  statement(text, 'f', rest);
  for_each_token(rest,
                 [&](int64_t, std::string_view t) { check_corner(src, line, text, t, defined); });
  if (n < 3)
    throw_at_line(src, line, "face has " + std::to_string(n) + " vertices; expected at least 3");
  if (n > int64_t(UINT32_MAX)) throw_at_line(src, line, "face has too many vertices");
  return n;
}

}  // namespace

PolyMesh read_obj(const std::string& src, std::string_view data) {
  PolyMesh mesh;

  // Pre-scan: corners per face, control bytes, float overflow, index ranges.
  uint64_t defined[3] = {0, 0, 0};  // v, vt, vn lines so far
  for_each_line(data, [&](uint64_t line, std::string_view text) {
    const int64_t n = prescan_line(src, line, text, defined);
    if (n >= 0) mesh.face_sizes.push_back(uint32_t(n));
    return true;
  });

  tinyobj::attrib_t attrib;
  std::vector<tinyobj::shape_t> shapes;
  std::vector<tinyobj::material_t> materials;
  std::string warn, err;
  MemoryBuf buf(data.data(), data.size());
  std::istream in(&buf);
  if (!tinyobj::LoadObj(&attrib, &shapes, &materials, &warn, &err, &in, nullptr,
                        /*triangulate=*/false, /*default_vcols_fallback=*/false)) {
    uint64_t line = line_in_message(err);
    std::string what = "cannot parse OBJ (tinyobjloader: " + trim(err.substr(0, err.find('\n'))) +
                       "); expected vertex references v, v/t, v//n or v/t/n with nonzero integers";
    if (line > 0) throw_at_line(src, line, what);
    throw Error(src + ": " + what);
  }

  const size_t nv = attrib.vertices.size() / 3;
  const size_t nn = attrib.normals.size() / 3;
  const size_t nt = attrib.texcoords.size() / 2;
  if (nv > UINT32_MAX) throw Error(src + ": more than 2^32-1 vertices are not supported");
  mesh.positions.resize(nv);
  for (size_t i = 0; i < nv; ++i)
    mesh.positions[i] = {attrib.vertices[3 * i], attrib.vertices[3 * i + 1],
                         attrib.vertices[3 * i + 2]};

  auto fail_face = [&](uint64_t face, const std::string& what) {
    auto [line, text] = face_line(data, face);
    if (line == 0) throw Error(src + ": face " + std::to_string(face) + ": " + what);
    throw_at_line(src, line, what + " in face " + excerpt(text));
  };

  // Flatten tinyobjloader's shapes (file order) and check every index.
  const uint64_t face_count = mesh.face_sizes.size();
  mesh.face_indices.reserve(size_t(mesh.fan_triangle_count() + 2 * face_count));
  std::vector<tinyobj::index_t> corners;
  corners.reserve(mesh.face_indices.capacity());
  std::vector<uint32_t> shape_object;
  std::unordered_map<std::string, uint32_t> object_id;
  uint64_t f = 0;
  for (const tinyobj::shape_t& shape : shapes) {
    if (shape.mesh.num_face_vertices.empty()) continue;  // lines or points only
    std::string name = trim(shape.name);
    if (name.empty()) name = "default";
    auto [it, added] = object_id.try_emplace(name, uint32_t(mesh.object_names.size()));
    if (added) mesh.object_names.push_back(name);
    size_t k = 0;
    const auto& idx = shape.mesh.indices;
    for (unsigned char tiny_size : shape.mesh.num_face_vertices) {
      if (f >= face_count || (mesh.face_sizes[f] & 0xff) != tiny_size ||
          mesh.face_sizes[f] > idx.size() - k)
        fail_face(f, "internal: tinyobjloader disagrees with the face pre-scan");
      for (uint32_t c = 0; c < mesh.face_sizes[f]; ++c) corners.push_back(idx[k++]);
      shape_object.push_back(it->second);
      ++f;
    }
  }
  if (f != face_count)
    fail_face(f, "internal: tinyobjloader returned " + std::to_string(f) + " faces, expected " +
                     std::to_string(face_count));

  bool any_normal = false, any_uv = false;
  {
    uint64_t face = 0, end = face_count ? mesh.face_sizes[0] : 0;
    const std::string range = " (" + std::to_string(nv) + " defined)";
    for (size_t c = 0; c < corners.size(); ++c) {
      while (c >= end) end += mesh.face_sizes[++face];
      const tinyobj::index_t& x = corners[c];
      if (x.vertex_index < 0 || size_t(x.vertex_index) >= nv)
        fail_face(face, "vertex index out of range" + range +
                            "; expected 1..N or -N..-1 relative to the vertices read so far");
      if (x.normal_index < -1 || (x.normal_index >= 0 && size_t(x.normal_index) >= nn))
        fail_face(face, "normal index out of range (" + std::to_string(nn) + " vn defined)");
      if (x.texcoord_index < -1 || (x.texcoord_index >= 0 && size_t(x.texcoord_index) >= nt))
        fail_face(face, "texture index out of range (" + std::to_string(nt) + " vt defined)");
      mesh.face_indices.push_back(uint32_t(x.vertex_index));
      any_normal |= x.normal_index >= 0;
      any_uv |= x.texcoord_index >= 0;
    }
  }

  if (any_normal) {
    mesh.normals.resize(nn);
    for (size_t i = 0; i < nn; ++i)
      mesh.normals[i] = {attrib.normals[3 * i], attrib.normals[3 * i + 1],
                         attrib.normals[3 * i + 2]};
    mesh.normal_indices.reserve(corners.size());
    for (const tinyobj::index_t& x : corners) {
      if (x.normal_index < 0 && mesh.normals.size() == nn) mesh.normals.push_back({0, 0, 0});
      mesh.normal_indices.push_back(x.normal_index >= 0 ? uint32_t(x.normal_index) : uint32_t(nn));
    }
  }
  if (any_uv) {
    mesh.uvs.resize(nt);
    for (size_t i = 0; i < nt; ++i)
      mesh.uvs[i] = {attrib.texcoords[2 * i], attrib.texcoords[2 * i + 1]};
    mesh.uv_indices.reserve(corners.size());
    for (const tinyobj::index_t& x : corners) {
      if (x.texcoord_index < 0 && mesh.uvs.size() == nt) mesh.uvs.push_back({0, 0});
      mesh.uv_indices.push_back(x.texcoord_index >= 0 ? uint32_t(x.texcoord_index) : uint32_t(nt));
    }
  }

  if (mesh.object_names.size() > 1) mesh.face_object = std::move(shape_object);
  if (face_count == 0) mesh.object_names.clear();
  return mesh;
}

namespace {

// Reads an OBJ file line by line through a window, in one pass: OBJ faces can only use vertices
// defined before them (prescan_line checks that), so the positions read so far (12 bytes per
// vertex) are all a face needs. Lines are split and checked exactly as read_obj does, and the
// coordinates are parsed by tinyobjloader's own parseReal, so every position has the same bits.
class ObjFaceStream final : public FaceStream {
 public:
  ObjFaceStream(const std::string& path, size_t max_corners, size_t window_bytes)
      : FaceStream(path), max_corners_(std::max<size_t>(max_corners, 1)) {
    if (has_xz_suffix(path)) {
      bytes_ = read_file(path);
      window_ = std::make_unique<ByteWindow>(bytes_.view(), 0);
    } else {
      window_ = std::make_unique<ByteWindow>(path, 0, window_bytes, true);
    }
  }

  bool next(FaceBatch& out) override {
    out.clear();
    std::string_view text, rest;
    while (out.corners.size() < max_corners_ && next_line(text)) {
      ++line_;
      const uint64_t vertices_before = defined_[0];
      const int64_t n = prescan_line(name_, line_, text, defined_);
      if (n < 0) {
        if (defined_[0] != vertices_before) positions_.push_back(parse_vertex(text));
        continue;
      }
      out.sizes.push_back(uint32_t(n));
      out.face_ids.push_back(faces_++);
      statement(text, 'f', rest);
      for_each_token(rest, [&](int64_t, std::string_view corner) {
        // "v", "v/t", "v//n" or "v/t/n", already checked by prescan_line (1..N or -N..-1).
        std::string_view d = corner.substr(0, corner.find('/'));
        const bool negative = d[0] == '-';
        if (d[0] == '-' || d[0] == '+') d.remove_prefix(1);
        uint64_t value = 0;
        for (char c : d) value = value * 10 + uint64_t(c - '0');
        const uint64_t idx = negative ? positions_.size() - value : value - 1;
        out.corners.push_back(positions_[idx]);
      });
    }
    return out.face_count() > 0;
  }

  void rewind() override {
    window_->seek(0);
    line_ = faces_ = 0;
    defined_[0] = defined_[1] = defined_[2] = 0;
    positions_.clear();
    pending_cr_ = false;
  }

  uint64_t resident_bytes() const override {
    return positions_.capacity() * sizeof(Vec3f) + window_->buffer_bytes() + bytes_.size() +
           linebuf_.capacity();
  }

 private:
  // The next line, split as for_each_line does (\n, \r\n or \r); valid until the next call.
  bool next_line(std::string_view& text) {
    ByteWindow& w = *window_;
    for (;;) {
      if (w.cur == w.end && !w.more()) return false;
      if (pending_cr_) {  // a \r ended the last window: a \n right after it belongs to it
        pending_cr_ = false;
        if (*w.cur == '\n') {
          ++w.cur;
          continue;
        }
      }
      break;
    }
    const char* b = w.cur;
    const char* j = b;
    while (j < w.end && *j != '\n' && *j != '\r') ++j;
    text = std::string_view(b, size_t(j - b));
    if (j == w.end) {
      w.cur = j;
    } else if (*j == '\r' && j + 1 == w.end) {
      w.cur = j + 1;
      pending_cr_ = true;
    } else {
      w.cur = (*j == '\r' && j[1] == '\n') ? j + 2 : j + 1;
    }
    return true;
  }

  // x, y, z of a 'v' line, parsed by tinyobjloader's parseReal as LoadObj does.
  Vec3f parse_vertex(std::string_view text) {
    linebuf_.assign(text);
    const char* token = linebuf_.c_str();
    token += strspn(token, " \t");
    token += 2;  // "v" and the blank (checked by prescan_line)
    const float x = tinyobj::parseReal(&token, 0.0);
    const float y = tinyobj::parseReal(&token, 0.0);
    const float z = tinyobj::parseReal(&token, 0.0);
    return {x, y, z};
  }

  size_t max_corners_;
  FileBytes bytes_;
  std::unique_ptr<ByteWindow> window_;
  std::vector<Vec3f> positions_;
  std::string linebuf_;
  uint64_t defined_[3] = {0, 0, 0};
  uint64_t line_ = 0, faces_ = 0;
  bool pending_cr_ = false;
};

}  // namespace

std::unique_ptr<FaceStream> open_obj_stream(const std::string& path, size_t max_corners,
                                            size_t window_bytes) {
  return std::make_unique<ObjFaceStream>(path, max_corners, window_bytes);
}

}  // namespace slim::detail
