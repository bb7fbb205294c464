// The Costa quantized n-gon mesh store: V. Costa, J. M. Pereira, J. A. Jorge, "Fast Compression
// of Meshes for GPU Ray-Tracing", WSCG 2013, section 3.2 "Geometry Compression".
//
// Three arrays, each stored plain or compressed (the paper's letters):
//   primitive array  plain: n+1 prefix-summed uint32 offsets (Figure 6, Listing 1)
//                    P:     offset(i) = floor(avg * i) + Min + residual(i), residuals bit-packed
//                           at the minimum width (Listing 2, PACKPRIMITIVES)
//   face array       plain: uint32 vertex indices (first entry of a 5+ vertex primitive carries the
//                           fan/strip flag in bit 0)
//                    F:     the same entries bit-packed, leading zeros dropped (Listing 3)
//   vertex array     plain: float3
//                    V:     uint16 x 3 in the scene box (Listing 4; lossy)
// T (triangulate first) acts on the input (mesh/tessellate.h), before the store.
// Every combination gives O(1) access to primitive i: two offset reads, then its face entries.
#pragma once

#include <bit>
#include <cstdint>
#include <cstring>
#include <string>
#include <vector>

#include "slimrt/math.h"

namespace slim {

static_assert(std::endian::native == std::endian::little,
              "BitArray reads fields with unaligned little-endian 64-bit loads");

// ---- bit-packed arrays ------------------------------------------------------------------------

// Reads element i of a packed array of `width`-bit fields (0 <= width <= 32). One unaligned 8-byte
// load: the field starts at bit (i * width) & 7 <= 7 of it and ends by bit 7 + 32 < 64. The array
// must have 8 bytes of padding after its last field (BitArray has). Width 0 reads 0.
SLIM_INLINE uint32_t bit_read(const uint8_t* data, uint32_t width, uint64_t i) {
  const uint64_t bit = i * width;
  uint64_t w;
  std::memcpy(&w, data + (bit >> 3), 8);
  return uint32_t((w >> (bit & 7)) & ((uint64_t(1) << width) - 1));
}

// Fixed-width packed unsigned integers (the paper's callocBits / pack).
class BitArray {
 public:
  BitArray() = default;
  // `count` zero fields of `width` bits (0..32; throws slim::Error otherwise).
  BitArray(uint64_t count, uint32_t width);

  // Sets field i to `value`, which must fit in width bits (SLIM_ASSERT).
  void set(uint64_t i, uint32_t value);
  uint32_t get(uint64_t i) const { return bit_read(data(), width_, i); }

  uint64_t size() const { return count_; }
  uint32_t width() const { return width_; }
  const uint8_t* data() const { return reinterpret_cast<const uint8_t*>(words_.data()); }
  // Bytes held: ceil(count * width / 64) words plus one word of read padding.
  uint64_t bytes() const { return words_.size() * sizeof(uint64_t); }

 private:
  std::vector<uint64_t> words_ = std::vector<uint64_t>(1, 0);
  uint64_t count_ = 0;
  uint32_t width_ = 0;
};

// Bits needed to hold v (0 for v = 0): the paper's "log2" of Listings 2 and 3, rounded up.
SLIM_INLINE uint32_t bits_for(uint64_t v) { return uint32_t(std::bit_width(v)); }

// ---- vertex quantization (Listing 4) ------------------------------------------------------------

// 16 bits per component in the scene box: p = lo + q * step, step = (hi - lo) / 65535 per axis.
struct VertexQuantizer {
  Vec3f lo, step;  // 24 B kept by the store

  explicit VertexQuantizer(const Box3f& scene_box);
  VertexQuantizer() = default;
  SLIM_INLINE float decode(uint32_t q, int a) const { return lo[a] + float(q) * step[a]; }
  SLIM_INLINE Vec3f decode(const uint16_t* q) const {
    return {decode(q[0], 0), decode(q[1], 1), decode(q[2], 2)};
  }
  // The code whose decoded value is nearest to x (ties to the lower code); 0 for non-finite x.
  uint16_t encode(float x, int a) const;
};

// The quantizer of a vertex array: the box of its finite vertices (the paper's scene box), or
// `lattice_box` when it is not empty (BuildOptions::lattice_box, which must contain the vertices:
// meshes quantized with the same box decode a vertex they share to the same bits).
VertexQuantizer make_vertex_quantizer(const std::vector<Vec3f>& vertices,
                                      const Box3f& lattice_box = Box3f());

// ---- the store ---------------------------------------------------------------------------------

struct CostaFlags {
  bool T = false, P = false, F = false, V = false;
  // Parses any of "T", "P", "F", "V" in that order ("" = none); throws slim::Error otherwise.
  static CostaFlags parse(const std::string& letters);
  std::string letters() const;
};

// Primitive kinds follow from the vertex count alone (paper Listing 5): 3 = triangle, 4 = quad
// (a 4-vertex fan), 5+ = fan or strip, told apart by the flag bit in the first face entry.
constexpr uint32_t kFanStripFlagMin = 5;

// The regular data structure the store encodes (paper Figures 2 and 6): primitive i has vertices
// faces[prim_offsets[i] .. prim_offsets[i+1]); for a primitive of kFanStripFlagMin+ vertices the
// first face entry is (vertex << 1) | flag (0 = fan, 1 = strip). mesh/tessellate.h's NgonMesh
// converts to it.
struct NgonArrays {
  const std::vector<Vec3f>& vertices;
  const std::vector<uint32_t>& prim_offsets;
  const std::vector<uint32_t>& faces;
  size_t prim_count() const { return prim_offsets.empty() ? 0 : prim_offsets.size() - 1; }
};

// The store of one NgonMesh under P, F, V (T is applied before, to the NgonMesh).
class QuantizedMesh {
 public:
  QuantizedMesh() = default;
  // Encodes the primitives, faces and vertices of `mesh` (the side tables prim_face, face_base
  // are not part of the store). V quantizes with make_vertex_quantizer(vertices, lattice_box).
  QuantizedMesh(const NgonArrays& mesh, bool P, bool F, bool V, const Box3f& lattice_box = Box3f());

