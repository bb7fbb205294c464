// Cluster encoder and checker (prim/cluster.h).
#include "prim/cluster.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <iterator>
#include <stdexcept>

namespace slim::cluster {

namespace {

// Writes LSB-first fields of up to 32 bits; `out` holds 8 bytes beyond the last field's byte.
struct BitWriter {
  std::vector<uint8_t>& out;
  size_t base;
  uint64_t pos = 0;
  void put(uint32_t v, uint32_t w) {
    if (w == 0) return;
    uint64_t x;
    uint8_t* p = out.data() + base + (pos >> 3);
    std::memcpy(&x, p, 8);
    x |= (uint64_t(v) & ((uint64_t(1) << w) - 1)) << (pos & 7);
    std::memcpy(p, &x, 8);
    pos += w;
  }
};

}  // namespace

std::vector<uint8_t> encode(const ClusterSource& s, const uint32_t* const* prims,
                            const uint32_t* counts, int k, bool slack) {
  if (k < 1 || k > 8) throw std::logic_error("cluster: 1..8 children");
  std::vector<uint32_t> tris;  // triangles in child order
  ClusterHeader h{};
  for (int c = 0; c < k; ++c) {
    if (counts[c] < 1 || counts[c] > 8) throw std::logic_error("cluster: 1..8 triangles a child");
    for (uint32_t j = 0; j < counts[c]; ++j) tris.push_back(prims[c][j]);
    h.end[c] = uint8_t(tris.size());
  }
  for (int c = k; c < 8; ++c) h.end[c] = h.end[k - 1];
  h.ntris = uint8_t(tris.size());
  // Distinct vertex codes in order of first use (duplicated input vertices with the same code are
  // stored once), found through a small open-addressing table.
  std::vector<uint32_t> codes;  // 3 per local vertex
  std::vector<uint8_t> local(tris.size() * 3);
  uint16_t table[1024];
  std::fill(std::begin(table), std::end(table), uint16_t(0xffff));
  for (size_t t = 0; t < tris.size(); ++t)
    for (int j = 0; j < 3; ++j) {
      const uint32_t* c = &s.codes[3 * size_t(s.tris[3 * size_t(tris[t]) + j])];
      uint32_t h = (c[0] * 0x9E3779B1u) ^ (c[1] * 0x85EBCA77u) ^ (c[2] * 0xC2B2AE3Du);
      h = (h ^ (h >> 15)) & 1023;
      for (;; h = (h + 1) & 1023) {
        const uint16_t i = table[h];
        if (i == 0xffff) {
          table[h] = uint16_t(codes.size() / 3);
          local[3 * t + j] = uint8_t(codes.size() / 3);
          codes.insert(codes.end(), c, c + 3);
          break;
        }
        if (codes[3 * i] == c[0] && codes[3 * i + 1] == c[1] && codes[3 * i + 2] == c[2]) {
          local[3 * t + j] = uint8_t(i);
          break;
        }
      }
    }
  const uint32_t nv = uint32_t(codes.size() / 3);
  if (nv > 255) throw std::logic_error("cluster: more than 255 vertices");
  h.nverts = uint8_t(nv);
  // Per child: the smallest vertex index it uses is its base; ib covers the widest child range.
  uint32_t vbase[8] = {};
  for (int c = 0, first = 0; c < k; first = h.end[c], ++c) {
    uint32_t lo = 255, hi = 0;
    for (size_t i = 3 * size_t(first); i < 3 * size_t(h.end[c]); ++i) {
      lo = std::min<uint32_t>(lo, local[i]);
      hi = std::max<uint32_t>(hi, local[i]);
    }
    vbase[c] = lo;
    h.ib = uint8_t(std::max(uint32_t(h.ib), bit_width(hi - lo)));
  }
  for (int a = 0; a < 3; ++a) {
    uint32_t lo = codes[a], hi = codes[a];
    for (uint32_t i = 0; i < nv; ++i) {
      lo = std::min(lo, codes[3 * i + a]);
      hi = std::max(hi, codes[3 * i + a]);
    }
    h.anchor[a] = lo;
    h.bits[a] = uint8_t(bit_width(hi - lo));
  }
  uint32_t glo = ~0u, ghi = 0;
  std::vector<uint32_t> ids;
  for (uint32_t t : tris) {
    ids.push_back(s.prim_ids[t]);
    glo = std::min(glo, s.geom_ids[t]);
    ghi = std::max(ghi, s.geom_ids[t]);
  }
  std::sort(ids.begin(), ids.end());
  h.prim_base = ids[0];
  h.geom_base = glo;
  h.gb = uint8_t(bit_width(ghi - glo));
  // PrimID runs: a run starts at the first sorted id that is 2^ob or more past the current start;
  // ob is the width with the fewest bits (run starts + per triangle run index and offset). The
  // widest ob gives one run: the plain base + offset, for meshes whose ids are in random order.
  auto runs_of = [&](uint32_t ob, std::vector<uint32_t>& starts) {
    starts.clear();
    for (uint32_t id : ids)
      if (starts.empty() || uint64_t(id - starts.back()) >= (uint64_t(1) << ob))
        starts.push_back(id);
  };
  std::vector<uint32_t> starts;
  uint64_t best_bits = ~uint64_t(0);
  uint32_t best_ob = 0;
  for (uint32_t ob = 0; ob <= 32; ++ob) {
    runs_of(ob, starts);
    if (starts.size() > 255) continue;
    const uint64_t bits = starts.size() * uint64_t(bit_width(starts.back() - h.prim_base)) +
                          tris.size() * uint64_t(bit_width(uint32_t(starts.size()) - 1) + ob);
    if (bits < best_bits) {
      best_bits = bits;
      best_ob = ob;
    }
  }
  runs_of(best_ob, starts);
  h.nruns = uint8_t(starts.size());
  h.ob = uint8_t(best_ob);
  h.pb = uint8_t(bit_width(starts.back() - h.prim_base));

  const Layout L = layout(h);
  std::vector<uint8_t> out(data_bytes(h) + 8, 0);  // 8: the writer's 64-bit stores
  std::memcpy(out.data(), &h, sizeof(h));
  BitWriter w{out, sizeof(ClusterHeader)};
  for (int c = 0; c < k; ++c) w.put(vbase[c], L.vbw);
  for (int c = 0, first = 0; c < k; first = h.end[c], ++c)
    for (size_t i = 3 * size_t(first); i < 3 * size_t(h.end[c]); ++i)
      w.put(local[i] - vbase[c], h.ib);
  for (uint32_t i = 0; i < nv; ++i)
    for (int a = 0; a < 3; ++a) w.put(codes[3 * i + a] - h.anchor[a], h.bits[a]);
  for (uint32_t st : starts) w.put(st - h.prim_base, h.pb);
  for (uint32_t t : tris) {
    const uint32_t id = s.prim_ids[t];
    const uint32_t run =
        uint32_t(std::upper_bound(starts.begin(), starts.end(), id) - starts.begin()) - 1;
    w.put(run, L.rb);
    w.put(id - starts[run], h.ob);
    w.put(s.geom_ids[t] - glo, h.gb);
  }
  if (w.pos != L.end) throw std::logic_error("cluster: stream size mismatch");
  out.resize(data_bytes(h) + (slack ? kClusterReadSlack : 0));
  if (s.stats) {
    std::lock_guard<std::mutex> lock(s.stats->m);
    EncodeStats& st = *s.stats;
    st.clusters++;
    st.triangles += h.ntris;
    st.vertices += nv;
    st.position_bits += uint64_t(nv) * L.vbits;
    st.topology_bits += L.verts + 8 * sizeof(h.end);
    st.id_bits += L.end - L.runs + 64;
    st.header_bytes += sizeof(ClusterHeader);
  }
  return out;
}

bool check(const uint8_t* data, uint64_t size, uint32_t children, bool lossless, std::string* why) {
  auto fail = [&](const std::string& m) {
    if (why) *why = "cluster: " + m;
    return false;
  };
  if (size < sizeof(ClusterHeader))
    return fail("shorter than its " + std::to_string(sizeof(ClusterHeader)) + "-byte header");
  if (children < 1 || children > 8) return fail("children must be 1..8");
  ClusterHeader h;
  std::memcpy(&h, data, sizeof(h));
  if (h.nverts < 1) return fail("no vertex");
  if (h.ntris < 1 || h.ntris > 64) return fail("triangle count must be 1..64");
  const uint32_t max_bits = lossless ? 32 : 24;
  for (int a = 0; a < 3; ++a)
    if (h.bits[a] > max_bits)
      return fail("axis width beyond " + std::to_string(max_bits) + " bits");
  if (h.ib > 8 || h.pb > 32 || h.gb > 32 || h.ob > 32)
    return fail("index or id width beyond its limit");
  if (h.nruns < 1 || h.nruns > h.ntris) return fail("run count must be 1..ntris");
  uint32_t prev = 0;
  for (uint32_t c = 0; c < children; ++c) {
    if (h.end[c] <= prev || h.end[c] - prev > 8) return fail("child of 0 or more than 8 triangles");
    prev = h.end[c];
  }
  if (prev != h.ntris) return fail("children do not cover the triangles");
  if (child_count(h) != children) return fail("child ends disagree with the child count");
  if (data_bytes(h) > size) return fail("stream runs past the data");
  const uint8_t* bits = data + sizeof(ClusterHeader);
  const Layout L = layout(h);
  // Bytes beyond `size` are not read: every field read here lies inside data_bytes(h).
  auto get = [&](uint64_t pos, uint32_t w) {
    uint32_t v = 0;
    for (uint32_t b = 0; b < w; ++b)
      v |= uint32_t((bits[(pos + b) >> 3] >> ((pos + b) & 7)) & 1) << b;
    return v;
  };
  for (uint32_t c = 0, first = 0; c < children; first = h.end[c], ++c) {
    const uint32_t vbase = get(uint64_t(c) * L.vbw, L.vbw);
    for (uint32_t i = 3 * first; i < 3u * h.end[c]; ++i) {
      const uint64_t v = uint64_t(vbase) + get(L.topo + uint64_t(i) * h.ib, h.ib);
      if (v >= h.nverts) return fail("vertex index " + std::to_string(v) + " >= vertex count");
    }
  }
  for (uint32_t t = 0; t < h.ntris; ++t) {
    const uint32_t run = get(L.ids + uint64_t(t) * L.idbits, L.rb);
    if (run >= h.nruns) return fail("run index " + std::to_string(run) + " >= run count");
  }
  return true;
}

Quantized quantize(const Vec3f* vertices, size_t nv, const uint32_t* tris, size_t ntris,
                   double rel_error, bool lossless, const Box3f& lattice_box) {
  constexpr uint32_t kLatticeMax = (1u << 24) - 1;
  Quantized z;
  std::vector<uint8_t> used(nv, 0);
  for (size_t i = 0; i < 3 * ntris; ++i) used[tris[i]] = 1;
  const bool given = !lattice_box.empty();
  Box3f box = lattice_box;
  if (!given)
    for (size_t i = 0; i < nv; ++i)
      if (used[i]) box.extend(vertices[i]);
  double ext = 0, d2 = 0;
  if (ntris || given)
    for (int a = 0; a < 3; ++a) {
      const double e = double(box.hi[a]) - double(box.lo[a]);
      ext = std::max(ext, e);
      d2 += e * e;
    }
  z.diag = std::sqrt(d2);
  z.codes.assign(3 * nv, 0);
  z.decoded.assign(vertices, vertices + nv);
  if (!lossless) {
    if (!(rel_error > 0.0) || !std::isfinite(rel_error))
      throw Error(
          "cluster: the error bound (BuildOptions::cluster_error) must be positive and finite");
    // Rounding to the nearest lattice point moves a vertex by at most step * sqrt(3) / 2.
    const double bound = rel_error * z.diag;
    double step = bound > 0 ? std::exp2(std::floor(std::log2(bound * 2.0 / std::sqrt(3.0)))) : 1.0;
    while (ext / step > double(kLatticeMax) - 1) {
      step *= 2;
      z.coarsened = true;
    }
    z.lattice.step = float(step);
    for (int a = 0; a < 3; ++a) z.lattice.origin[a] = ntris || given ? box.lo[a] : 0.0f;
    for (size_t i = 0; i < nv; ++i) {
      if (!used[i]) continue;
      for (int a = 0; a < 3; ++a) {
        const double q =
            std::nearbyint((double(vertices[i][a]) - double(z.lattice.origin[a])) / step);
        const uint32_t qi = uint32_t(std::clamp(q, 0.0, double(kLatticeMax)));
        z.codes[3 * i + a] = qi;
        z.decoded[i][a] = lattice_coord(z.lattice, a, qi);
      }
    }
  } else {
    for (size_t i = 0; i < nv; ++i)
      if (used[i])
        for (int a = 0; a < 3; ++a) z.codes[3 * i + a] = float_key(vertices[i][a]);
  }
  double sum_sq = 0, sum = 0;
  uint64_t n = 0;
  for (size_t i = 0; i < nv; ++i) {
    if (!used[i]) continue;
    double e2 = 0;
    for (int a = 0; a < 3; ++a) {
      const double d = double(z.decoded[i][a]) - double(vertices[i][a]);
      e2 += d * d;
    }
    z.max_error = std::max(z.max_error, std::sqrt(e2));
    sum += std::sqrt(e2);
    sum_sq += e2;
    n++;
  }
  z.rms_error = n ? std::sqrt(sum_sq / double(n)) : 0.0;
  z.mean_error = n ? sum / double(n) : 0.0;
  return z;
}

}  // namespace slim::cluster
