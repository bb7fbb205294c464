// libFuzzer target: the Costa quantized n-gon mesh bit streams (src/prim/quantized_mesh.h;
// Costa, Pereira, Jorge, "Fast Compression of Meshes for GPU Ray-Tracing", section 3.2): the
// bit-packed arrays (BitArray), the predicted primitive array (P), the packed face array (F) and
// the 16-bit vertex quantization (V), on meshes made from the fuzz input.
//
// Input bytes:
//   [0]      bit 0: triangulate first (T); bit 1: raw float vertices (any bits, NaN/Inf
//            included) instead of int16 lattice vertices; bits 2-7: the lattice scale exponent
//   [1]      vertex count - 1 (1..256)
//   then     vertices (3 x int16 or 3 x float each), then faces until the input ends: a size byte
//            (3 + byte % 14 corners) and one index byte per corner (taken modulo the vertex count)
//   first 8 bytes of the rest also drive the BitArray round trip
// Checks, for all 8 combinations of P, F, V:
//   - QuantizedMesh::validate() accepts the store of a mesh load_ngon_mesh() produced;
//   - round trip: every offset and face entry decodes to the NgonMesh's, through the generic
//     accessors and the hot-path CostaView<P, F, V>; every finite vertex decodes exactly (no V) or
//     within half a quantization step plus float rounding (V; Listing 4, rounded to nearest);
//   - BitArray: values of any width 0..32 read back as written.
#include <cmath>
#include <cstdint>
#include <cstring>
#include <string>
#include <vector>

#include "fuzz_common.h"
#include "mesh/tessellate.h"
#include "prim/quantized_mesh.h"

namespace {

using namespace slim;

using fuzz::Reader;

void check_bit_array(Reader in) {
  const uint32_t width = in.byte() % 33;
  const uint64_t count = 1 + in.byte() % 200;
  BitArray a(count, width);
  std::vector<uint32_t> want(count);
  uint64_t seed = 0;
  in.bytes(&seed, 6);
  for (uint64_t i = 0; i < count; ++i) {
    seed = seed * 6364136223846793005ULL + 1442695040888963407ULL;
    const uint32_t mask = width == 32 ? 0xffffffffu : (1u << width) - 1;
    want[i] = uint32_t(seed >> 29) & mask;
    a.set(i, want[i]);
  }
  for (uint64_t i = 0; i < count; ++i)
    SLIM_FUZZ_CHECK(a.get(i) == want[i],
                    "BitArray width " + std::to_string(width) + " entry " + std::to_string(i));
}

template <bool P, bool F, bool V>
void check_store(const NgonMesh& m) {
  const QuantizedMesh q(m, P, F, V);
  const std::string which =
      std::string("costa-") + (P ? "P" : "") + (F ? "F" : "") + (V ? "V" : "");
  std::string why;
  SLIM_FUZZ_CHECK(q.validate(&why), which + ": " + why);
  SLIM_FUZZ_CHECK(q.prim_count() == m.prim_count() && q.face_count() == m.faces.size(), which);
  CostaView<P, F, V> view{q.raw()};
  for (uint32_t i = 0; i <= q.prim_count(); ++i) {
    SLIM_FUZZ_CHECK(q.offset(i) == m.prim_offsets[i], which + " offset " + std::to_string(i));
    SLIM_FUZZ_CHECK(view.offset(i) == m.prim_offsets[i], which + " view offset");
  }
  for (uint64_t j = 0; j < m.faces.size(); ++j) {
    SLIM_FUZZ_CHECK(q.face(j) == m.faces[j], which + " face entry " + std::to_string(j));
    SLIM_FUZZ_CHECK(view.face(j) == m.faces[j], which + " view face entry");
  }
  Box3f box;
  for (const Vec3f& p : m.vertices)
    if (is_finite(p)) box.extend(p);
  const Vec3f size = box.size();
  // A box wider than the float range cannot be decoded as lo + q * step (q * step overflows).
  const bool decodable = reduce_max(size) < 1e38f;
  for (uint32_t k = 0; k < m.vertices.size(); ++k) {
    const Vec3f got = q.vertex(k), want = m.vertices[k];
    SLIM_FUZZ_CHECK(got == view.vertex(k) || !is_finite(want), which + " view vertex");
    if (!is_finite(want)) continue;
    if (!V) {
      SLIM_FUZZ_CHECK(fuzz::same_bits(got.x, want.x) && fuzz::same_bits(got.y, want.y) &&
                          fuzz::same_bits(got.z, want.z),
                      which + " vertex " + std::to_string(k));
      continue;
    }
    if (!decodable) continue;
    for (int a = 0; a < 3; ++a) {
      // The step the specification gives (Listing 4: 16 bits per component in the box of the
      // finite vertices), from this target's own box, not the quantizer's stored step.
      const double step = (double(box.hi[a]) - double(box.lo[a])) / 65535.0;
      // Float rounding of lo + q * step (the stored step is this one rounded to float: at most
      // 65535 of its ulps, below the term below); and a box narrower than 65535 denormal steps
      // (about 1e-40) has its step rounded to a denormal or to 0, every vertex then decodes near
      // lo.
      const double ulp =
          2.4e-7 * (std::fabs(double(box.lo[a])) + std::fabs(double(box.hi[a]))) + 1e-40;
      SLIM_FUZZ_CHECK(std::fabs(double(got[a]) - double(want[a])) <= 0.5 * step + ulp,
                      which + " vertex " + std::to_string(k) + " axis " + std::to_string(a) + ": " +
                          std::to_string(got[a]) + " for " + std::to_string(want[a]));
    }
  }
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  Reader in{data, size};
  check_bit_array(in);
  const uint8_t mode = in.byte();
  const bool triangulate = mode & 1, raw = mode & 2;
  const int exp = int(mode >> 2) - 32;
  const uint32_t nv = 1 + in.byte();
  PolyMesh mesh;
  mesh.name = "fuzz";
  for (uint32_t k = 0; k < nv; ++k) {
    if (raw) {
      Vec3f p;
      in.bytes(&p, sizeof p);
      mesh.positions.push_back(p);
    } else {
      int16_t q[3];
      in.bytes(q, sizeof q);
      mesh.positions.push_back(Vec3f(std::ldexp(float(q[0]), exp), std::ldexp(float(q[1]), exp),
                                     std::ldexp(float(q[2]), exp)));
    }
  }
  while (in.n > 0) {
    const uint32_t corners = 3 + in.byte() % 14;
    mesh.face_sizes.push_back(corners);
    for (uint32_t c = 0; c < corners; ++c) mesh.face_indices.push_back(in.byte() % nv);
  }
  NgonMesh m;
  try {
    m = load_ngon_mesh({&mesh});
    if (triangulate) m = triangulate_ngon_mesh(m);
  } catch (const Error&) {
    return 0;
  }
  check_store<false, false, false>(m);
  check_store<false, false, true>(m);
  check_store<false, true, false>(m);
  check_store<false, true, true>(m);
  check_store<true, false, false>(m);
  check_store<true, false, true>(m);
  check_store<true, true, false>(m);
  check_store<true, true, true>(m);
  return 0;
}
