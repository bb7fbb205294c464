// `slimrt render` under mpirun: see mpi_render.h. The MPI part compiles only with SLIM_HAVE_MPI
// (CMake SLIM_MPI); without it a RenderRanks is one process.
#include "mpi_render.h"

#include <tbb/task_arena.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <climits>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <deque>
#include <string>
#include <thread>
#include <vector>

#include "slimrt/error.h"

#if SLIM_HAVE_MPI
// The C API only: Open MPI's (deprecated) C++ bindings would need libmpi_cxx.
#define OMPI_SKIP_MPICXX 1
#define MPICH_SKIP_MPICXX 1
#include <mpi.h>
#endif

namespace slim::cli {

namespace {

// A non-negative integer from the environment, or -1 when unset or not a number.
int env_int(const char* name) {
  const char* v = std::getenv(name);
  if (!v || !*v) return -1;
  char* end = nullptr;
  long n = std::strtol(v, &end, 10);
  return *end == '\0' && n >= 0 && n <= (1 << 30) ? int(n) : -1;
}

}  // namespace

#if SLIM_HAVE_MPI

namespace {

constexpr int kTagResult = 1;  // rank > 0 -> 0: a finished tile (or none), asking for the next
constexpr int kTagAssign = 2;  // 0 -> rank > 0: the next tile number, -1 when none is left
constexpr int kPrefetch = 2;   // tiles each rank keeps requested

// A result message: this header, then the tile's pixels (3 floats each, row-major). Messages are
// held in float buffers, the header in the first kHeaderFloats, so that a tile is rendered into
// the message it is sent in and stored into the image from the message it arrives in.
struct ResultHeader {
  int32_t tile;  // -1: no tile (the first requests)
  int32_t reserved;
  uint64_t rays;
};
static_assert(sizeof(ResultHeader) == 16);
constexpr size_t kHeaderFloats = sizeof(ResultHeader) / sizeof(float);
static_assert(kHeaderFloats * sizeof(float) == sizeof(ResultHeader));

// The tiles of a width x height image, tile x tile pixels each, numbered row-major.
struct TileGrid {
  int width, height, tile, tiles_x, tiles_y;
  TileGrid(int w, int h, int t)
      : width(w), height(h), tile(t), tiles_x((w + t - 1) / t), tiles_y((h + t - 1) / t) {}
  int count() const { return tiles_x * tiles_y; }
  void rect(int i, int& x0, int& y0, int& x1, int& y1) const {
    x0 = (i % tiles_x) * tile;
    y0 = (i / tiles_x) * tile;
    x1 = std::min(x0 + tile, width);
    y1 = std::min(y0 + tile, height);
  }
  // Floats of the largest tile (a tile no larger than the image).
  size_t max_floats() const {
    return size_t(std::min(tile, width)) * size_t(std::min(tile, height)) * 3;
  }
  size_t floats(int i) const {
    int x0, y0, x1, y1;
    rect(i, x0, y0, x1, y1);
    return size_t(x1 - x0) * size_t(y1 - y0) * 3;
  }
};

// Copies a tile's row-major pixels into the image.
void store_tile(Image& img, const TileGrid& grid, int i, const float* px) {
  int x0, y0, x1, y1;
  grid.rect(i, x0, y0, x1, y1);
  const size_t row = size_t(x1 - x0) * 3;
  for (int y = y0; y < y1; ++y)
    std::memcpy(&img.rgb[(size_t(y) * size_t(img.width) + size_t(x0)) * 3],
                px + size_t(y - y0) * row, row * sizeof(float));
}

// 64-bit FNV-1a of a string: the configuration name in the scene fingerprint.
uint64_t fnv1a(const std::string& s) {
  uint64_t h = 0xcbf29ce484222325ULL;
  for (unsigned char c : s) h = (h ^ c) * 0x100000001b3ULL;
  return h;
}

// Rank > 0: asks for tiles, renders them and sends them back until rank 0 has none left. Results
// go out with MPI_Isend from two buffers in turn, so that the next tile renders while rank 0 takes
// in the last one; a tile is rendered straight into its message, by every thread of the rank's one
// task arena (render_region cuts a tile into as many pieces as the threads need).
void work(const Scene& scene, const Camera& cam, const RenderOptions& opt_in,
          const TileGrid& grid) {
  tbb::task_arena arena(opt_in.threads > 0 ? opt_in.threads : tbb::task_arena::automatic);
  RenderOptions opt = opt_in;
  opt.threads = 0;  // render_region runs in `arena`
  std::vector<float> msg[2];
  for (std::vector<float>& m : msg) m.resize(kHeaderFloats + grid.max_floats());
  MPI_Request sent[2] = {MPI_REQUEST_NULL, MPI_REQUEST_NULL};
  int turn = 0;
  // The buffer of this turn, once its previous message is out.
  auto buffer = [&]() -> std::vector<float>& {
    MPI_Wait(&sent[turn], MPI_STATUS_IGNORE);
    return msg[turn];
  };
  // Sends this turn's buffer: the header, then `floats` pixel floats already in it.
  auto send = [&](int tile, uint64_t rays, size_t floats) {
    std::vector<float>& m = msg[turn];
    const ResultHeader h{tile, 0, rays};
    std::memcpy(m.data(), &h, sizeof h);
    MPI_Isend(m.data(), int((kHeaderFloats + floats) * sizeof(float)), MPI_BYTE, 0, kTagResult,
              MPI_COMM_WORLD, &sent[turn]);
    turn ^= 1;
  };
  int pending = 0;  // requests not answered yet: every message to rank 0 is one
  std::deque<int> queue;
  for (int i = 0; i < kPrefetch; ++i, ++pending) {
    buffer();
    send(-1, 0, 0);
  }
  while (true) {
    while (queue.empty() && pending > 0) {
      int tile = -1;
      MPI_Recv(&tile, 1, MPI_INT, 0, kTagAssign, MPI_COMM_WORLD, MPI_STATUS_IGNORE);
      --pending;
      if (tile >= 0) queue.push_back(tile);
    }
    if (queue.empty()) break;
    const int tile = queue.front();
    queue.pop_front();
    if (tile >= grid.count())
      throw Error("rank 0 sent tile " + std::to_string(tile) + " of " +
                  std::to_string(grid.count()));
    int x0, y0, x1, y1;
    grid.rect(tile, x0, y0, x1, y1);
    RenderStats st;
    float* px = buffer().data() + kHeaderFloats;
    arena.execute([&] { render_region(scene, cam, opt, x0, y0, x1, y1, px, &st); });
    send(tile, st.rays, grid.floats(tile));
    ++pending;
  }
  MPI_Waitall(2, sent, MPI_STATUSES_IGNORE);
}

}  // namespace

RenderRanks::RenderRanks() {
  if (env_int("OMPI_COMM_WORLD_SIZE") < 0 && !std::getenv("PMIX_RANK")) return;
  int provided = 0;
  // Funneled: only the main thread calls MPI; rank 0's render thread and TBB's workers do not.
  MPI_Init_thread(nullptr, nullptr, MPI_THREAD_FUNNELED, &provided);
  mpi_ = true;
  MPI_Comm_rank(MPI_COMM_WORLD, &rank_);
  MPI_Comm_size(MPI_COMM_WORLD, &size_);
  if (provided < MPI_THREAD_FUNNELED && size_ > 1) {
    if (rank_ == 0)
      std::fprintf(stderr,
                   "slimrt: error: this MPI library gives no MPI_THREAD_FUNNELED support, which "
                   "slimrt render needs under mpirun\n");
    MPI_Abort(MPI_COMM_WORLD, 1);
  }
}

RenderRanks::~RenderRanks() {
  if (mpi_) MPI_Finalize();
}

void RenderRanks::abort_job(const char* what) const {
  std::fflush(stdout);
  std::fprintf(stderr, "slimrt: error (rank %d of %d): %s\n", rank_, size_, what);
  std::fflush(stderr);
  MPI_Abort(MPI_COMM_WORLD, 1);
  std::abort();  // MPI_Abort does not return
}

void RenderRanks::check_same_scene(const Scene& scene, const std::string& scene_name) const {
  if (!distributed()) return;
  constexpr int kFields = 8;
  const Box3f b = scene.bounds();
  auto bits = [](float lo, float hi) {
    uint32_t a, c;
    std::memcpy(&a, &lo, 4);
    std::memcpy(&c, &hi, 4);
    return uint64_t(a) << 32 | c;
  };
  const uint64_t mine[kFields] = {scene.stats().input_faces, scene.stats().triangles,
                                  scene.stats().primitives,  scene.memory().total(),
                                  bits(b.lo.x, b.hi.x),      bits(b.lo.y, b.hi.y),
                                  bits(b.lo.z, b.hi.z),      fnv1a(scene.options().config_name())};
  std::vector<uint64_t> all(is_root() ? size_t(size_) * kFields : 0);
  MPI_Gather(mine, kFields, MPI_UINT64_T, all.data(), kFields, MPI_UINT64_T, 0, MPI_COMM_WORLD);
  if (!is_root()) return;
  static const char* const kNames[kFields] = {"faces",    "triangles",    "primitives",
                                              "bytes",    "x bounds",     "y bounds",
                                              "z bounds", "configuration"};
  for (int r = 1; r < size_; ++r)
    for (int f = 0; f < kFields; ++f)
      if (all[size_t(r) * kFields + f] != mine[f])
        throw Error(scene_name + ": rank " + std::to_string(r) +
                    "'s scene differs from rank 0's (" + kNames[f] +
                    "); every rank reads the scene itself, so it must be the same file on "
                    "every machine");
}

Image RenderRanks::render(const Scene& scene, const Camera& cam, const RenderOptions& opt_in,
                          int tile_size, bool root_renders, bool progress, RenderStats* stats,
                          std::vector<int>* tiles_per_rank) const {
  if (!distributed()) return slim::render(scene, cam, opt_in, stats);
  if (tile_size < 1) throw Error("render: tile size must be positive");
  RenderOptions opt = opt_in;
  opt.progress = false;
  int width = 0, height = 0;
  render_size(cam, opt, width, height);
  const TileGrid grid(width, height, tile_size);
  // MPI counts in int: the tiles and a tile's message must stay below 2^31.
  if (uint64_t(grid.tiles_x) * uint64_t(grid.tiles_y) > uint64_t(INT_MAX))
    throw Error("--mpi-tile " + std::to_string(tile_size) + ": " + std::to_string(width) + "x" +
                std::to_string(height) +
                " pixels make more than 2^31 tiles; expected a larger tile");
  if (sizeof(ResultHeader) + grid.max_floats() * sizeof(float) > size_t(INT_MAX))
    throw Error("--mpi-tile " + std::to_string(tile_size) +
                ": a tile's pixels exceed MPI's 2 GiB message; expected a smaller tile");
  if (!is_root()) {
    work(scene, cam, opt, grid);
    return Image();
  }

  Image img;
  img.width = width;
  img.height = height;
  img.rgb.assign(size_t(width) * size_t(height) * 3, 0.0f);
  const int count = grid.count();
  std::atomic<int> next{0};  // the next tile to hand out, shared by both threads of rank 0
  std::atomic<int> done{0}, root_tiles{0};
  std::atomic<uint64_t> rays{0};
  std::atomic<bool> failed{false};
  std::exception_ptr error;

  // Rank 0 renders too unless told not to (its main thread mostly sleeps between messages): with
  // K processes on K cores a coordinator alone would leave one core idle.
  // Its tiles use every thread of one task arena (render_region cuts a tile into as many pieces
  // as the threads need).
  std::thread renderer([&] {
    if (!root_renders) return;
    try {
      tbb::task_arena arena(opt.threads > 0 ? opt.threads : tbb::task_arena::automatic);
      RenderOptions arena_opt = opt;
      arena_opt.threads = 0;  // render_region runs in `arena`
      std::vector<float> px(grid.max_floats());
      for (int t; !failed.load() && (t = next.fetch_add(1)) < count;) {
        int x0, y0, x1, y1;
        grid.rect(t, x0, y0, x1, y1);
        RenderStats st;
        arena.execute(
            [&] { render_region(scene, cam, arena_opt, x0, y0, x1, y1, px.data(), &st); });
        store_tile(img, grid, t, px.data());
        rays += st.rays;
        ++done;
        ++root_tiles;
      }
    } catch (...) {
      error = std::current_exception();
      failed = true;
    }
  });

  // The main thread answers requests. Rank r sends kPrefetch requests and then one message per
  // tile it was given, so it is finished once kPrefetch + assigned[r] messages came from it.
  std::vector<int> received(size_t(size_), 0), assigned(size_t(size_), 0);
  std::vector<int> owner(size_t(count), -1);
  std::vector<float> msg;  // a result message: header, then pixels (kHeaderFloats)
  const auto t0 = std::chrono::steady_clock::now();
  int shown = -1;
  auto all_in = [&] {
    if (next.load() < count) return false;
    for (int r = 1; r < size_; ++r)
      if (received[size_t(r)] != kPrefetch + assigned[size_t(r)]) return false;
    return true;
  };
  auto show = [&](bool last) {
    if (!progress) return;
    const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    const int percent = int(int64_t(done.load()) * 100 / std::max(count, 1));
    if (s < 2.0 || (percent == shown && !last)) return;
    if (percent != shown)
      std::fprintf(stderr, "\rrender %3d%% | %.1f s | %.2f MRays/s | %d processes ", percent, s,
                   double(rays.load()) / s * 1e-6, size_);
    if (last) std::fputc('\n', stderr);
    std::fflush(stderr);
    shown = percent;
  };
  auto finish = [&] {
    failed = true;
    renderer.join();
  };
  try {
    while (!all_in()) {
      if (failed.load()) break;
      int flag = 0;
      MPI_Status status;
      MPI_Iprobe(MPI_ANY_SOURCE, kTagResult, MPI_COMM_WORLD, &flag, &status);
      if (!flag) {
        show(false);
        std::this_thread::sleep_for(std::chrono::microseconds(100));
        continue;
      }
      const int from = status.MPI_SOURCE;
      int bytes = 0;
      MPI_Get_count(&status, MPI_BYTE, &bytes);
      msg.resize((size_t(std::max(bytes, 0)) + sizeof(float) - 1) / sizeof(float));
      MPI_Recv(msg.data(), bytes, MPI_BYTE, from, kTagResult, MPI_COMM_WORLD, MPI_STATUS_IGNORE);
      ResultHeader h{};
      if (size_t(bytes) < sizeof h)
        throw Error("rank " + std::to_string(from) + " sent a message of " + std::to_string(bytes) +
                    " bytes, expected at least " + std::to_string(sizeof h));
      std::memcpy(&h, msg.data(), sizeof h);
      if (h.tile >= 0) {
        if (h.tile >= count || owner[size_t(h.tile)] != from)
          throw Error("rank " + std::to_string(from) + " sent tile " + std::to_string(h.tile) +
                      ", which it was not given");
        const size_t floats = grid.floats(h.tile);
        if (size_t(bytes) != sizeof h + floats * sizeof(float))
          throw Error("rank " + std::to_string(from) + " sent " + std::to_string(bytes) +
                      " bytes for tile " + std::to_string(h.tile) + ", expected " +
                      std::to_string(sizeof h + floats * sizeof(float)));
        store_tile(img, grid, h.tile, msg.data() + kHeaderFloats);  // the one copy
        owner[size_t(h.tile)] = -2;                                 // received
        rays += h.rays;
        ++done;
      }
      ++received[size_t(from)];
      int tile = next.fetch_add(1);
      if (tile < count) {
        owner[size_t(tile)] = from;
        ++assigned[size_t(from)];
      } else {
        tile = -1;
      }
      MPI_Send(&tile, 1, MPI_INT, from, kTagAssign, MPI_COMM_WORLD);
    }
  } catch (...) {
    finish();
    throw;
  }
  renderer.join();
  if (error) std::rethrow_exception(error);
  show(true);
  if (stats) stats->rays = rays.load();
  if (tiles_per_rank) {
    tiles_per_rank->assign(assigned.begin(), assigned.end());
    (*tiles_per_rank)[0] = root_tiles.load();
  }
  return img;
}

#else  // no MPI: one process

RenderRanks::RenderRanks() {
  const int size = env_int("OMPI_COMM_WORLD_SIZE");
  const int rank = env_int("OMPI_COMM_WORLD_RANK");
  if (size <= 1 || rank < 0) return;
  size_ = size;
  rank_ = rank;
  if (rank_ == 0)
    std::fprintf(stderr,
                 "slimrt: note: this slimrt was built without MPI (CMake found no MPI, or "
                 "SLIM_MPI=OFF): rank 0 renders the whole image alone, the other %d processes "
                 "exit\n",
                 size_ - 1);
}

RenderRanks::~RenderRanks() = default;

void RenderRanks::abort_job(const char* what) const {
  std::fprintf(stderr, "slimrt: error: %s\n", what);
  std::abort();
}

void RenderRanks::check_same_scene(const Scene&, const std::string&) const {}

Image RenderRanks::render(const Scene& scene, const Camera& cam, const RenderOptions& opt, int,
                          bool, bool, RenderStats* stats, std::vector<int>*) const {
  return slim::render(scene, cam, opt, stats);
}

#endif

}  // namespace slim::cli
