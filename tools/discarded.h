// What the build left out of the input, for the CLI's summary lines, so that a user sees that
// input was discarded: faces with a NaN/Inf corner (SceneStats::skipped_faces) and exact
// duplicate triangles dropped from stacks of coincident ones (detail "duplicate_triangles").
#pragma once

#include <cstdint>
#include <string>

#include "slimrt/scene.h"

namespace slim::cli {

// "" when nothing was left out, else " | left out: N faces with a NaN/Inf vertex, M duplicate
// triangles".
inline std::string discarded_note(const SceneStats& st) {
  uint64_t duplicates = 0;
  for (const auto& [k, v] : st.details)
    if (k == "duplicate_triangles") duplicates = uint64_t(v);
  std::string parts;
  if (st.skipped_faces) parts += std::to_string(st.skipped_faces) + " faces with a NaN/Inf vertex";
  if (duplicates)
    parts += (parts.empty() ? "" : ", ") + std::to_string(duplicates) +
             " duplicate triangles (coincident with one kept)";
  return parts.empty() ? "" : " | left out: " + parts;
}

}  // namespace slim::cli
