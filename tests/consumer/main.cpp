// Builds a two-triangle scene with the installed slimrt and casts one ray at the second
// triangle; prints what it hit (checked by cmake/consumer_test.cmake).
#include <cstdio>

#include "slimrt/slimrt.h"

int main() {
  slim::PolyMesh mesh;
  mesh.positions = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {10, 0, 0}, {11, 0, 0}, {10, 1, 0}};
  mesh.face_sizes = {3, 3};
  mesh.face_indices = {0, 1, 2, 3, 4, 5};
  slim::Scene scene = slim::Scene::build(mesh, slim::BuildOptions::from_config("clbvh-compact"));
  slim::Ray ray;
  ray.org = {10.25f, 0.25f, 2.0f};
  ray.dir = {0.0f, 0.0f, -1.0f};
  slim::Hit hit = scene.intersect(ray);
  if (!hit.valid()) {
    std::printf("miss\n");
    return 1;
  }
  std::printf("hit triangle %u at t = %g (%s, %.1f bytes/triangle)\n", hit.primID, hit.t,
              scene.options().config_name().c_str(), scene.memory().bytes_per_triangle());
  return 0;
}
