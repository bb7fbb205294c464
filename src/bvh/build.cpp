// Binned SAH BVH2 builder (I. Wald, "On fast Construction of SAH-based Bounding Volume
// Hierarchies", 2007): centroids binned into `bins` bins along each axis, the best of the
// 3 x (bins-1) planes chosen by the SAH, primitives partitioned in place. Large nodes bin in
// parallel and both halves build as parallel tasks (TBB).
#include "bvh/build.h"

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

constexpr int kMaxBins = 64;
constexpr uint32_t kParallelBinThreshold = 1u << 16;  // refs per node to bin in parallel
constexpr uint32_t kParallelTaskThreshold = 1u << 12; // refs per node to build children as tasks
constexpr int kSahDepth = 64;                          // deeper: object median splits

struct CentroidBounds {
  Vec3f lo{kInf, kInf, kInf}, hi{-kInf, -kInf, -kInf};
  void extend(Vec3f c) {
    lo = min(lo, c);
    hi = max(hi, c);
  }
  void extend(const CentroidBounds& o) {
    lo = min(lo, o.lo);
    hi = max(hi, o.hi);
  }
};

SLIM_INLINE Vec3f centroid2(const Box3f& b) { return b.lo + b.hi; }  // 2x the centroid

struct Bins {
  std::array<std::array<Box3f, kMaxBins>, 3> box;
  std::array<std::array<uint32_t, kMaxBins>, 3> count{};
  void merge(const Bins& o, int nb) {
    for (int a = 0; a < 3; ++a)
      for (int i = 0; i < nb; ++i) {
        box[a][i].extend(o.box[a][i]);
        count[a][i] += o.count[a][i];
      }
  }
};

struct Binner {
  Vec3f lo, scale;  // bin index = (centroid2 - lo) * scale
  int nb;
  SLIM_INLINE int bin(float c2, int axis) const {
    int b = int((c2 - lo[axis]) * scale[axis]);
    return std::clamp(b, 0, nb - 1);
  }
};

struct Split {
  int axis = -1;
  int pos = 0;  // primitives with bin < pos go left
  float cost = kInf;
};

class Builder {
 public:
  Builder(std::vector<PrimRef>& refs, const Bvh2BuildConfig& cfg, Bvh2& out)
      : refs_(refs), cfg_(cfg), out_(out), nb_(std::clamp(cfg.bins, 2, kMaxBins)) {}

  void run() {
    const uint32_t n = uint32_t(refs_.size());
    out_.nodes.clear();
    out_.prim_ids.clear();
    if (n == 0) return;
    out_.nodes.resize(2 * size_t(n) - 1);
    node_count_ = 1;
    Box3f box;
    CentroidBounds cb;
    bounds_of(0, n, box, cb);
    build(0, 0, n, box, cb, 0);
    out_.nodes.resize(node_count_.load());
    out_.prim_ids.resize(n);
    for (uint32_t i = 0; i < n; ++i) out_.prim_ids[i] = refs_[i].id;
    out_.depth = max_depth_.load();
  }

 private:
  float blocks(uint32_t n) const { return float((n + cfg_.block_prims - 1) / cfg_.block_prims); }

  void bounds_of(uint32_t begin, uint32_t end, Box3f& box, CentroidBounds& cb) const {
    struct Acc {
      Box3f box;
      CentroidBounds cb;
    };
    auto body = [&](const tbb::blocked_range<uint32_t>& r, Acc a) {
      for (uint32_t i = r.begin(); i < r.end(); ++i) {
        a.box.extend(refs_[i].box);
        a.cb.extend(centroid2(refs_[i].box));
      }
      return a;
    };
    Acc a;
    if (end - begin >= kParallelBinThreshold) {
      a = tbb::parallel_reduce(
          tbb::blocked_range<uint32_t>(begin, end, 8192), Acc{}, body, [](Acc x, const Acc& y) {
            x.box.extend(y.box);
            x.cb.extend(y.cb);
            return x;
          });
    } else {
      a = body(tbb::blocked_range<uint32_t>(begin, end), Acc{});
    }
    box = a.box;
    cb = a.cb;
  }

