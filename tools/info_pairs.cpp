// `slimrt info --pairs SCENE`: triangle pairing statistics (A. Aman, S. Fenney, "Fast Triangle
// Pairing for Ray Tracing"): share of triangles paired
// by the edge-box heuristic against the in-order window-2 baseline, and the pairing time. With
// --json the figures are top-level keys of the output object (`triangles`, `paired_fraction`,
// `window2_paired_fraction`, `pairing_s`, ...) plus a "pairing" object with the details.
//
// pairing_s is the process's first call (unless --accel built a configuration that pairs): its
// scratch memory is fresh pages, whose first touch can cost more than the pairing itself on a VM
// (measured here: 1.8-3.0 ms per MB of 2 MB pages the host has not backed yet, against 0.2 ms per
// MB for pages the process freed a moment before). With --repeat K, pairing_later_s is the median
// pairing time of K - 1 further calls, which run in memory the calls before have just freed (pages
// the kernel recycles, no longer new to the host): the algorithm's throughput, page zeroing by the
// kernel included.
#include <algorithm>
#include <cstdio>
#include <vector>

#include "commands.h"
#include "slimrt/pairing.h"

namespace slim::cli {

namespace {

nlohmann::json stats_json(const PairingStats& s) {
  return {{"triangles", s.triangles},
          {"pairs", s.pairs},
          {"unpaired", s.unpaired},
          {"paired_fraction", s.paired_fraction},
          {"window2_paired_fraction", s.window2_paired_fraction},
          {"heuristic_paired_fraction", s.heuristic_paired_fraction},
          {"prescan_skipped", s.prescan_skipped},
          {"pairing_s", s.pairing_s},
          {"weld_s", s.weld_s},
          {"prescan_s", s.prescan_s},
          {"table_s", s.table_s},
          {"sort_s", s.sort_s},
          {"scan_s", s.scan_s},
          {"half_edges", s.half_edges},
          {"nonmanifold_edges", s.nonmanifold_edges},
          {"welded_vertices", s.welded_vertices},
          {"mtris_per_s", s.pairing_s > 0 ? double(s.triangles) / s.pairing_s * 1e-6 : 0.0}};
}

}  // namespace

void info_pairs(const PolyMesh& mesh, bool json, int repeat, nlohmann::json& out) {
  // What Scene::build does for bvh8-pairs / clbvh-pairs, then the two alternatives of the paper
  // for meshes that are not welded.
  PairingStats s = pairing_stats(mesh);
  std::vector<double> later;
  for (int i = 1; i < repeat; ++i) later.push_back(pairing_stats(mesh).pairing_s);
  std::sort(later.begin(), later.end());
  const double later_s = later.empty() ? 0.0 : later[later.size() / 2];
  PairingOptions weld;
  weld.weld = true;
  PairingStats w = pairing_stats(mesh, weld);
  PairingOptions coord;
  coord.coordinate_keys = true;
  PairingStats c = pairing_stats(mesh, coord);

  if (json) {
    // Top-level keys other programs read; the triangle count is the one paired over (the info
    // command's own `triangles` counts skipped NaN faces too: they agree on valid meshes).
    out["triangles"] = s.triangles;
    out["paired_fraction"] = s.paired_fraction;
    out["window2_paired_fraction"] = s.window2_paired_fraction;
    out["pairing_s"] = s.pairing_s;
    if (!later.empty()) {
      out["pairing_later_s"] = later_s;
      out["pairing_later_runs"] = later.size();
    }
    out["pairs"] = s.pairs;
    out["unpaired_triangles"] = s.unpaired;
    out["prescan_skipped"] = s.prescan_skipped;
    nlohmann::json p = stats_json(s);
    p["weld"] = stats_json(w);
    p["coordinate_keys"] = stats_json(c);
    out["pairing"] = p;
    return;
  }
  auto pct = [](double f) { return 100.0 * f; };
  std::printf("\ntriangle pairing (fast-triangle-pairing), one thread\n");
  std::printf("  triangles              %llu\n", (unsigned long long)s.triangles);
  std::printf("  window-2 (in order)    %.2f %% paired\n", pct(s.window2_paired_fraction));
  std::printf("  edge-box heuristic     %.2f %% paired\n", pct(s.heuristic_paired_fraction));
  std::printf("  used by bvh8-pairs     %.2f %% paired (%llu pairs, %llu unpaired)%s\n",
              pct(s.paired_fraction), (unsigned long long)s.pairs, (unsigned long long)s.unpaired,
              s.prescan_skipped ? ", input order kept by the pre-scan" : "");
  std::printf(
      "  pairing time           %.4f s = %.1f M triangles/s (pre-scan %.4f, table %.4f, "
      "sort %.4f, scan %.4f)\n",
      s.pairing_s, s.pairing_s > 0 ? s.triangles / s.pairing_s * 1e-6 : 0.0, s.prescan_s, s.table_s,
      s.sort_s, s.scan_s);
  if (!later.empty())
    std::printf(
        "  later calls            %.4f s = %.1f M triangles/s (median of %zu, min %.4f s)\n",
        later_s, later_s > 0 ? s.triangles / later_s * 1e-6 : 0.0, later.size(), later.front());
  std::printf("  half-edges sorted      %llu (%llu edges of 3+ triangles)\n",
              (unsigned long long)s.half_edges, (unsigned long long)s.nonmanifold_edges);
  std::printf("  with weld              %.2f %% paired (%llu vertices merged, %.4f s)\n",
              pct(w.paired_fraction), (unsigned long long)w.welded_vertices, w.pairing_s);
  std::printf("  coordinate keys        %.2f %% paired (%.4f s)\n", pct(c.paired_fraction),
              c.pairing_s);
}

}  // namespace slim::cli
