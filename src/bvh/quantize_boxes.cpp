// Quantized boxes of the BVH8 nodes and multi-leaves (bvh/bvh8.h), in a file of their own: the
// cluster encoder (prim/cluster.cpp) makes a multi-leaf's boxes too, and its fuzz target links
// this file without the rest of the BVH.
#include <algorithm>
#include <cmath>

#include "bvh/bvh8.h"
#include "core/assert.h"

namespace slim {

// ---- quantized boxes (Benthin et al. 2018, section 4.1 "Node Compression and Decompression") ---

namespace {

// The decoder's arithmetic, exactly: start + q * extent with one rounding (fma), as vfloat8 does.
SLIM_INLINE float decode_q(uint8_t q, float extent, float start) {
  return std::fma(float(q), extent, start);
}

}  // namespace

void quantize_planes(const float* start, const float* extent, const Box3f* boxes, int n,
                     uint8_t (*q)[8]) {
  for (int a = 0; a < 3; ++a) {
    const float s = start[a], ext = extent[a];
    for (int i = 0; i < 8; ++i) {
      uint8_t qlo = 255, qhi = 0;
      if (i < n) {
        float lo = boxes[i].lo[a], up = boxes[i].hi[a];
        float fl = std::floor((lo - s) / ext);
        float fu = std::ceil((up - s) / ext);
        int ql = int(std::clamp(fl, 0.0f, 255.0f));
        int qu = int(std::clamp(fu, 0.0f, 255.0f));
        while (ql > 0 && decode_q(uint8_t(ql), ext, s) > lo) --ql;
        while (qu < 255 && decode_q(uint8_t(qu), ext, s) < up) ++qu;
        qlo = uint8_t(ql);
        qhi = uint8_t(qu);
        SLIM_ASSERT(decode_q(qlo, ext, s) <= lo && decode_q(qhi, ext, s) >= up);
      }
      q[2 * a][i] = qlo;
      q[2 * a + 1][i] = qhi;
    }
  }
}

void quantize_boxes(const Box3f& parent, const Box3f* boxes, int n, QuantBoxes8& out) {
  for (int a = 0; a < 3; ++a) {
    float start = parent.lo[a];
    float hi = parent.hi[a];
    float ext = (hi - start) / 255.0f;
    // The step must be > 0 and 255 steps must reach the parent's upper bound, so that decoded
    // boxes are conservative and empty slots (lo = 255, hi = 0) decode to lo > hi.
    if (!(ext > 0.0f)) ext = std::max(std::fabs(start) * 1e-7f, 1e-30f);
    while (decode_q(255, ext, start) < hi || !(decode_q(255, ext, start) > start))
      ext = std::nextafter(ext, kInf) * (1.0f + 1e-7f);
    out.start[a] = start;
    out.extent[a] = ext;
  }
  quantize_planes(out.start, out.extent, boxes, n, out.q);
}

Box3f dequantize_planes(const uint8_t (*q)[8], const float* start, const float* extent, int i) {
  Box3f b;
  for (int a = 0; a < 3; ++a) {
    b.lo[a] = decode_q(q[2 * a][i], extent[a], start[a]);
    b.hi[a] = decode_q(q[2 * a + 1][i], extent[a], start[a]);
  }
  return b;
}

Box3f dequantize_box(const QuantBoxes8& q, int i) {
  return dequantize_planes(q.q, q.start, q.extent, i);
}

}  // namespace slim
