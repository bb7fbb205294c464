// slimrt analysis: the measurement and paper-reproduction hooks that the CLI, the benchmark and
// the tests use beside the user API of slimrt/slimrt.h: how a mesh becomes grids and what the
// lossy grids lose (grids.h), the Costa store sizes (costa.h), the pairing figures (pairing.h),
// the benchmark camera, path tracer, RNG and PSNR (render.h), each format's own build figures, the
// decoded triangles of the formats that intersect their own geometry, and a traversal that counts
// its work.
#pragma once

#include <optional>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "slimrt/costa.h"
#include "slimrt/decoded.h"
#include "slimrt/grids.h"
#include "slimrt/pairing.h"
#include "slimrt/render.h"
#include "slimrt/slimrt.h"

namespace slim {

// The figures a scene's format measures at build beside Scene::stats(), as name/value pairs in the
// order its builder reports them: node counts per type, leaf fill, SAH cost, build phase times,
// the lossy formats' error figures, what a joined scene's chunks add up to, ... (the names differ
// between formats; `slimrt info SCENE --accel NAME` lists them). A scene file keeps them, so an
// opened scene gives the saved scene's. Empty for an empty scene.
using StatDetails = std::vector<std::pair<std::string, double>>;
const StatDetails& stat_details(const Scene& scene);
// The value of one of them, or std::nullopt where the scene's format does not report it.
std::optional<double> stat_detail(const Scene& scene, std::string_view name);

// Scene::intersect that also counts the traversal's work (node visits, box and primitive tests)
// into `counters`: slower, for statistics, not for timing. Thread-safe for distinct counters.
Hit intersect_counted(const Scene& scene, const Ray& ray, TraversalCounters& counters);

// The triangles the format of `opt` intersects when it has its own geometry
// (describe(opt).own_geometry: lossy grids, costa), decoded exactly as its leaves decode them:
// a rebuild by the same deterministic conversion as Scene::build (in the conversion's order, not
// the scene's leaf order); std::nullopt for the formats that intersect the input's fan triangles.
// Throws slim::Error on malformed meshes. With a built scene at hand, the next one is cheaper.
std::optional<DecodedTriangles> decoded_triangles(const std::vector<const PolyMesh*>& meshes,
                                                  const BuildOptions& opt);

// A built scene's decoded triangles (Scene::decoded_triangles), or where its scene does not decode
// its leaves (cluster), the rebuild above from `meshes`, which must be the scene's input.
std::optional<DecodedTriangles> decoded_triangles(const Scene& scene,
                                                  const std::vector<const PolyMesh*>& meshes);

// The decoded triangles as a triangle mesh (face i = decoded triangle i; t.face maps it back to
// the input face), for a reference that reads meshes (Embree, a brute force).
PolyMesh to_mesh(const DecodedTriangles& t, const std::string& name = "decoded");

}  // namespace slim
