// Binned SAH BVH2 builder (I. Wald, "On fast Construction of SAH-based Bounding Volume
// Hierarchies", 2007): centroids binned into `bins` bins along each axis, the best of the
// 3 x (bins-1) planes chosen by the SAH, primitives partitioned in place. Large nodes bin in
// parallel and both halves build as parallel tasks (TBB).
#include "bvh/build.h"

#include "core/simd.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_invoke.h>
#include <tbb/parallel_reduce.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <cmath>

namespace slim {
namespace {

using simd::vfloat4;
using simd::vint4;

constexpr int kMaxBins = 64;
constexpr uint32_t kParallelBinThreshold = 1u << 16;   // refs per node to bin in parallel
constexpr uint32_t kParallelTaskThreshold = 1u << 12;  // refs per node to build children as tasks
constexpr int kSahDepth = 64;                           // deeper: object median splits

// A PrimRef's box as two 4-wide vectors (the 4th lanes hold unrelated bytes and are ignored).
SLIM_INLINE vfloat4 ref_lo(const PrimRef& r) { return vfloat4::loadu(&r.box.lo.x); }
SLIM_INLINE vfloat4 ref_hi(const PrimRef& r) { return vfloat4::loadu(&r.box.hi.x); }

struct Box4 {
  vfloat4 lo{kInf}, hi{-kInf};
  SLIM_INLINE void extend(vfloat4 l, vfloat4 h) {
    lo = simd::min(lo, l);
    hi = simd::max(hi, h);
  }
  SLIM_INLINE void extend(const Box4& b) { extend(b.lo, b.hi); }
  SLIM_INLINE Box3f box3() const {
    return Box3f({lo[0], lo[1], lo[2]}, {hi[0], hi[1], hi[2]});
  }
  SLIM_INLINE float half_area() const {
    alignas(16) float d[4];
    (hi - lo).storeu(d);
    return d[0] >= 0.0f ? d[0] * d[1] + d[1] * d[2] + d[2] * d[0] : 0.0f;
  }
};

// Bin boxes are left uninitialised on construction: clear() sets the ones in use.
struct BinBox {
  vfloat4 lo, hi;
  SLIM_INLINE void extend(vfloat4 l, vfloat4 h) {
    lo = simd::min(lo, l);
    hi = simd::max(hi, h);
  }
};

struct Bins {
  BinBox box[3][kMaxBins];
  uint32_t count[3][kMaxBins];
  void clear(int nb) {
    for (int a = 0; a < 3; ++a)
      for (int i = 0; i < nb; ++i) {
        box[a][i] = {vfloat4(kInf), vfloat4(-kInf)};
        count[a][i] = 0;
      }
  }
  void merge(const Bins& o, int nb) {
    for (int a = 0; a < 3; ++a)
      for (int i = 0; i < nb; ++i) {
        box[a][i].extend(o.box[a][i].lo, o.box[a][i].hi);
        count[a][i] += o.count[a][i];
      }
  }
};

// Centroid (times 2) -> bin, for the 3 axes at once.
struct Binner {
  vfloat4 lo, scale;
  int nb;
  SLIM_INLINE vint4 bins(vfloat4 c2) const {
    return simd::clamp(simd::to_int_trunc((c2 - lo) * scale), vint4(0), vint4(nb - 1));
  }
  SLIM_INLINE int bin(const PrimRef& r, int axis) const {
    float c = (r.box.lo[axis] + r.box.hi[axis] - lo[axis]) * scale[axis];
    int b = int(c);
    return b < 0 ? 0 : (b > nb - 1 ? nb - 1 : b);
  }
};

struct Split {
  int axis = -1;
  int pos = 0;  // primitives with bin < pos go left
  float cost = kInf;
};

struct Range {
  Box4 box;  // primitive bounds
  Box4 cb;   // centroid (x2) bounds
};

class Builder {
 public:
  Builder(std::vector<PrimRef>& refs, const Bvh2BuildConfig& cfg, Bvh2& out)
      : refs_(refs),
        cfg_(cfg),
        out_(out),
        nb_(std::clamp(cfg.bins, 2, kMaxBins)),
        inv_block_(1.0f / float(std::max<uint32_t>(cfg.block_prims, 1))) {}

  void run() {
    const uint32_t n = uint32_t(refs_.size());
    out_.nodes.clear();
    out_.prim_ids.clear();
    if (n == 0) return;
    out_.nodes.resize(2 * size_t(n) - 1);
    node_count_ = 1;
    build(0, 0, n, range_of(0, n), 0);
    out_.nodes.resize(node_count_.load());
    out_.prim_ids.resize(n);
    for (uint32_t i = 0; i < n; ++i) out_.prim_ids[i] = refs_[i].id;
    out_.depth = max_depth_.load();
  }