  void bin_range(const Binner& b, uint32_t begin, uint32_t end, Bins& bins) const {
    for (uint32_t i = begin; i < end; ++i) {
      const Box3f& box = refs_[i].box;
      Vec3f c = centroid2(box);
      for (int a = 0; a < 3; ++a) {
        int k = b.bin(c[a], a);
        bins.box[a][k].extend(box);
        bins.count[a][k]++;
      }
    }
  }

  Split find_split(const Binner& b, const Bins& bins, const Vec3f& cext) const {
    Split best;
    for (int a = 0; a < 3; ++a) {
      if (!(cext[a] > 0.0f)) continue;
      // Sweep from the right: cost and count of everything at or right of bin i.
      std::array<float, kMaxBins> rcost;
      std::array<uint32_t, kMaxBins> rcnt;
      Box3f rb;
      uint32_t rc = 0;
      for (int i = nb_ - 1; i > 0; --i) {
        rb.extend(bins.box[a][i]);
        rc += bins.count[a][i];
        rcost[i] = rb.half_area() * blocks(rc);
        rcnt[i] = rc;
      }
      Box3f lb;
      uint32_t lc = 0;
      for (int i = 1; i < nb_; ++i) {
        lb.extend(bins.box[a][i - 1]);
        lc += bins.count[a][i - 1];
        if (lc == 0 || rcnt[i] == 0) continue;
        float cost = lb.half_area() * blocks(lc) + rcost[i];
        if (cost < best.cost) best = {a, i, cost};
      }
    }
    return best;
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

  void build(uint32_t node, uint32_t begin, uint32_t end, const Box3f& box,
             const CentroidBounds& cb, int depth) {
    const uint32_t n = end - begin;
    if (n == 1) return make_leaf(node, begin, end, box, depth);

    Vec3f cext = cb.hi - cb.lo;
    uint32_t mid = begin;
    bool median = depth >= kSahDepth || !(reduce_max(cext) > 0.0f);
    if (!median) {
      Binner b;
      b.nb = nb_;
      b.lo = cb.lo;
      for (int a = 0; a < 3; ++a)
        b.scale[a] = cext[a] > 0.0f ? float(nb_) * 0.99999f / cext[a] : 0.0f;
      Bins bins;
      if (n >= kParallelBinThreshold) {
        bins = tbb::parallel_reduce(
            tbb::blocked_range<uint32_t>(begin, end, 16384), Bins{},
            [&](const tbb::blocked_range<uint32_t>& r, Bins acc) {
              bin_range(b, r.begin(), r.end(), acc);
              return acc;
            },
            [&](Bins x, const Bins& y) {
              x.merge(y, nb_);
              return x;
            });
      } else {
        bin_range(b, begin, end, bins);
      }
      Split s = find_split(b, bins, cext);
      float leaf_cost = box.half_area() * blocks(n);
      float split_cost = cfg_.trav_cost * box.half_area() + s.cost;
      if (n <= cfg_.max_leaf_size && (s.axis < 0 || leaf_cost <= split_cost))
        return make_leaf(node, begin, end, box, depth);
      if (s.axis < 0) {
        median = true;
      } else {
        auto it = std::partition(refs_.begin() + begin, refs_.begin() + end, [&](const PrimRef& r) {
          return b.bin(centroid2(r.box)[s.axis], s.axis) < s.pos;
        });
        mid = uint32_t(it - refs_.begin());
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
                           return centroid2(x.box)[a] < centroid2(y.box)[a];
                         });
      }
    }

    uint32_t left = node_count_.fetch_add(2);
    Bvh2Node& nd = out_.nodes[node];
    nd.box = box;
    nd.first = left;
    nd.count = 0;

    Box3f lbox, rbox;
    CentroidBounds lcb, rcb;
    bounds_of(begin, mid, lbox, lcb);
    bounds_of(mid, end, rbox, rcb);
    if (n >= kParallelTaskThreshold) {
      tbb::parallel_invoke([&] { build(left, begin, mid, lbox, lcb, depth + 1); },
                           [&] { build(left + 1, mid, end, rbox, rcb, depth + 1); });
    } else {
      build(left, begin, mid, lbox, lcb, depth + 1);
      build(left + 1, mid, end, rbox, rcb, depth + 1);
    }
  }

  std::vector<PrimRef>& refs_;
  const Bvh2BuildConfig& cfg_;
  Bvh2& out_;
  int nb_;
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
