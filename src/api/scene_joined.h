// A scene joined from chunk scenes (Scene::build_chunked; README.md "Inputs larger than memory"):
// every chunk of the input is a scene of the configuration's own format, and a small top-level BVH2
// over the chunks' boxes joins them.
#pragma once

#include <cstdint>
#include <memory>

#include "api/scene_impl.h"

namespace slim {

namespace detail {
class ChunkSource;  // mesh/chunks.h
}

// Builds every chunk of `src` with `opt` (its lattice_box set to src.bounds(), one chunk at a time,
// each freed before the next is loaded) and joins them. Reports the phase "chunks" to opt.progress.
std::unique_ptr<Scene::Impl> build_joined_scene(const detail::ChunkSource& src,
                                                const BuildOptions& opt);
// An empty joined scene of `chunks` chunks for Scene::open to fill (api/scene_file.cpp).
std::unique_ptr<Scene::Impl> empty_joined_scene(const BuildOptions& opt, uint32_t chunks);

}  // namespace slim