 private:
  // Leaf blocks for n primitives (the SAH's intersection cost unit).
  SLIM_INLINE float blocks(uint32_t n) const { return std::ceil(float(n) * inv_block_); }

  Range range_of(uint32_t begin, uint32_t end) const {
    auto body = [&](const tbb::blocked_range<uint32_t>& r, Range a) {
      for (uint32_t i = r.begin(); i < r.end(); ++i) {
        vfloat4 l = ref_lo(refs_[i]), h = ref_hi(refs_[i]);
        a.box.extend(l, h);
        vfloat4 c = l + h;
        a.cb.extend(c, c);
      }
      return a;
    };
    if (end - begin >= kParallelBinThreshold)
      return tbb::parallel_reduce(tbb::blocked_range<uint32_t>(begin, end, 8192), Range{}, body,
                                  [](Range x, const Range& y) {
                                    x.box.extend(y.box);
                                    x.cb.extend(y.cb);
                                    return x;
                                  });
    return body(tbb::blocked_range<uint32_t>(begin, end), Range{});
  }

  void bin_range(const Binner& b, uint32_t begin, uint32_t end, Bins& bins) const {
    alignas(16) int32_t k[4];
    for (uint32_t i = begin; i < end; ++i) {
      vfloat4 l = ref_lo(refs_[i]), h = ref_hi(refs_[i]);
      b.bins(l + h).storeu(k);
      for (int a = 0; a < 3; ++a) {
        bins.box[a][k[a]].extend(l, h);
        bins.count[a][k[a]]++;
      }
    }
  }

  Split find_split(const Bins& bins, int nb, const Vec3f& cext) const {
    Split best;
    for (int a = 0; a < 3; ++a) {
      if (!(cext[a] > 0.0f)) continue;
      // Sweep from the right: cost and count of everything at or right of bin i.
      float rcost[kMaxBins];
      uint32_t rcnt[kMaxBins];
      Box4 rb;
      uint32_t rc = 0;
      for (int i = nb - 1; i > 0; --i) {
        rb.extend(bins.box[a][i].lo, bins.box[a][i].hi);
        rc += bins.count[a][i];
        rcost[i] = rb.half_area() * blocks(rc);
        rcnt[i] = rc;
      }
      Box4 lb;
      uint32_t lc = 0;
      for (int i = 1; i < nb; ++i) {
        lb.extend(bins.box[a][i - 1].lo, bins.box[a][i - 1].hi);
        lc += bins.count[a][i - 1];
        if (lc == 0 || rcnt[i] == 0) continue;
        float cost = lb.half_area() * blocks(lc) + rcost[i];
        if (cost < best.cost) best = {a, i, cost};
      }
    }
    return best;
  }

  // In-place partition by bin < pos on the split axis, computing both children's bounds.
  uint32_t partition(const Binner& b, const Split& s, uint32_t begin, uint32_t end, Range& left,
                     Range& right) {
    uint32_t i = begin, j = end;
    auto add = [](Range& r, const PrimRef& p) {
      vfloat4 l = ref_lo(p), h = ref_hi(p);
      r.box.extend(l, h);
      vfloat4 c = l + h;
      r.cb.extend(c, c);
    };
    for (;;) {
      while (i < j && b.bin(refs_[i], s.axis) < s.pos) add(left, refs_[i++]);
      while (i < j && b.bin(refs_[j - 1], s.axis) >= s.pos) add(right, refs_[--j]);
      if (i >= j) break;
      std::swap(refs_[i], refs_[j - 1]);
      add(left, refs_[i++]);
      add(right, refs_[--j]);
    }
    return i;
  }

