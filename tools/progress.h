// Progress on stderr of the steps that take long: StepProgress for a step the library reports
// nothing about while it runs (loading), BuildMeter for Scene::build (BuildOptions::progress). A
// thread waits, and once the step has taken ~2 s prints its name, the elapsed time (and for a
// build the phase, its percentage and its rate in triangles/s) every half second, then the total
// when it ends. Only when enabled (stderr is a terminal and --quiet is not given); the work itself
// never waits for the printing.
#pragma once

#include <algorithm>
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <cstdio>
#include <mutex>
#include <string>
#include <thread>

#include "slimrt/scene.h"

namespace slim::cli {

class StepProgress {
 public:
  StepProgress(bool enabled, std::string what) : what_(std::move(what)) {
    if (enabled) thread_ = std::thread([this] { run(); });
  }
  ~StepProgress() {
    if (!thread_.joinable()) return;
    {
      std::lock_guard<std::mutex> lock(mutex_);
      done_ = true;
    }
    cv_.notify_one();
    thread_.join();
  }
  StepProgress(const StepProgress&) = delete;
  StepProgress& operator=(const StepProgress&) = delete;

 private:
  void run() {
    using namespace std::chrono;
    auto t0 = steady_clock::now();
    std::unique_lock<std::mutex> lock(mutex_);
    if (cv_.wait_for(lock, seconds(2), [this] { return done_; })) return;
    bool drawn = false;
    while (true) {
      double s = duration<double>(steady_clock::now() - t0).count();
      std::fprintf(stderr, "\r%s | %.1f s ", what_.c_str(), s);
      std::fflush(stderr);
      drawn = true;
      if (cv_.wait_for(lock, milliseconds(500), [this] { return done_; })) break;
    }
    if (drawn) {
      double s = duration<double>(steady_clock::now() - t0).count();
      std::fprintf(stderr, "\r%s | done in %.1f s\n", what_.c_str(), s);
    }
  }

  std::string what_;
  std::mutex mutex_;
  std::condition_variable cv_;
  bool done_ = false;
  std::thread thread_;
};

// Progress of a Scene::build: pass callback() as BuildOptions::progress. Shows
//   build bvh8-tri4v (1000000 triangles) | bvh2 45% | 3.1 s | 1.52 M triangles/s
// where the rate is the phase's: the scene's triangles times the phase's fraction done over the
// time the phase has run.
class BuildMeter {
 public:
  BuildMeter(bool enabled, std::string what, uint64_t triangles)
      : what_(std::move(what)), triangles_(triangles) {
    if (enabled) thread_ = std::thread([this] { run(); });
  }
  ~BuildMeter() {
    if (!thread_.joinable()) return;
    {
      std::lock_guard<std::mutex> lock(mutex_);
      done_ = true;
    }
    cv_.notify_one();
    thread_.join();
  }
  BuildMeter(const BuildMeter&) = delete;
  BuildMeter& operator=(const BuildMeter&) = delete;

  // Empty when not enabled: the build then reports nothing.
  BuildProgressFn callback() {
    if (!thread_.joinable()) return {};
    return [this](const BuildProgress& p) {
      std::lock_guard<std::mutex> lock(mutex_);
      if (p.phase != phase_) {
        phase_ = p.phase;
        phase_start_ = std::chrono::steady_clock::now();
      }
      fraction_ = p.fraction();
      return true;
    };
  }

 private:
  void run() {
    using namespace std::chrono;
    const auto t0 = steady_clock::now();
    std::unique_lock<std::mutex> lock(mutex_);
    if (cv_.wait_for(lock, seconds(2), [this] { return done_; })) return;
    bool drawn = false;
    while (true) {
      const auto now = steady_clock::now();
      const double s = duration<double>(now - t0).count();
      std::string line = "\r" + what_;
      char buf[128];
      if (!phase_.empty()) {
        std::snprintf(buf, sizeof buf, " | %s %3d%%", phase_.c_str(), int(fraction_ * 100.0));
        line += buf;
      }
      std::snprintf(buf, sizeof buf, " | %.1f s", s);
      line += buf;
      const double phase_s = duration<double>(now - phase_start_).count();
      if (!phase_.empty() && fraction_ > 0.0 && phase_s > 0.0) {
        std::snprintf(buf, sizeof buf, " | %.2f M triangles/s",
                      double(triangles_) * fraction_ / phase_s * 1e-6);
        line += buf;
      }
      // Spaces clear what a longer previous line left.
      std::fprintf(stderr, "%-*s", int(width_), line.c_str());
      width_ = std::max(width_, line.size());
      std::fflush(stderr);
      drawn = true;
      if (cv_.wait_for(lock, milliseconds(500), [this] { return done_; })) break;
    }
    if (drawn) {
      const double s = duration<double>(steady_clock::now() - t0).count();
      char buf[128];
      std::snprintf(buf, sizeof buf, " | done in %.1f s | %.2f M triangles/s", s,
                    s > 0 ? double(triangles_) / s * 1e-6 : 0.0);
      std::fprintf(stderr, "%-*s\n", int(width_), ("\r" + what_ + buf).c_str());
    }
  }

  std::string what_;
  uint64_t triangles_;
  std::mutex mutex_;
  std::condition_variable cv_;
  bool done_ = false;
  std::string phase_;  // the phase last reported (guarded by mutex_), its start and fraction done
  std::chrono::steady_clock::time_point phase_start_ = std::chrono::steady_clock::now();
  double fraction_ = 0;
  size_t width_ = 0;
  std::thread thread_;
};

}  // namespace slim::cli
