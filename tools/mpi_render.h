// `mpirun -np K slimrt render SCENE ...`: one image rendered by K processes (Open MPI; the CLI
// links it when CMake finds it, SLIM_MPI; the library never does).
//
// Every rank loads and builds (or, for a scene file, maps) the same scene itself. Rank 0 hands
// out square tiles of the image on request (a work queue: a rank that finishes a tile sends its
// pixels and gets the next tile number back; each rank keeps two tiles requested so that it does
// not wait for the reply), renders tiles itself on a second thread while its main thread answers,
// gathers the pixels and writes the image. Tiles are shaded by slim::render_region, which gives
// every pixel the bits slim::render gives it, so the image equals the one-process render.
//
// Without mpirun nothing of this runs: one process, slim::render, as always.
#pragma once

#include <cstdint>
#include <exception>
#include <string>
#include <vector>

#include "slimrt/render.h"
#include "slimrt/scene.h"

namespace slim::cli {

class RenderRanks {
 public:
  // Joins the MPI job when mpirun started this process (Open MPI's OMPI_COMM_WORLD_SIZE, or
  // PMIX_RANK, in the environment) and the CLI was built with MPI. A CLI built without MPI under
  // mpirun -np K: rank 0 (from OMPI_COMM_WORLD_RANK) says so on stderr and renders alone, the
  // other ranks are idle() and exit at once.
  RenderRanks();
  ~RenderRanks();  // MPI_Finalize when MPI was initialized
  RenderRanks(const RenderRanks&) = delete;
  RenderRanks& operator=(const RenderRanks&) = delete;

  int rank() const { return rank_; }
  int size() const { return size_; }
  bool is_root() const { return rank_ == 0; }
  // More than one MPI process: render() splits the image.
  bool distributed() const { return mpi_ && size_ > 1; }
  // A process of mpirun -np K whose CLI has no MPI, other than rank 0: nothing to do.
  bool idle() const { return !mpi_ && rank_ != 0; }

  // Runs fn() and returns its result. When distributed(), an exception on this rank is printed
  // ("slimrt: error (rank r of K): ...") and ends the whole job with MPI_Abort, so that no other
  // rank waits forever for this one; otherwise it propagates to main().
  template <class Fn>
  int guard(Fn&& fn) {
    if (!distributed()) return fn();
    try {
      return fn();
    } catch (const std::bad_alloc&) {
      abort_job("out of memory (std::bad_alloc)");
    } catch (const std::exception& e) {
      abort_job(e.what());
    }
  }

  // Throws slim::Error on rank 0 when a rank's scene differs from rank 0's (faces, triangles,
  // primitives, bytes, bounds, configuration): each rank reads the scene itself, on other
  // machines from its own copy of the file. A collective call: every rank makes it.
  void check_same_scene(const Scene& scene, const std::string& scene_name) const;

  // slim::render across the ranks, tiles of tile_size x tile_size pixels (the last row and column
  // of tiles may be smaller). root_renders: rank 0 renders tiles too, else it only hands them out
  // and gathers them. Rank 0 returns the whole image, in stats the rays of all ranks and in
  // tiles_per_rank the number of tiles each rank rendered; the others return an empty image.
  // progress: rank 0 shows the share of tiles done on stderr after ~2 s. A collective call.
  Image render(const Scene& scene, const Camera& cam, const RenderOptions& opt, int tile_size,
               bool root_renders, bool progress, RenderStats* stats,
               std::vector<int>* tiles_per_rank) const;

 private:
  [[noreturn]] void abort_job(const char* what) const;

  int rank_ = 0, size_ = 1;
  bool mpi_ = false;
};

}  // namespace slim::cli
