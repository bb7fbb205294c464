// One phase of a build's progress (BuildOptions::progress, slimrt/scene.h): the builders add the
// work they finish (a subtree's primitives, a chunk of references) to an atomic counter, and the
// user's callback is called when the counter crosses the next percent, under a mutex so that the
// calls are serialized and `done` grows from one call to the next. The builders hold a pointer
// that is null when no callback is set: no counter, no call, no other work.
#pragma once

#include <algorithm>
#include <atomic>
#include <cstdint>
#include <mutex>
#include <string>

#include "slimrt/scene.h"

namespace slim {

class PhaseProgress {
 public:
  // Reports done = 0 (when total > 0).
  PhaseProgress(const BuildProgressFn& fn, std::string phase, uint64_t total) : fn_(fn) {
    report_.phase = std::move(phase);
    report_.total = total;
    if (total > 0) call(0);
  }
  PhaseProgress(const PhaseProgress&) = delete;
  PhaseProgress& operator=(const PhaseProgress&) = delete;

  // Adds n units of finished work (thread-safe). Calls the callback when the total crossed the
  // next percent; throws slim::Cancelled if it (or an earlier call) returned false. Not inlined:
  // the builders' loops around a call keep their code (and registers) as without progress.
  __attribute__((noinline)) void add(uint64_t n) {
    if (cancelled_.load(std::memory_order_relaxed)) throw_cancelled();
    const uint64_t done = done_.fetch_add(n, std::memory_order_relaxed) + n;
    if (step_of(done) <= shown_step_.load(std::memory_order_relaxed)) return;
    std::lock_guard<std::mutex> lock(mutex_);
    // Under the lock: the counter read here is at least any value reported before.
    const uint64_t now = std::min(done_.load(std::memory_order_relaxed), report_.total);
    const uint64_t step = step_of(now);
    if (step <= shown_step_.load(std::memory_order_relaxed)) return;
    shown_step_.store(step, std::memory_order_relaxed);
    call_locked(now);
  }

  // Reports done = total once (the phase's last report). Call it when the phase has ended.
  void finish() {
    std::lock_guard<std::mutex> lock(mutex_);
    if (last_reported_ == report_.total && report_.total > 0) return;
    shown_step_.store(kSteps, std::memory_order_relaxed);
    call_locked(report_.total);
  }

 private:
  static constexpr uint64_t kSteps = 100;
  uint64_t step_of(uint64_t done) const {
    if (done >= report_.total) return kSteps;
    return uint64_t(double(done) / double(report_.total) * double(kSteps));
  }
  void call(uint64_t done) {
    std::lock_guard<std::mutex> lock(mutex_);
    call_locked(done);
  }
  void call_locked(uint64_t done) {
    if (cancelled_.load(std::memory_order_relaxed)) throw_cancelled();
    report_.done = done;
    last_reported_ = done;
    if (!fn_(report_)) {
      cancelled_.store(true, std::memory_order_relaxed);
      throw_cancelled();
    }
  }
  [[noreturn]] void throw_cancelled() const {
    throw Cancelled("build cancelled by the progress callback in phase '" + report_.phase + "'");
  }

  const BuildProgressFn& fn_;
  BuildProgress report_;  // guarded by mutex_
  uint64_t last_reported_ = ~uint64_t(0);
  std::mutex mutex_;
  alignas(64) std::atomic<uint64_t> done_{0};
  alignas(64) std::atomic<uint64_t> shown_step_{0};
  std::atomic<bool> cancelled_{false};
};

// A single report outside a counted phase (the steps of "prepare"); throws slim::Cancelled when
// the callback returns false.
inline void report_progress(const BuildProgressFn& fn, const char* phase, uint64_t done,
                            uint64_t total) {
  BuildProgress p;
  p.phase = phase;
  p.done = done;
  p.total = total;
  if (!fn(p))
    throw Cancelled(std::string("build cancelled by the progress callback in phase '") + phase +
                    "'");
}

}  // namespace slim
