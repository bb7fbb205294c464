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
#include <functional>
#include <mutex>
#include <string>
#include <thread>

#include "slimrt/scene.h"

namespace slim::cli {

// The line on stderr: a thread that waits ~2 s, then draws line(seconds) every half second and
// last(seconds) when the object goes (if it drew anything). It prints holding no lock that the
// work takes, so the work never waits for a slow terminal. Declare it as the last member of its
// owner: it is joined before the state its functions read goes.
class ProgressLine {
 public:
  using Text = std::function<std::string(double seconds)>;
  ProgressLine(bool enabled, Text line, Text last)
      : line_(std::move(line)), last_(std::move(last)) {
    if (enabled) thread_ = std::thread([this] { run(); });
  }
  ~ProgressLine() {
    if (!thread_.joinable()) return;
    {
      std::lock_guard<std::mutex> lock(mutex_);
      done_ = true;
    }
    cv_.notify_one();
    thread_.join();
  }
  ProgressLine(const ProgressLine&) = delete;
  ProgressLine& operator=(const ProgressLine&) = delete;
  bool enabled() const { return thread_.joinable(); }

 private:
  void run() {
    using namespace std::chrono;
    const auto t0 = steady_clock::now();
    auto seconds_now = [&] { return duration<double>(steady_clock::now() - t0).count(); };
    std::unique_lock<std::mutex> lock(mutex_);
    if (cv_.wait_for(lock, seconds(2), [this] { return done_; })) return;
    size_t width = 0;  // spaces clear what a longer previous line left
    while (true) {
      lock.unlock();
      const std::string text = "\r" + line_(seconds_now());
      std::fprintf(stderr, "%-*s", int(width), text.c_str());
      std::fflush(stderr);
      width = std::max(width, text.size());
      lock.lock();
      if (cv_.wait_for(lock, milliseconds(500), [this] { return done_; })) break;
    }
    lock.unlock();
    std::fprintf(stderr, "%-*s\n", int(width), ("\r" + last_(seconds_now())).c_str());
  }

  Text line_, last_;
  std::mutex mutex_;
  std::condition_variable cv_;
  bool done_ = false;
  std::thread thread_;
};

// A step the library reports nothing about while it runs (loading): its name and elapsed time.
class StepProgress {
 public:
  StepProgress(bool enabled, std::string what)
      : what_(std::move(what)),
        line_(
            enabled, [this](double s) { return what_ + " | " + fixed1(s) + " s "; },
            [this](double s) { return what_ + " | done in " + fixed1(s) + " s"; }) {}

 private:
  static std::string fixed1(double s) {
    char buf[32];
    std::snprintf(buf, sizeof buf, "%.1f", s);
    return buf;
  }
  std::string what_;
  ProgressLine line_;
};

// Progress of a Scene::build: pass callback() as BuildOptions::progress. Shows
//   build bvh8-tri4v (1000000 triangles) | bvh2 45% | 3.1 s | 1.52 M triangles/s
// where the rate is the phase's: the scene's triangles times the phase's fraction done over the
// time the phase has run.
class BuildMeter {
 public:
  // The line names the configuration `config` and the scene's `triangles`.
  BuildMeter(bool enabled, const std::string& config, uint64_t triangles)
      : what_("build " + config + " (" + std::to_string(triangles) + " triangles)"),
        triangles_(triangles),
        line_(
            enabled, [this](double s) { return line(s); },
            [this](double s) {
              char buf[128];
              std::snprintf(buf, sizeof buf, " | done in %.1f s | %.2f M triangles/s", s,
                            s > 0 ? double(triangles_) / s * 1e-6 : 0.0);
              return what_ + buf;
            }) {}

  // Empty when not enabled: the build then reports nothing.
  BuildProgressFn callback() {
    if (!line_.enabled()) return {};
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
  std::string line(double s) {
    std::string phase;
    double fraction = 0, phase_s = 0;
    {
      std::lock_guard<std::mutex> lock(mutex_);  // a copy: formatting happens unlocked
      phase = phase_;
      fraction = fraction_;
      phase_s =
          std::chrono::duration<double>(std::chrono::steady_clock::now() - phase_start_).count();
    }
    std::string text = what_;
    char buf[128];
    if (!phase.empty()) {
      std::snprintf(buf, sizeof buf, " | %s %3d%%", phase.c_str(), int(fraction * 100.0));
      text += buf;
    }
    std::snprintf(buf, sizeof buf, " | %.1f s", s);
    text += buf;
    if (!phase.empty() && fraction > 0.0 && phase_s > 0.0) {
      std::snprintf(buf, sizeof buf, " | %.2f M triangles/s",
                    double(triangles_) * fraction / phase_s * 1e-6);
      text += buf;
    }
    return text;
  }

  std::string what_;
  uint64_t triangles_;
  std::mutex mutex_;  // guards the phase last reported, its start and its fraction done
  std::string phase_;
  std::chrono::steady_clock::time_point phase_start_ = std::chrono::steady_clock::now();
  double fraction_ = 0;
  ProgressLine line_;  // last: its thread reads the members above
};

}  // namespace slim::cli
