#include "mesh/triangulate.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <string>

namespace slim {

FaceChunks face_chunks(const MeshView& m) {
  const size_t nf = m.face_sizes.size();
  const size_t nc = (nf + FaceChunks::kFaces - 1) / FaceChunks::kFaces;
  FaceChunks fc;
  fc.corner.assign(nc + 1, 0);
  tbb::parallel_for(size_t(0), nc, [&](size_t k) {
    const size_t f1 = std::min(nf, (k + 1) * FaceChunks::kFaces);
    uint64_t c = 0;
    for (size_t f = k * FaceChunks::kFaces; f < f1; ++f) c += m.face_sizes[f];
    fc.corner[k + 1] = c;
  });
  for (size_t k = 0; k < nc; ++k) fc.corner[k + 1] += fc.corner[k];
  return fc;
}

namespace {

// Per mesh: which vertices are finite, and per face chunk the first output triangle and the
// faces skipped (with a non-finite corner).
struct MeshPlan {
  LargeArray<uint8_t> finite;
  FaceChunks chunks;
  std::vector<uint64_t> first_tri;  // per chunk, then the total at the end
  std::vector<uint64_t> skipped;    // per chunk
};

}  // namespace

TriangleMesh triangulate_fan(const MeshList& meshes) {
  TriangleMesh out;
  uint64_t nv = 0, nt = 0;
  for (const MeshView* m : meshes) {
    nv += m->positions.size();
    nt += m->fan_triangle_count();
    out.input_faces += m->face_count();
  }
  if (nv >= 0xffffffffull || nt >= 0xffffffffull)
    throw Error("scene too large: " + std::to_string(nv) + " vertices, " + std::to_string(nt) +
                " triangles (at most 2^32-1 of each)");
  out.input_triangles = nt;

  // Pass 1: finite vertices, and the output triangles of each chunk of faces.
  std::vector<MeshPlan> plan(meshes.size());
  uint64_t tri_total = 0;
  for (size_t g = 0; g < meshes.size(); ++g) {
    const MeshView& m = *meshes[g];
    MeshPlan& p = plan[g];
    const size_t nvm = m.positions.size();
    p.finite = LargeArray<uint8_t>(nvm);
    tbb::parallel_for(tbb::blocked_range<size_t>(0, nvm, 16384),
                      [&](const tbb::blocked_range<size_t>& r) {
                        for (size_t i = r.begin(); i < r.end(); ++i)
                          p.finite[i] = is_finite(m.positions[i]);
                      });
    p.chunks = face_chunks(m);
    const size_t nc = p.chunks.count();
    p.first_tri.assign(nc + 1, 0);
    p.skipped.assign(nc, 0);
    for_each_face_chunk(m, p.chunks, [&](size_t k, size_t f0, size_t f1, const uint32_t* idx) {
      uint64_t tris = 0, skipped = 0;
      for (size_t f = f0; f < f1; idx += m.face_sizes[f], ++f) {
        const uint32_t n = m.face_sizes[f];
        if (face_finite(p.finite.data(), idx, n))
          tris += n >= 3 ? n - 2 : 0;  // check_mesh refuses faces of fewer than 3 corners
        else
          skipped++;
      }
      p.first_tri[k + 1] = tris;
      p.skipped[k] = skipped;
    });
    p.first_tri[0] = tri_total;
    for (size_t k = 0; k < nc; ++k) {
      p.first_tri[k + 1] += p.first_tri[k];
      out.skipped_faces += p.skipped[k];
    }
    tri_total = p.first_tri[nc];
  }

  // Pass 2: vertices and triangles written in parallel, at the positions a serial loop would
  // give them.
  out.vertices.resize(nv);
  out.tris.resize(3 * tri_total);
  out.geom_ids.resize(tri_total);
  out.prim_ids.resize(tri_total);
  uint64_t vbase = 0;
  for (uint32_t g = 0; g < meshes.size(); ++g) {
    const MeshView& m = *meshes[g];
    const MeshPlan& p = plan[g];
    const uint32_t base = uint32_t(vbase);
    out.vertex_base.push_back(base);
    tbb::parallel_for(tbb::blocked_range<size_t>(0, m.positions.size(), 16384),
                      [&](const tbb::blocked_range<size_t>& r) {
                        for (size_t i = r.begin(); i < r.end(); ++i)
                          out.vertices[base + i] = m.positions[i];
                      });
    vbase += m.positions.size();
    for_each_face_chunk(m, p.chunks, [&](size_t k, size_t f0, size_t f1, const uint32_t* idx) {
      uint64_t t = p.first_tri[k];
      for (size_t f = f0; f < f1; idx += m.face_sizes[f], ++f) {
        const uint32_t n = m.face_sizes[f];
        if (!face_finite(p.finite.data(), idx, n)) continue;
        for (uint32_t j = 1; j + 1 < n; ++j, ++t) {
          out.tris[3 * t] = base + idx[0];
          out.tris[3 * t + 1] = base + idx[j];
          out.tris[3 * t + 2] = base + idx[j + 1];
          out.geom_ids[t] = g;
          out.prim_ids[t] = uint32_t(f);
        }
      }
    });
  }
  return out;
}

}  // namespace slim