  // Bins the range and returns the best SAH split. Not inlined so that the bins (several KB) do
  // not live in the frame of the recursive build(). Small nodes use fewer bins (one per
  // primitive at most), which keeps the per-node cost proportional to the node.
  __attribute__((noinline)) Split bin_and_split(uint32_t begin, uint32_t end, const Box3f& cbox,
                                                Binner& b) const {
    const uint32_t n = end - begin;
    const Vec3f cext = cbox.hi - cbox.lo;
    const int nb = int(std::min<uint32_t>(uint32_t(nb_), std::max<uint32_t>(n, 2)));
    b.nb = nb;
    float lo4[4] = {cbox.lo.x, cbox.lo.y, cbox.lo.z, 0.0f}, sc4[4] = {0, 0, 0, 0};
    for (int a = 0; a < 3; ++a) sc4[a] = cext[a] > 0.0f ? float(nb) * 0.99999f / cext[a] : 0.0f;
    b.lo = vfloat4::loadu(lo4);
    b.scale = vfloat4::loadu(sc4);
    if (n >= kParallelBinThreshold) {
      Bins empty;
      empty.clear(nb);
      Bins bins = tbb::parallel_reduce(
          tbb::blocked_range<uint32_t>(begin, end, 16384), empty,
          [&](const tbb::blocked_range<uint32_t>& r, Bins acc) {
            bin_range(b, r.begin(), r.end(), acc);
            return acc;
          },
          [&](Bins x, const Bins& y) {
            x.merge(y, nb);
            return x;
          });
      return find_split(bins, nb, cext);
    }
    Bins bins;
    bins.clear(nb);
    bin_range(b, begin, end, bins);
    return find_split(bins, nb, cext);
  }

  void make_leaf(uint32_t node, uint32_t begin, uint32_t end, const Box3f& box, int depth) {
    Bvh2Node& nd = out_.nodes[node];
    nd.box = box;
    nd.first = begin;
    nd.count = end - begin;
    int d = max_depth_.load(std::memory_order_relaxed);
    while (depth > d && !max_depth_.compare_exchange_weak(d, depth)) {
    }
  }

  void build(uint32_t node, uint32_t begin, uint32_t end, const Range& range, int depth) {
    const uint32_t n = end - begin;
    const Box3f box = range.box.box3();
    // A split never beats a leaf of at most one block: both halves would cost a block each on
    // top of the node (SAH), so such nodes become leaves without binning.
    if (n == 1 || (n <= cfg_.block_prims && n <= cfg_.max_leaf_size))
      return make_leaf(node, begin, end, box, depth);

    const Box3f cbox = range.cb.box3();
    const Vec3f cext = cbox.hi - cbox.lo;
    uint32_t mid = begin;
    Range left, right;
    bool median = depth >= kSahDepth || !(reduce_max(cext) > 0.0f);
    if (!median) {
      Binner b;
      Split s = bin_and_split(begin, end, cbox, b);
      float leaf_cost = box.half_area() * blocks(n);
      float split_cost = cfg_.trav_cost * box.half_area() + s.cost;
      if (n <= cfg_.max_leaf_size && (s.axis < 0 || leaf_cost <= split_cost))
        return make_leaf(node, begin, end, box, depth);
      if (s.axis < 0) {
        median = true;
      } else {
        mid = partition(b, s, begin, end, left, right);
        if (mid == begin || mid == end) median = true;
      }
    } else if (n <= cfg_.max_leaf_size) {
      return make_leaf(node, begin, end, box, depth);
    }
    if (median) {
      // Object median along the largest centroid extent (or by index if all centroids agree).
      mid = begin + n / 2;
      if (reduce_max(cext) > 0.0f) {
        int a = max_dim(cext);
        std::nth_element(refs_.begin() + begin, refs_.begin() + mid, refs_.begin() + end,
                         [a](const PrimRef& x, const PrimRef& y) {
                           return x.box.lo[a] + x.box.hi[a] < y.box.lo[a] + y.box.hi[a];
                         });
      }
      left = range_of(begin, mid);
      right = range_of(mid, end);
    }

    uint32_t first = node_count_.fetch_add(2);
    Bvh2Node& nd = out_.nodes[node];
    nd.box = box;
    nd.first = first;
    nd.count = 0;
    if (n >= kParallelTaskThreshold) {
      tbb::parallel_invoke([&] { build(first, begin, mid, left, depth + 1); },
                           [&] { build(first + 1, mid, end, right, depth + 1); });
    } else {
      build(first, begin, mid, left, depth + 1);
      build(first + 1, mid, end, right, depth + 1);
    }
  }

  std::vector<PrimRef>& refs_;
  const Bvh2BuildConfig& cfg_;
  Bvh2& out_;
  int nb_;
  float inv_block_;
  std::atomic<uint32_t> node_count_{0};
  std::atomic<int> max_depth_{0};
};

}  // namespace

Bvh2 build_bvh2(std::vector<PrimRef>&& refs, const Bvh2BuildConfig& cfg) {
  Bvh2 out;
  Builder b(refs, cfg, out);
  if (cfg.threads > 0) {
    tbb::task_arena arena(cfg.threads);
    arena.execute([&] { b.run(); });
  } else {
    b.run();
  }
  std::vector<PrimRef>().swap(refs);
  return out;
}

}  // namespace slim
