// slimrt info --costa: sizes of the Costa quantized n-gon mesh (V. Costa, J. M. Pereira,
// J. A. Jorge, "Fast Compression of Meshes for GPU Ray-Tracing", WSCG 2013, Tables 1 and 3):
// regular and triangulated sizes, gzip -9, and every combination of T, P, F, V.
#include <cstdio>
#include <string>

#include "commands.h"
#include "slimrt/costa.h"

namespace slim::cli {

namespace {

std::string human(uint64_t b) {
  char buf[32];
  if (b >= (uint64_t(1) << 20))
    std::snprintf(buf, sizeof buf, "%.2f MB", double(b) / double(1 << 20));
  else
    std::snprintf(buf, sizeof buf, "%.2f KB", double(b) / 1024.0);
  return buf;
}

}  // namespace

void info_costa(const PolyMesh& mesh, bool json, nlohmann::json& out) {
  CostaSizes s = costa_sizes(mesh);
  if (json) {
    out["regular_bytes"] = s.regular_bytes;
    out["triangulated_bytes"] = s.triangulated_bytes;
    out["gzip_bytes"] = s.gzip_bytes;
    out["gzip_triangulated_bytes"] = s.gzip_triangulated_bytes;
    nlohmann::json combos = nlohmann::json::object();
    for (const auto& [k, v] : s.combos) combos[k] = v;
    out["combos"] = combos;
    nlohmann::json in_order = nlohmann::json::object();
    for (const auto& [k, v] : s.input_order_combos) in_order[k] = v;
    out["input_order_combos"] = in_order;
    out["costa"] = {{"vertices", s.vertices},
                    {"input_faces", s.input_faces},
                    {"skipped_faces", s.skipped_faces},
                    {"primitives", s.primitives},
                    {"triangles", s.triangles},
                    {"quads", s.quads},
                    {"fans", s.fans},
                    {"strips", s.strips},
                    {"triangulated_primitives", s.triangulated_primitives},
                    {"prim_residual_bits", s.prim_residual_bits},
                    {"prim_residual_bits_triangulated", s.prim_residual_bits_triangulated},
                    {"face_bits", s.face_bits},
                    {"face_bits_triangulated", s.face_bits_triangulated},
                    {"tess_polygons", s.tess_polygons},
                    {"tess_glu", s.tess_glu},
                    {"tess_fallbacks", s.tess_fallbacks}};
    return;
  }
  std::printf("\ncosta quantized n-gon mesh (Costa et al., Tables 1 and 3)\n");
  std::printf("  primitives       %llu: %llu triangles, %llu quads, %llu fans, %llu strips\n",
              (unsigned long long)s.primitives, (unsigned long long)s.triangles,
              (unsigned long long)s.quads, (unsigned long long)s.fans,
              (unsigned long long)s.strips);
  std::printf("  triangulated     %llu triangles\n", (unsigned long long)s.triangulated_primitives);
  std::printf(
      "  5+ gons          %llu tessellated: %llu by GLU, %llu fanned (self-intersecting or "
      "degenerate projection)\n",
      (unsigned long long)s.tess_polygons, (unsigned long long)s.tess_glu,
      (unsigned long long)s.tess_fallbacks);
  std::printf("  packing widths   P residuals %u bits (T: %u), F faces %u bits (T: %u)\n",
              s.prim_residual_bits, s.prim_residual_bits_triangulated, s.face_bits,
              s.face_bits_triangulated);
  std::printf("  REGULAR          %s (%llu B)\n", human(s.regular_bytes).c_str(),
              (unsigned long long)s.regular_bytes);
  std::printf("  TRIANGULATED     %s (%llu B)\n", human(s.triangulated_bytes).c_str(),
              (unsigned long long)s.triangulated_bytes);
  std::printf("  %-6s %10s %14s %8s %10s %14s %8s\n", "", "GZIP", "OURS", "RATIO", "vs GZIP",
              "INPUT ORDER", "RATIO");
  for (const std::string& c : costa_combinations()) {
    const bool t = !c.empty() && c[0] == 'T';
    const uint64_t base = t ? s.triangulated_bytes : s.regular_bytes;
    const uint64_t gz = t ? s.gzip_triangulated_bytes : s.gzip_bytes;
    const uint64_t b = s.combos.at(c), bi = s.input_order_combos.at(c);
    const bool first = c.empty() || c == "T";
    auto pct = [&](uint64_t x) { return base ? 100.0 * double(x) / double(base) : 0.0; };
    std::printf("  %-6s %10s %14s %7.2f%% %9.2fx %14s %7.2f%%\n", c.empty() ? "-" : c.c_str(),
                first ? human(gz).c_str() : "...", human(b).c_str(), pct(b),
                gz ? double(b) / double(gz) : 0.0, human(bi).c_str(), pct(bi));
  }
  std::printf(
      "  (RATIO: of REGULAR, or of TRIANGULATED for the T rows, as in the paper. OURS: the store\n"
      "   as a scene keeps it -- leaf order balanced for P, vertices renumbered for F; INPUT\n"
      "   ORDER: primitives and vertices as loaded, the paper's layout)\n");
}

}  // namespace slim::cli
