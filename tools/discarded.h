// What the build left out of the input, for the CLI's summary lines, so that a user sees that
// input was discarded: faces with a NaN/Inf corner (SceneStats::skipped_faces) and exact
// duplicate triangles dropped from stacks of coincident ones (stat_detail "duplicate_triangles").
#pragma once

#include <cstdint>
#include <string>

#include "slimrt/analysis.h"

namespace slim::cli {

// "" when nothing was left out, else " | left out: N faces with a NaN/Inf vertex, M duplicate
// triangles".
inline std::string discarded_note(const Scene& scene) {
  const SceneStats& st = scene.stats();
  const uint64_t duplicates = uint64_t(stat_detail(scene, "duplicate_triangles").value_or(0));
  std::string parts;
  if (st.skipped_faces) parts += std::to_string(st.skipped_faces) + " faces with a NaN/Inf vertex";
  if (duplicates)
    parts += (parts.empty() ? "" : ", ") + std::to_string(duplicates) +
             " duplicate triangles (coincident with one kept)";
  return parts.empty() ? "" : " | left out: " + parts;
}

}  // namespace slim::cli
