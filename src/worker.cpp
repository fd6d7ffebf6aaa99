#include "worker.h"

#if defined(__x86_64__) || defined(__i386__)
#include <immintrin.h>
#define COLLRES_PAUSE() _mm_pause()
#else
#define COLLRES_PAUSE() std::this_thread::yield()
#endif

namespace collres {
namespace {
constexpr int kSpins = 4000;   // pauses (~40 ns each) a thread spins before it sleeps or yields
}  // namespace

Worker::Worker() : thread_([this] { loop(); }) {}

Worker::~Worker() {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    stop_ = true;
  }
  wake_.notify_one();
  thread_.join();
}

void Worker::loop() {
  for (;;) {
    // spin a little for the next task, then sleep until one is posted
    for (int i = 0; i < kSpins && state_.load(std::memory_order_acquire) != kPosted; ++i)
      COLLRES_PAUSE();
    if (state_.load(std::memory_order_acquire) != kPosted) {
      std::unique_lock<std::mutex> lock(mutex_);
      wake_.wait(lock, [this] { return stop_ || state_.load() == kPosted; });
      if (stop_) return;
    }
    int posted = kPosted;
    if (!state_.compare_exchange_strong(posted, kTaken, std::memory_order_acq_rel)) continue;
    (*task_)();
    state_.store(kDone, std::memory_order_release);
  }
}

void Worker::run_pair(const std::function<void()>& first, const std::function<void()>& second) {
  task_ = &second;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    state_.store(kPosted, std::memory_order_release);
  }
  wake_.notify_one();
  first();
  int posted = kPosted;
  if (state_.compare_exchange_strong(posted, kIdle, std::memory_order_acq_rel)) {
    second();   // the worker has not taken it: run it here
    return;
  }
  // the worker runs it: wait until it is done
  for (int i = 0; state_.load(std::memory_order_acquire) != kDone; ++i) {
    if (i < kSpins) {
      COLLRES_PAUSE();
    } else {
      std::this_thread::yield();
    }
  }
  state_.store(kIdle, std::memory_order_relaxed);
}

}  // namespace collres
