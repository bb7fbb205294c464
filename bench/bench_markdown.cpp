// The Markdown writer of `slimrt bench`: see bench_markdown.h.
#include "bench_markdown.h"

#include <cstdio>
#include <sstream>

#include "embree_scene.h"

namespace slim::bench {

namespace {

std::string fmt(const char* f, double v) {
  char buf[64];
  std::snprintf(buf, sizeof buf, f, v);
  return buf;
}

std::string cell(const std::optional<double>& v, const char* f) {
  return v ? fmt(f, *v) : std::string("—");
}

std::optional<double> median_of(const std::optional<Spread>& s) {
  if (!s) return std::nullopt;
  return s->median;
}

std::string markdown_escape(std::string s) {
  std::string out;
  for (char c : s) {
    if (c == '|') out += '\\';
    out += c == '\n' ? ' ' : c;
  }
  return out;
}

}  // namespace

std::string ratio_cell(const std::optional<Spread>& s, const char* f) {
  if (!s) return "—";
  return fmt(f, s->median) + " (" + fmt(f, s->lo) + "-" + fmt(f, s->hi) + ")" +
         (s->noisy() ? " !" : "");
}

std::string report_markdown(const BenchReport& report) {
  std::ostringstream o;
  o << "slimrt bench: " << report.machine.cpu << ", " << report.machine.threads << " threads, isa "
    << report.machine.isa << "; camera " << report.width << "x" << report.height << "; "
    << report.repeat << " interleaved rounds; Embree kernels: " << EmbreeScene::kernel_isa()
    << ".\n"
    << "W1 = one primary ray per pixel, W2 = diffuse path tracing (up to " << report.max_bounces
    << " bounces, every ray counted). Each round times every configuration once (W1 then W2), in "
       "an order rotating by one configuration per round; each timing repeats its workload "
       "until "
    << report.min_seconds
    << " s have passed and counts the fastest pass. MRays/s = median over the rounds. "
       "ratio = median over the rounds of MRays/s over embree-tri's in the same round, (min-max) "
       "over the rounds; ! = the range is wider than +-10% of the median. box/prim = tests per ray "
       "(slimrt only, untimed counting pass): W1 over all workload-1 rays, W2s over the paths of "
       "every 16th pixel. agree = workload-1 hits agreeing with Embree on the same geometry "
       "(docs/benchmark.md): embree-tri, or for grid, lossy-grid* and costa-* embree-tri run on "
       "the format's own decoded triangles; vs tri = agreement with embree-tri on the input's fan "
       "triangles. build s = median over the rounds (each round builds every configuration once, "
       "in the round's order, before timing rays), (min-max) over the rounds. MB = geometry + "
       "BVH + side tables.\n\n";
  o << "| scene | config | build s | Mtri/s | MB | B/tri | W1 MRays/s | W2 MRays/s | W1 ratio | "
       "W2 ratio | box/ray W1 | prim/ray W1 | box/ray W2s | prim/ray W2s | agree % | vs tri % | "
       "PSNR dB | note |\n";
  o << "| --- | --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | "
       "---: | ---: | ---: | ---: | --- |\n";
  for (const BenchRow& r : report.rows) {
    o << "| " << markdown_escape(r.scene) << " | " << r.config << " | ";
    if (!r.measured()) {
      for (int i = 0; i < 15; ++i) o << "— | ";
      o << markdown_escape(r.reason) << " |\n";
      continue;
    }
    std::optional<double> mb;
    if (r.bytes_total) mb = double(*r.bytes_total) / 1e6;
    std::optional<double> agree;
    if (r.hit_agreement) agree = 100.0 * *r.hit_agreement;
    std::optional<double> vs_tri;
    if (r.agreement_embree_tri) vs_tri = 100.0 * *r.agreement_embree_tri;
    if (r.config == "embree-tri") vs_tri = agree;
    std::string note;
    if (r.hit_agreement && *r.hit_agreement < kLosslessAgreement) note = "ERROR: agreement < 99.9%";
    if (!r.kept) note += std::string(note.empty() ? "" : "; ") + "rebuilt in each round";
    std::string psnr_cell = r.error.psnr_identical ? "inf" : cell(r.error.psnr_db, "%.2f");
    o << ratio_cell(r.build_s, "%.3f") << " | " << cell(r.build_mprims_s, "%.2f") << " | "
      << cell(mb, "%.2f") << " | " << cell(r.bytes_per_triangle, "%.1f") << " | "
      << cell(median_of(r.mrays_primary), "%.2f") << " | "
      << cell(median_of(r.mrays_diffuse), "%.2f") << " | " << ratio_cell(r.ratio_primary, "%.2f")
      << " | " << ratio_cell(r.ratio_diffuse, "%.2f") << " | " << cell(r.box_tests_per_ray, "%.1f")
      << " | " << cell(r.prim_tests_per_ray, "%.1f") << " | "
      << cell(r.box_tests_per_ray_w2, "%.1f") << " | " << cell(r.prim_tests_per_ray_w2, "%.1f")
      << " | " << cell(agree, "%.3f") << " | " << cell(vs_tri, "%.3f") << " | " << psnr_cell
      << " | " << note << " |\n";
  }
  return o.str();
}

}  // namespace slim::bench