  uint32_t prim_count() const { return prim_count_; }
  uint64_t face_count() const { return face_count_; }
  uint32_t vertex_count() const { return vertex_count_; }
  bool packed_prims() const { return P_; }
  bool packed_faces() const { return F_; }
  bool quantized_vertices() const { return V_; }

  // Bytes held, per array and in total (each including the parameters it needs to decode).
  uint64_t prim_bytes() const;
  uint64_t face_bytes() const;
  uint64_t vertex_bytes() const;
  uint64_t bytes() const { return prim_bytes() + face_bytes() + vertex_bytes(); }
  uint32_t prim_residual_bits() const { return residuals_.width(); }
  uint32_t face_bits() const { return packed_faces_.width(); }

  // Generic (not hot-path) accessors: offset(i) for i in 0..prim_count(), face entry j, vertex k.
  uint32_t offset(uint32_t i) const;
  uint32_t face(uint64_t j) const;
  Vec3f vertex(uint32_t k) const;
  const VertexQuantizer& quantizer() const { return quant_; }

  // Checks the decoded primitive array (monotonic, 3+ vertices each, ends at face_count()) and
  // the face entries (indices below vertex_count()). Returns false and sets `why` on failure.
  bool validate(std::string* why) const;

  // Raw access for CostaView.
  struct Raw {
    const uint32_t* offsets;
    const uint8_t* residuals;
    uint32_t residual_bits;
    double avg;
    int64_t residual_min;
    const uint32_t* faces;
    const uint8_t* packed_faces;
    uint32_t face_bits;
    const Vec3f* vertices;
    const uint16_t* qvertices;
    VertexQuantizer quant;
  };
  Raw raw() const;
  // Element counts of the arrays raw() points to (scene files save them as sections).
  struct Counts {
    uint64_t offsets, residual_bytes, faces, packed_face_bytes, vertices, qvertices;
  };
  Counts counts() const {
    return {offsets_.size(),       residuals_.bytes(), faces_.size(),
            packed_faces_.bytes(), vertices_.size(),   qvertices_.size()};
  }

 private:
  bool P_ = false, F_ = false, V_ = false;
  uint32_t prim_count_ = 0, vertex_count_ = 0;
  uint64_t face_count_ = 0;
  // Primitive array: plain offsets, or (P) linear prediction avg * i plus packed residuals.
  std::vector<uint32_t> offsets_;
  BitArray residuals_;
  double avg_ = 0;  // face entries per primitive (Listing 2 keeps it as a float; see .cpp)
  int64_t residual_min_ = 0;
  // Face array.
  std::vector<uint32_t> faces_;
  BitArray packed_faces_;
  // Vertex array.
  std::vector<Vec3f> vertices_;
  std::vector<uint16_t> qvertices_;  // 3 per vertex
  VertexQuantizer quant_;
};

// The linear predictor of the primitive array (Listing 2), shared by encoder and decoder so both
// compute the same bits. Double precision: a float avg * i drifts by a few entries at 10M
// primitives, which would widen every residual.
SLIM_INLINE int64_t predict_offset(double avg, uint32_t i) { return int64_t(avg * double(i)); }

// Hot-path decoder of a QuantizedMesh, specialised on the paper's letters.
template <bool P, bool F, bool V>
struct CostaView {
  QuantizedMesh::Raw r{};

  SLIM_INLINE uint32_t offset(uint32_t i) const {
    if constexpr (P)
      return uint32_t(predict_offset(r.avg, i) + r.residual_min +
                      int64_t(bit_read(r.residuals, r.residual_bits, i)));
    else
      return r.offsets[i];
  }
  SLIM_INLINE uint32_t face(uint64_t j) const {
    if constexpr (F)
      return bit_read(r.packed_faces, r.face_bits, j);
    else
      return r.faces[j];
  }
  SLIM_INLINE Vec3f vertex(uint32_t k) const {
    if constexpr (V)
      return r.quant.decode(r.qvertices + 3 * uint64_t(k));
    else
      return r.vertices[k];
  }
};

}  // namespace slim
