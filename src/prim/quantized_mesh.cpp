// The Costa quantized n-gon mesh store (Costa et al., WSCG 2013, section 3.2): primitive
// array packing (Listing 2), face packing (Listing 3), vertex quantization (Listing 4).
#include "prim/quantized_mesh.h"

#include "slimrt/error.h"

#include <algorithm>
#include <cmath>

#include "core/assert.h"

namespace slim {

// ---- BitArray ----------------------------------------------------------------------------------

BitArray::BitArray(uint64_t count, uint32_t width) : count_(count), width_(width) {
  if (width > 32) throw Error("BitArray: width " + std::to_string(width) + " > 32");
  const uint64_t bits = count * width;
  words_.assign((bits + 63) / 64 + 1, 0);  // + 1 word: bit_read loads 8 bytes at any field
}

void BitArray::set(uint64_t i, uint32_t value) {
  SLIM_ASSERT(i < count_);
  SLIM_ASSERT(width_ == 32 || value < (uint64_t(1) << width_));
  if (width_ == 0) return;
  const uint64_t bit = i * width_;
  uint8_t* p = reinterpret_cast<uint8_t*>(words_.data()) + (bit >> 3);
  const uint32_t shift = uint32_t(bit & 7);
  const uint64_t mask = ((uint64_t(1) << width_) - 1) << shift;
  uint64_t w;
  std::memcpy(&w, p, 8);
  w = (w & ~mask) | ((uint64_t(value) << shift) & mask);
  std::memcpy(p, &w, 8);
}

// ---- VertexQuantizer (Listing 4) ---------------------------------------------------------------

VertexQuantizer::VertexQuantizer(const Box3f& box) {
  for (int a = 0; a < 3; ++a) {
    float lo_a = box.empty() ? 0.0f : box.lo[a];
    float hi_a = box.empty() ? 0.0f : box.hi[a];
    lo[a] = lo_a;
    // The paper scales by 65535 / (max - min); we store the inverse, the decoding step.
    step[a] = hi_a > lo_a ? float((double(hi_a) - double(lo_a)) / 65535.0) : 0.0f;
  }
}

uint16_t VertexQuantizer::encode(float x, int a) const {
  if (!std::isfinite(x) || !(step[a] > 0.0f)) return 0;
  // The paper truncates ((v - min) * scale); rounding halves the error. Among the codes around
  // the rounded one, keep the one whose decoded float (as the decoder computes it) is nearest.
  double q0 = std::nearbyint((double(x) - double(lo[a])) / double(step[a]));
  int best = int(std::clamp(q0, 0.0, 65535.0));
  double best_err = std::fabs(double(decode(uint32_t(best), a)) - double(x));
  for (int q = std::max(0, best - 1); q <= std::min(65535, best + 1); ++q) {
    double err = std::fabs(double(decode(uint32_t(q), a)) - double(x));
    if (err < best_err) best = q, best_err = err;
  }
  return uint16_t(best);
}

VertexQuantizer make_vertex_quantizer(const std::vector<Vec3f>& vertices,
                                      const Box3f& lattice_box) {
  if (!lattice_box.empty()) return VertexQuantizer(lattice_box);
  Box3f box;
  for (const Vec3f& p : vertices)
    if (is_finite(p)) box.extend(p);
  return VertexQuantizer(box);
}

// ---- flags
// ---------------------------------------------------------------------------------------

CostaFlags CostaFlags::parse(const std::string& letters) {
  CostaFlags f;
  const char* order = "TPFV";
  size_t k = 0;
  for (char c : letters) {
    while (order[k] && order[k] != c) ++k;
    if (!order[k])
      throw Error("costa options '" + letters +
                  "': expected any of the letters T, P, F, V in that order");
    bool& b = c == 'T' ? f.T : c == 'P' ? f.P : c == 'F' ? f.F : f.V;
    b = true;
    ++k;
  }
  return f;
}

std::string CostaFlags::letters() const {
  std::string s;
  if (T) s += 'T';
  if (P) s += 'P';
  if (F) s += 'F';
  if (V) s += 'V';
  return s;
}

// ---- the store
// -------------------------------------------------------------------------------------

QuantizedMesh::QuantizedMesh(const NgonArrays& m, bool P, bool F, bool V, const Box3f& lattice_box)
    : P_(P), F_(F), V_(V) {
  const uint64_t n = m.prim_count();
  if (n >= 0xffffffffull) throw Error("costa: too many primitives");
  prim_count_ = uint32_t(n);
  face_count_ = m.faces.size();
  vertex_count_ = uint32_t(m.vertices.size());

  // Primitive array.
  if (!P) {
    offsets_ = n ? m.prim_offsets : std::vector<uint32_t>{0};
  } else {
    // PACKPRIMITIVES (Listing 2): predict offset i as avg * i, store actual - predicted - Min in
    // log2(Max - Min) bits. Min and Max start at 0, as in the listing.
    const uint32_t total = n ? m.prim_offsets[n] : 0;
    avg_ = n ? double(total) / double(n) : 0.0;
    int64_t lo = 0, hi = 0;
    for (uint64_t i = 0; i <= n; ++i) {
      int64_t actual = n ? int64_t(m.prim_offsets[i]) : 0;
      int64_t diff = actual - predict_offset(avg_, uint32_t(i));
      lo = std::min(lo, diff);
      hi = std::max(hi, diff);
    }
    residual_min_ = lo;
    // Offsets and predictions lie in [0, 2^31) (load_ngon_mesh), so the range fits 32 bits.
    residuals_ = BitArray(n + 1, bits_for(uint64_t(hi - lo)));
    for (uint64_t i = 0; i <= n; ++i) {
      int64_t actual = n ? int64_t(m.prim_offsets[i]) : 0;
      residuals_.set(i, uint32_t(actual - predict_offset(avg_, uint32_t(i)) - lo));
    }
  }

  // Face array.
  if (!F) {
    faces_ = m.faces;
  } else {
    // PACKFACES (Listing 3) packs at log2(2 * vertices) bits, room for the flag bit. We pack at
    // the width of the largest entry actually stored: the same whenever a high-index fan or strip
    // carries a flag, one bit less when no entry needs it (triangle and quad meshes, whose kinds
    // follow from the vertex count alone). At least 1 bit: entries of 0 bits would cost no bytes,
    // and a scene file's face range could then exceed any bound its size sets (CostaLeaf::
    // check_params refuses 0 bits but in an empty store).
    uint32_t mx = 0;
    for (uint32_t e : m.faces) mx = std::max(mx, e);
    packed_faces_ = BitArray(m.faces.size(), std::max(1u, bits_for(mx)));
    for (uint64_t j = 0; j < m.faces.size(); ++j) packed_faces_.set(j, m.faces[j]);
  }

  // Vertex array.
  if (!V) {
    vertices_ = m.vertices;
  } else {
    // PACKVERTICES (Listing 4): scene box coordinates, 16 bits per component.
    quant_ = make_vertex_quantizer(m.vertices, lattice_box);
    qvertices_.resize(3 * m.vertices.size());
    for (size_t k = 0; k < m.vertices.size(); ++k)
      for (int a = 0; a < 3; ++a) qvertices_[3 * k + a] = quant_.encode(m.vertices[k][a], a);
  }
}

uint64_t QuantizedMesh::prim_bytes() const {
  // P: the packed residuals + avg (8 B) + Min (8 B) + width (4 B).
  return P_ ? residuals_.bytes() + 20 : offsets_.size() * sizeof(uint32_t);
}
uint64_t QuantizedMesh::face_bytes() const {
  return F_ ? packed_faces_.bytes() + 4 : faces_.size() * sizeof(uint32_t);
}
uint64_t QuantizedMesh::vertex_bytes() const {
  return V_ ? qvertices_.size() * sizeof(uint16_t) + sizeof(VertexQuantizer)
            : vertices_.size() * sizeof(Vec3f);
}

uint32_t QuantizedMesh::offset(uint32_t i) const {
  if (P_) return uint32_t(predict_offset(avg_, i) + residual_min_ + int64_t(residuals_.get(i)));
  return offsets_[i];
}
uint32_t QuantizedMesh::face(uint64_t j) const { return F_ ? packed_faces_.get(j) : faces_[j]; }
Vec3f QuantizedMesh::vertex(uint32_t k) const {
  return V_ ? quant_.decode(&qvertices_[3 * uint64_t(k)]) : vertices_[k];
}

QuantizedMesh::Raw QuantizedMesh::raw() const {
  Raw r{};
  r.offsets = offsets_.data();
  r.residuals = residuals_.data();
  r.residual_bits = residuals_.width();
  r.avg = avg_;
  r.residual_min = residual_min_;
  r.faces = faces_.data();
  r.packed_faces = packed_faces_.data();
  r.face_bits = packed_faces_.width();
  r.vertices = vertices_.data();
  r.qvertices = qvertices_.data();
  r.quant = quant_;
  return r;
}

bool QuantizedMesh::validate(std::string* why) const {
  auto fail = [&](const std::string& s) {
    if (why) *why = "costa store: " + s;
    return false;
  };
  if (offset(0) != 0) return fail("primitive 0 does not start at face entry 0");
  uint32_t prev = 0;
  for (uint32_t i = 0; i < prim_count_; ++i) {
    uint32_t next = offset(i + 1);
    if (next < prev + 3 || next > face_count_)
      return fail("primitive " + std::to_string(i) + " has a bad face range [" +
                  std::to_string(prev) + ", " + std::to_string(next) + ")");
    for (uint32_t j = prev; j < next; ++j) {
      uint32_t v = face(j);
      if (j == prev && next - prev >= kFanStripFlagMin) v >>= 1;
      if (v >= vertex_count_)
        return fail("face entry " + std::to_string(j) + " indexes vertex " + std::to_string(v) +
                    " of " + std::to_string(vertex_count_));
    }
    prev = next;
  }
  if (prev != face_count_) return fail("the primitive array does not end at the face count");
  return true;
}

}  // namespace slim
