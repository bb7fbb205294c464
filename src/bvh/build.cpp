// Binned SAH BVH2 builder (I. Wald, "On fast Construction of SAH-based Bounding Volume
// Hierarchies", 2007): centroids binned into `bins` bins along each axis, the best of the
// 3 x (bins-1) planes chosen by the SAH, primitives partitioned in place. Large nodes bin in
// parallel and both halves build as parallel tasks (TBB).
#include "bvh/build.h"

#include "core/progress.h"
#include "core/simd.h"
#include "core/simd_ext.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_invoke.h>
#include <tbb/parallel_reduce.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <cmath>
#include <cstring>
#include <memory>
#include <mutex>
#include <stdexcept>

namespace slim {
namespace {

using simd::vfloat4;
using simd::vfloat8;
using simd::vint4;

constexpr int kMaxBins = 64;
constexpr uint32_t kParallelBinThreshold = 1u << 16;   // refs per node to bin in parallel
constexpr uint32_t kParallelTaskThreshold = 1u << 12;  // refs per node to build children as tasks
constexpr uint32_t kTwoBinSetThreshold = 256;          // refs per node to bin into two bin sets
constexpr int kSahDepth = 64;                          // deeper: object median splits

// The builder's own primitive reference: one aligned 8-float row [-lo.x, -lo.y, -lo.z, idlo |
// hi.x, hi.y, hi.z, idhi]. With the lower corner negated, growing a box by another is a single
// 8-wide max (Embree keeps its bins the same way), and a whole reference is one aligned load.
// Lanes 3 and 7 hold no coordinate and are ignored by every result, but the 8-wide arithmetic
// still runs on them: they carry the id's two 16-bit halves as quiet-NaN payloads. Raw id bits
// would be a denormal float for every id below 2^23, and a denormal operand costs x86 CPUs a
// microcode assist per operation (binning terrain/torus references: 17-21 TSC cycles each instead
// of 8-11, rdtsc per node class on torus:1024). NaN operands cost nothing.
constexpr uint32_t kNanBox = 0x7FC00000u;
struct alignas(32) Ref {
  float v[8];
  SLIM_INLINE vfloat8 row() const { return vfloat8::load(v); }
  SLIM_INLINE uint32_t id() const {
    uint32_t lo, hi;
    std::memcpy(&lo, &v[3], 4);
    std::memcpy(&hi, &v[7], 4);
    return (lo & 0xFFFFu) | (hi & 0xFFFFu) << 16;
  }
  // Twice the centroid on axis a (lo + hi, rounded once).
  SLIM_INLINE float c2(int a) const { return v[4 + a] - v[a]; }
};
static_assert(sizeof(Ref) == 32);

SLIM_INLINE Ref make_ref(const PrimRef& p) {
  Ref r;
  for (int a = 0; a < 3; ++a) {
    r.v[a] = -p.box.lo[a];
    r.v[4 + a] = p.box.hi[a];
  }
  const uint32_t lo = kNanBox | (p.id & 0xFFFFu), hi = kNanBox | p.id >> 16;
  std::memcpy(&r.v[3], &lo, 4);
  std::memcpy(&r.v[7], &hi, 4);
  return r;
}

// Box as one 8-wide row [-lo | hi] (lanes 3, 7 ignored); empty = all -inf.
struct Box8 {
  vfloat8 b{-kInf};
  SLIM_INLINE void extend(vfloat8 r) { b = simd::max(b, r); }
  SLIM_INLINE Box3f box3() const {
    alignas(32) float t[8];
    b.store(t);
    return Box3f({-t[0], -t[1], -t[2]}, {t[4], t[5], t[6]});
  }
  // Half the surface area, 0 for an empty box: (dx*dy + dy*dz) + dz*dx as the scalar code did.
  SLIM_INLINE float half_area() const {
    alignas(16) float d[4];
    (simd::upper4(b) + simd::lower4(b)).storeu(d);  // hi - lo
    return d[0] >= 0.0f ? d[0] * d[1] + d[1] * d[2] + d[2] * d[0] : 0.0f;
  }
};

// Primitive bounds and centroid (x2) bounds of a range; the centroid box is kept as [-c | c].
struct Range {
  Box8 box;
  Box8 cb;
  SLIM_INLINE void add(vfloat8 r) {
    box.extend(r);
    // [-lo | hi] - [hi | -lo] = [-(hi + lo) | hi + lo]: the centroid row in one lane swap and
    // one subtraction (the same hi + lo as upper4 - lower4, negated exactly).
    cb.extend(r - simd::swap_halves(r));
  }
  // The join of parallel_reduce.
  static Range merged(Range x, const Range& y) {
    x.box.extend(y.box.b);
    x.cb.extend(y.cb.b);
    return x;
  }
};

struct Bins {
  vfloat8 box[3][kMaxBins];     // [axis][bin] rows [-lo | hi]
  uint32_t count[kMaxBins][4];  // [bin][axis] (lane 3 unused), one 4-wide load per bin
  void clear(int nb) {
    for (int i = 0; i < nb; ++i) {
      for (int a = 0; a < 3; ++a) box[a][i] = vfloat8(-kInf);
      for (int a = 0; a < 4; ++a) count[i][a] = 0;
    }
  }
  void merge(const Bins& o, int nb) {
    for (int i = 0; i < nb; ++i) {
      for (int a = 0; a < 3; ++a) box[a][i] = simd::max(box[a][i], o.box[a][i]);
      for (int a = 0; a < 3; ++a) count[i][a] += o.count[i][a];
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
};

struct Split {
  int axis = -1;
  int pos = 0;  // primitives with bin < pos go left
  float cost = kInf;
};

class Builder {
 public:
  Builder(uint32_t count, const PrimRefFill& fill, const Bvh2BuildConfig& cfg, Bvh2& out)
      : count_(count),
        fill_(fill),
        cfg_(cfg),
        out_(out),
        nb_(std::clamp(cfg.bins, 2, kMaxBins)),
        inv_block_(1.0f / float(std::max<uint32_t>(cfg.block_prims, 1))) {}

  void run() {
    // Counts are summed in 32-bit signed lanes by the SAH sweep.
    if (count_ >= (uint32_t(1) << 31))
      throw std::length_error("BVH build: at most 2^31 - 1 primitives");
    const uint32_t n = count_;
    if (n == 0) return;
    // Every large array is uninitialised huge-page memory (core/large_array.h), first touched by
    // the threads that fill it; the nodes are bounded by 2n - 1 but only the pages of the nodes
    // made are ever touched.
    refs_ = LargeArray<Ref>(n);
    Range root = tbb::parallel_reduce(
        tbb::blocked_range<uint32_t>(0, n, 8192), Range{},
        [&](const tbb::blocked_range<uint32_t>& r, Range a) {
          constexpr uint32_t kChunk = 256;
          PrimRef tmp[kChunk];
          for (uint32_t b = r.begin(); b < r.end(); b += kChunk) {
            const uint32_t e = std::min(r.end(), b + kChunk);
            fill_(b, e, tmp);
            for (uint32_t i = b; i < e; ++i) {
              refs_[i] = make_ref(tmp[i - b]);
              a.add(refs_[i].row());
            }
          }
          if (cfg_.progress) cfg_.progress->add(r.size());
          return a;
        },
        Range::merged);
    out_.nodes = LargeArray<Bvh2Node>(2 * size_t(n) - 1);
    node_count_ = 1;
    build(0, 0, n, root, 0);
    out_.nodes.shrink(node_count_.load());
    out_.prim_ids = LargeArray<uint32_t>(n);
    tbb::parallel_for(tbb::blocked_range<uint32_t>(0, n, 16384),
                      [&](const tbb::blocked_range<uint32_t>& r) {
                        for (uint32_t i = r.begin(); i < r.end(); ++i)
                          out_.prim_ids[i] = refs_[i].id();
                      });
    refs_ = LargeArray<Ref>();
    out_.depth = max_depth_.load();
    std::sort(out_.dropped.begin(), out_.dropped.end());  // the same order on every run
  }

 private:
  // Leaf blocks for n primitives (the SAH's intersection cost unit).
  SLIM_INLINE float blocks(uint32_t n) const { return std::ceil(float(n) * inv_block_); }

  Range range_of(uint32_t begin, uint32_t end) const {
    auto body = [&](const tbb::blocked_range<uint32_t>& r, Range a) {
      for (uint32_t i = r.begin(); i < r.end(); ++i) a.add(refs_[i].row());
      return a;
    };
    if (end - begin >= kParallelBinThreshold)
      return tbb::parallel_reduce(tbb::blocked_range<uint32_t>(begin, end, 8192), Range{}, body,
                                  Range::merged);
    return body(tbb::blocked_range<uint32_t>(begin, end), Range{});
  }

  SLIM_INLINE void bin_one(const Binner& b, const Ref& ref, Bins& bins) const {
    alignas(16) int32_t k[4];
    const vfloat8 r = ref.row();
    b.bins(simd::upper4(r) - simd::lower4(r)).storeu(k);
    for (int a = 0; a < 3; ++a) {
      bins.box[a][k[a]] = simd::max(bins.box[a][k[a]], r);
      bins.count[k[a]][a]++;
    }
  }

  // Neighbouring references mostly fall into the same bins, and each update of a bin waits for
  // the previous one (load - max - store). Large ranges alternate between two bin sets, merged at
  // the end, so that two such chains run side by side.
  void bin_range(const Binner& b, uint32_t begin, uint32_t end, Bins& bins) const {
    uint32_t i = begin;
    if (end - begin >= kTwoBinSetThreshold) {
      Bins second;
      second.clear(b.nb);
      for (; i + 1 < end; i += 2) {
        bin_one(b, refs_[i], bins);
        bin_one(b, refs_[i + 1], second);
      }
      bins.merge(second, b.nb);
    }
    for (; i < end; ++i) bin_one(b, refs_[i], bins);
  }

  // Half areas of the three boxes r0..r2 ([-lo | hi] rows) in lanes 0-2: (dx*dy + dy*dz) + dz*dx
  // per lane, as Box8::half_area computes it, 0 for an empty box.
  static SLIM_INLINE vfloat4 half_areas3(vfloat8 r0, vfloat8 r1, vfloat8 r2) {
    using namespace simd;
    vfloat4 x, y, z;
    transpose3(upper4(r0) + lower4(r0), upper4(r1) + lower4(r1), upper4(r2) + lower4(r2), x, y, z);
    const vfloat4 area = (x * y + y * z) + z * x;
    return select(x >= vfloat4(0.0f), area, vfloat4(0.0f));
  }

  // The SAH sweep over the bins of the three axes at once (lane = axis). Same arithmetic and the
  // same choice as a scalar sweep axis by axis, bin by bin, keeping the first strict minimum.
  Split find_split(const Bins& bins, int nb, const Vec3f& cext) const {
    using namespace simd;
    const vfloat4 inv_block(inv_block_);
    auto blocks4 = [&](vint4 c) { return ceil4(to_float4(c) * inv_block); };
    // Sweep from the right: cost and count of everything at or right of bin i.
    alignas(16) float rcost[kMaxBins][4];
    alignas(16) uint32_t rcnt[kMaxBins][4];
    vfloat8 r0(-kInf), r1(-kInf), r2(-kInf);
    vint4 rc(0);
    for (int i = nb - 1; i > 0; --i) {
      r0 = max(r0, bins.box[0][i]);
      r1 = max(r1, bins.box[1][i]);
      r2 = max(r2, bins.box[2][i]);
      rc = add4i(rc, load4i(bins.count[i]));
      (half_areas3(r0, r1, r2) * blocks4(rc)).storeu(rcost[i]);
      rc.storeu(reinterpret_cast<int32_t*>(rcnt[i]));
    }
    const float axis_ok[4] = {cext[0] > 0.0f ? 1.0f : 0.0f, cext[1] > 0.0f ? 1.0f : 0.0f,
                              cext[2] > 0.0f ? 1.0f : 0.0f, 0.0f};
    const vbool4 usable = vfloat4::loadu(axis_ok) > vfloat4(0.0f);
    vfloat8 l0(-kInf), l1(-kInf), l2(-kInf);
    vint4 lc(0);
    vfloat4 best(kInf), best_pos(0.0f);
    for (int i = 1; i < nb; ++i) {
      l0 = max(l0, bins.box[0][i - 1]);
      l1 = max(l1, bins.box[1][i - 1]);
      l2 = max(l2, bins.box[2][i - 1]);
      lc = add4i(lc, load4i(bins.count[i - 1]));
      const vfloat4 cost = half_areas3(l0, l1, l2) * blocks4(lc) + vfloat4::loadu(rcost[i]);
      const vbool4 ok =
          usable & (to_float4(lc) > vfloat4(0.0f)) & (to_float4(load4i(rcnt[i])) > vfloat4(0.0f));
      const vbool4 better = ok & (cost < best);
      best = select(better, cost, best);
      best_pos = select(better, vfloat4(float(i)), best_pos);
    }
    Split s;
    for (int a = 0; a < 3; ++a)
      if (best[a] < s.cost) s = {a, int(best_pos[a]), best[a]};
    return s;
  }

  // In-place partition by bin < pos on the split axis, computing both children's bounds.
  // The bounds grow in locals (registers): through the references they would be loaded and
  // stored back around every swap (the stores to refs may alias them), a store-to-load chain
  // per reference.
  uint32_t partition(const Binner& b, const Split& s, uint32_t begin, uint32_t end, Range& left,
                     Range& right) {
    uint32_t i = begin, j = end;
    Ref* refs = refs_.data();
    Range l, r;
    // bin < pos without the bin: clamp(trunc(c), 0, nb - 1) < pos <=> c < pos for an integer
    // 1 <= pos <= nb - 1, with c = (c2 - lo) * scale rounded exactly as Binner::bins (finite: the
    // coordinates are checked finite and in range).
    const int a = s.axis;
    const float lo = b.lo[a], scale = b.scale[a], pos = float(s.pos);
    auto left_of = [&](const Ref& x) { return (x.c2(a) - lo) * scale < pos; };
    for (;;) {
      while (i < j && left_of(refs[i])) l.add(refs[i++].row());
      while (i < j && !left_of(refs[j - 1])) r.add(refs[--j].row());
      if (i >= j) break;
      const vfloat8 x = refs[i].row(), y = refs[j - 1].row();
      y.store(refs[i].v);
      x.store(refs[j - 1].v);
      l.add(y);
      r.add(x);
      ++i, --j;
    }
    left = l;
    right = r;
    return i;
  }

  // Bins the range and returns the best SAH split. Not inlined so that the bins (several KB) do
  // not live in the frame of the recursive build(). Small nodes use fewer bins, 4 + n / 20 up to
  // cfg.bins (Embree's BinMapping rule): clearing and sweeping the bins is the cost of a small
  // node, not binning its few references. Against one bin per primitive up to cfg.bins: BVH2
  // build of terrain:1024 0.47 -> 0.42 s, SAH cost +0.02% (terrain), +0.2% (hawaii), +0.5%
  // (torus).
  __attribute__((noinline)) Split bin_and_split(uint32_t begin, uint32_t end, const Box3f& cbox,
                                                Binner& b) const {
    const uint32_t n = end - begin;
    const Vec3f cext = cbox.hi - cbox.lo;
    const int nb = int(std::min<uint32_t>(uint32_t(nb_), 4 + n / 20));
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

  void note_depth(int depth) {
    int d = max_depth_.load(std::memory_order_relaxed);
    while (depth > d && !max_depth_.compare_exchange_weak(d, depth)) {
    }
  }

  // Orders refs by their centroids on axis a (the object median and full_blocks' counts).
  static auto centroid_less(int a) {
    return [a](const Ref& x, const Ref& y) { return x.c2(a) < y.c2(a); };
  }

  // The split of the node over refs [begin, end): false if it becomes a leaf, else the refs are
  // partitioned at mid with the children's ranges in left and right.
  bool split(uint32_t begin, uint32_t end, const Range& range, int depth, uint32_t& mid,
             Range& left, Range& right) {
    const uint32_t n = end - begin;
    // A split never beats a leaf of at most one block: both halves would cost a block each on
    // top of the node (SAH), so such nodes become leaves without binning.
    if (n == 1 || (n <= cfg_.block_prims && n <= cfg_.max_leaf_size)) return false;
    const Box3f cbox = range.cb.box3();
    const Vec3f cext = cbox.hi - cbox.lo;
    mid = begin;
    bool median = depth >= kSahDepth || !(reduce_max(cext) > 0.0f);
    if (!median) {
      Binner b;
      Split s = bin_and_split(begin, end, cbox, b);
      float leaf_cost = range.box.half_area() * blocks(n);
      float split_cost = cfg_.trav_cost * range.box.half_area() + s.cost;
      if (n <= cfg_.max_leaf_size && (s.axis < 0 || leaf_cost <= split_cost)) return false;
      if (s.axis < 0) {
        median = true;
      } else {
        mid = partition(b, s, begin, end, left, right);
        if (mid == begin || mid == end)
          median = true;
        else if (n <= cfg_.full_blocks_below)
          full_blocks(b, s, begin, end, mid, left, right);
      }
    } else if (n <= cfg_.max_leaf_size) {
      return false;
    }
    if (median) {
      // Object median along the largest centroid extent (or by index if all centroids agree).
      mid = begin + n / 2;
      if (reduce_max(cext) > 0.0f) {
        int a = max_dim(cext);
        Ref* refs = refs_.data();
        std::nth_element(refs + begin, refs + mid, refs + end, centroid_less(a));
      }
      left = range_of(begin, mid);
      right = range_of(mid, end);
    }
    return true;
  }

  // Nodes of at most full_blocks_below primitives (the clusters: leaves of up to B = block_prims
  // primitives, a block being a whole cluster): a node of n = q B + s primitives (0 < s <= B)
  // needs ceil(n / B) = q + 1 blocks, and its children need no more if and only if the left count
  // l = a B + b (0 < b <= B) has b >= s. The binned split rarely lands on such a count (a node of
  // up to 2B primitives has 4 + n / 20 bins), and each extra block is a cluster of its own, half
  // empty on average. So a split that needs one more block moves to the nearest count that does
  // not (the refs partitioned there by their centroids on the split axis) when the SAH, blocks
  // counted, says the move costs no more. Where every split moves, a node of n primitives holds
  // ceil(n / B) clusters; above full_blocks_below the splits stay the SAH's.
  void full_blocks(const Binner& bins, const Split& split, uint32_t begin, uint32_t end,
                   uint32_t& mid, Range& left, Range& right) {
    const uint32_t B = cfg_.block_prims, n = end - begin, l = mid - begin;
    const uint32_t s = (n - 1) % B + 1, b = (l - 1) % B + 1;
    if (b >= s) return;
    const uint32_t down = l - b, up = l + (s - b);  // multiples of B / b = s
    const uint32_t nl = down == 0 || (up < n && up - l <= l - down) ? up : down;
    if (nl == 0 || nl >= n) return;
    auto cost = [&](const Range& x, const Range& y, uint32_t nx) {
      return x.box.half_area() * blocks(nx) + y.box.half_area() * blocks(n - nx);
    };
    const float before = cost(left, right, l);
    const int axis = split.axis;
    Ref* refs = refs_.data();
    std::nth_element(refs + begin, refs + begin + nl, refs + end, centroid_less(axis));
    Range l2 = range_of(begin, begin + nl), r2 = range_of(begin + nl, end);
    if (cost(l2, r2, nl) <= before) {
      mid = begin + nl;
      left = l2;
      right = r2;
    } else {
      mid = partition(bins, split, begin, end, left, right);  // the SAH's split back
    }
  }

  // Whether refs [begin, end) may hold duplicates to drop: more than a leaf takes, all with one
  // centroid (no split can separate them), not yet checked above (`checked`).
  bool drops_duplicates(uint32_t begin, uint32_t end, const Range& range, bool checked) const {
    if (checked || !(cfg_.thin_stack || (cfg_.duplicate_key && cfg_.same_primitive))) return false;
    if (end - begin <= cfg_.max_leaf_size) return false;
    const Box3f cbox = range.cb.box3();
    return !(reduce_max(cbox.hi - cbox.lo) > 0.0f);
  }

  // Drops exact duplicates among refs [begin, end). With duplicate_key: sorted by
  // (duplicate_key, id), the first of each group of equal primitives (the lowest id) stays; with
  // thin_stack, that hook chooses. The others move behind the kept ones and their ids go to
  // Bvh2::dropped. Returns the new end. The range's boxes are unchanged (a duplicate has the box
  // of the primitive kept; a thinned primitive lies inside its old box).
  uint32_t drop_duplicates(uint32_t begin, uint32_t end) {
    Ref* refs = refs_.data();
    const uint32_t n = end - begin;
    std::vector<uint8_t> keep(n, 1);
    if (cfg_.thin_stack) {
      std::vector<uint32_t> ids(n);
      for (uint32_t i = 0; i < n; ++i) ids[i] = refs[begin + i].id();
      cfg_.thin_stack(ids.data(), n, keep.data());
    } else {
      std::vector<std::pair<uint64_t, uint32_t>> order(n);  // (key, position in the range)
      for (uint32_t i = 0; i < n; ++i) order[i] = {cfg_.duplicate_key(refs[begin + i].id()), i};
      std::sort(order.begin(), order.end(), [&](const auto& x, const auto& y) {
        return x.first != y.first ? x.first < y.first
                                  : refs[begin + x.second].id() < refs[begin + y.second].id();
      });
      std::vector<uint32_t> kept;  // ids kept with the current key
      for (uint32_t i = 0; i < n;) {
        uint32_t j = i;
        kept.clear();
        for (; j < n && order[j].first == order[i].first; ++j) {
          const uint32_t id = refs[begin + order[j].second].id();
          bool dup = false;
          for (size_t k = 0; k < kept.size() && !dup; ++k) dup = cfg_.same_primitive(kept[k], id);
          if (dup)
            keep[order[j].second] = 0;
          else
            kept.push_back(id);
        }
        i = j;
      }
    }
    // Kept refs first (in their order in the range), dropped ones behind them.
    std::vector<Ref> kept, dropped;
    kept.reserve(n);
    for (uint32_t i = 0; i < n; ++i) (keep[i] ? kept : dropped).push_back(refs[begin + i]);
    std::copy(kept.begin(), kept.end(), refs + begin);
    std::copy(dropped.begin(), dropped.end(), refs + begin + kept.size());
    if (!dropped.empty()) {
      std::lock_guard<std::mutex> lock(dropped_mutex_);
      for (const Ref& r : dropped) out_.dropped.push_back(r.id());
    }
    return begin + uint32_t(kept.size());
  }

  // Large nodes: children as parallel tasks, node pairs from the shared counter.
  void build(uint32_t node, uint32_t begin, uint32_t end, const Range& range, int depth,
             bool checked = false) {
    if (drops_duplicates(begin, end, range, checked)) {
      const uint32_t kept_end = drop_duplicates(begin, end);
      if (cfg_.progress) cfg_.progress->add(end - kept_end);
      end = kept_end;
      checked = true;
    }
    if (end - begin < kParallelTaskThreshold)
      return build_subtree(node, begin, end, range, depth, checked);
    uint32_t mid;
    Range left, right;
    Bvh2Node& nd = out_.nodes[node];
    nd.box = range.box.box3();
    if (!split(begin, end, range, depth, mid, left, right)) {
      nd.first = begin;
      nd.count = end - begin;
      if (cfg_.progress) cfg_.progress->add(end - begin);
      return note_depth(depth);
    }
    const uint32_t first = node_count_.fetch_add(2);
    nd.first = first;
    nd.count = 0;
    tbb::parallel_invoke([&] { build(first, begin, mid, left, depth + 1, checked); },
                         [&] { build(first + 1, mid, end, right, depth + 1, checked); });
  }

  // A subtree for one thread: built into a local array (depth first), then placed with one
  // fetch_add of the node counter instead of one per node. With a fetch_add per node the
  // counter's cache line moved between the threads all the time (perf, nefertiti, 2 threads:
  // ~9% of build()'s samples after the lock xadd). Children still follow their parent.
  void build_subtree(uint32_t node, uint32_t begin, uint32_t end, const Range& range, int depth,
                     bool checked) {
    std::vector<Bvh2Node> local;
    local.reserve(2 * size_t(end - begin) - 1);
    local.emplace_back();
    int max_depth = depth;
    build_local(local, 0, begin, end, range, depth, max_depth, checked);
    const uint32_t extra = uint32_t(local.size() - 1);
    const uint32_t base = extra ? node_count_.fetch_add(extra) : 0;  // local k >= 1 -> base + k - 1
    for (size_t k = 0; k < local.size(); ++k) {
      Bvh2Node x = local[k];
      if (!x.is_leaf()) x.first += base - 1;
      out_.nodes[k == 0 ? node : base + k - 1] = x;
    }
    note_depth(max_depth);
    if (cfg_.progress) cfg_.progress->add(end - begin);
  }

  // Progress: build_subtree counts the whole range, dropped duplicates included.
  void build_local(std::vector<Bvh2Node>& local, uint32_t li, uint32_t begin, uint32_t end,
                   const Range& range, int depth, int& max_depth, bool checked) {
    if (drops_duplicates(begin, end, range, checked)) {
      end = drop_duplicates(begin, end);
      checked = true;
    }
    uint32_t mid;
    Range left, right;
    const Box3f box = range.box.box3();
    if (!split(begin, end, range, depth, mid, left, right)) {
      local[li] = {box, begin, end - begin};
      max_depth = std::max(max_depth, depth);
      return;
    }
    const uint32_t first = uint32_t(local.size());
    local.emplace_back();  // within the reserved 2n - 1: no reallocation
    local.emplace_back();
    local[li] = {box, first, 0};
    build_local(local, first, begin, mid, left, depth + 1, max_depth, checked);
    build_local(local, first + 1, mid, end, right, depth + 1, max_depth, checked);
  }

  uint32_t count_;
  const PrimRefFill& fill_;
  const Bvh2BuildConfig& cfg_;
  Bvh2& out_;
  int nb_;
  float inv_block_;
  LargeArray<Ref> refs_;
  // Each on its own cache line: the tasks read the fields above all the time, and a node
  // allocation (fetch_add) by one thread would evict them from the other's cache (perf on
  // nefertiti, 2 threads: the load after the lock xadd held 13% of build()'s samples).
  std::mutex dropped_mutex_;  // Bvh2::dropped
  alignas(64) std::atomic<uint32_t> node_count_{0};
  alignas(64) std::atomic<int> max_depth_{0};  // the class size rounds up to its line
};

}  // namespace

Bvh2 build_bvh2(uint32_t count, const PrimRefFill& fill, const Bvh2BuildConfig& cfg) {
  Bvh2 out;
  Builder b(count, fill, cfg, out);
  if (cfg.threads > 0) {
    tbb::task_arena arena(cfg.threads);
    arena.execute([&] { b.run(); });
  } else {
    b.run();
  }
  return out;
}

Bvh2 build_bvh2(const std::vector<PrimRef>& refs, const Bvh2BuildConfig& cfg) {
  if (refs.size() >= (size_t(1) << 31))
    throw std::length_error("BVH build: at most 2^31 - 1 primitives");
  return build_bvh2(
      uint32_t(refs.size()),
      [&](uint32_t begin, uint32_t end, PrimRef* out) {
        std::copy(refs.begin() + begin, refs.begin() + end, out);
      },
      cfg);
}

}  // namespace slim
