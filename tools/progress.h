// Progress of a step the library reports nothing about while it runs (loading, building): a
// thread that waits, and once the step has taken ~2 s prints its name and the elapsed time on
// stderr every half second, then the total when it ends. Only when enabled (stderr is a terminal
// and --quiet is not given); the traced work itself never touches it.
#pragma once

#include <chrono>
#include <condition_variable>
#include <cstdio>
#include <mutex>
#include <string>
#include <thread>

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

}  // namespace slim::cli
