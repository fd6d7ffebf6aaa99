#include "worker.h"

#include <algorithm>
#include <chrono>

#if defined(__x86_64__) || defined(__i386__)
#include <immintrin.h>
#define COLLRES_PAUSE() _mm_pause()
#else
#define COLLRES_PAUSE() std::this_thread::yield()
#endif

namespace collres {
namespace {
// pauses (~40 ns each) a waiting thread spins before it sleeps (the worker) or yields its
// core (the caller): short, so that a busy machine loses little to spinning
constexpr int kSpins = 256;
constexpr int kFirstBackoff = 4, kLastBackoff = 1024;   // runs alone after a long wait

void wait_until(const std::function<bool()>& ready) {
  for (int i = 0; !ready(); ++i) {
    if (i < kSpins) {
      COLLRES_PAUSE();
    } else {
      std::this_thread::yield();
    }
  }
}
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
  uint32_t seen = 0;   // the last run helped with
  for (;;) {
    for (int i = 0; i < kSpins && static_cast<uint32_t>(ticket_.load() >> 32) == seen; ++i)
      COLLRES_PAUSE();
    uint32_t generation;
    {
      std::unique_lock<std::mutex> lock(mutex_);
      wake_.wait(lock, [&] { return stop_ || generation_ != seen; });
      if (stop_) return;
      generation = seen = generation_;
    }
    helped_.fetch_add(static_cast<uint64_t>(help(generation)), std::memory_order_relaxed);
  }
}

int Worker::help(uint32_t generation) {
  for (int ran = 0;;) {
    uint64_t ticket = ticket_.load(std::memory_order_acquire);
    const int chunk = static_cast<int>(ticket & 0xffffffffu);
    if (static_cast<uint32_t>(ticket >> 32) != generation || chunk >= chunks_.load()) return ran;
    if (!ticket_.compare_exchange_weak(ticket, ticket + 1, std::memory_order_acq_rel)) continue;
    wait_until([&] { return done_.load(std::memory_order_acquire) == chunk; });
    (*task_)(chunk);
    done_.store(chunk + 1, std::memory_order_release);
    ++ran;
  }
}

void Worker::run_pair(const std::function<void()>& first, const std::function<void(int)>& second,
                      int chunks) {
  chunks_run_ += static_cast<uint64_t>(chunks);
  if (alone_ > 0) {   // backing off: all here, in order
    --alone_;
    first();
    for (int c = 0; c < chunks; ++c) second(c);
    return;
  }
  const auto start = std::chrono::steady_clock::now();
  uint32_t generation;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    task_ = &second;
    chunks_ = chunks;
    done_.store(0);
    generation = ++generation_;
    ticket_.store(static_cast<uint64_t>(generation) << 32, std::memory_order_release);
  }
  wake_.notify_one();
  first();
  help(generation);   // the chunks the worker has not taken
  // (a chunk the worker claimed is finished before the next run is posted: it reads
  // task_ only while it holds one)
  if (done_.load(std::memory_order_acquire) == chunks) {
    backoff_ /= 2;
    return;
  }
  const auto waiting = std::chrono::steady_clock::now();
  wait_until([&] { return done_.load(std::memory_order_acquire) == chunks; });
  const auto end = std::chrono::steady_clock::now();
  if (end - waiting > (end - start) / 10) {
    backoff_ = std::min(std::max(2 * backoff_, kFirstBackoff), kLastBackoff);
    alone_ = backoff_;
  } else {
    backoff_ /= 2;
  }
}

}  // namespace collres
