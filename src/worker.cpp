#include "worker.h"

#include <algorithm>
#include <chrono>
#include <stdexcept>

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
constexpr unsigned kExplore = 17;   // every this many runs of a kind, the mode not chosen
constexpr double kWeight = 0.2;     // of a run's cost in the running mean

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
    const int chunk = static_cast<int>(ticket & 0xffffu);
    const int chunks = static_cast<int>((ticket >> 16) & 0xffffu);
    if (static_cast<uint32_t>(ticket >> 32) != generation || chunk >= chunks) return ran;
    if (!ticket_.compare_exchange_weak(ticket, ticket + 1, std::memory_order_acq_rel)) continue;
    // the chunks it depends on: every chunk claimed before it, so they finish (each
    // finished chunk counts once: done_ reaches the gate only when all before it are done)
    const int gate = gate_ != nullptr ? gate_[chunk] : chunk;
    wait_until([&] { return done_.load(std::memory_order_acquire) >= gate; });
    (*task_)(chunk);
    done_.fetch_add(1, std::memory_order_acq_rel);
    ++ran;
  }
}

void Worker::run_pair(const std::function<void()>& first, const std::function<void(int)>& second,
                      int chunks, int kind, double work) {
  if (chunks < 0 || chunks > kMaxChunks) throw std::invalid_argument("Worker: chunks out of range");
  run(&first, second, chunks, nullptr, kind, work);
}

void Worker::run_waves(const std::function<void(int)>& task, int chunks, const int32_t* gate,
                       int kind, double work) {
  if (chunks <= 1 || chunks > kMaxChunks) {   // (one chunk: nothing to share)
    for (int c = 0; c < chunks; ++c) task(c);
    return;
  }
  run(nullptr, task, chunks, gate, kind, work);
}

void Worker::run(const std::function<void()>* first, const std::function<void(int)>& task,
                 int chunks, const int32_t* gate, int kind, double work) {
  chunks_run_ += static_cast<uint64_t>(chunks);
  Costs& costs = costs_[kind & 1];
  // the mode that has cost less per unit of work, the other one every kExplore-th run (an
  // unmeasured mode first)
  const bool better = costs.paired <= costs.alone;
  const bool paired = ++costs.runs % kExplore == 0 ? !better : better;
  const auto start = std::chrono::steady_clock::now();
  if (paired) {
    uint32_t generation;
    {
      std::lock_guard<std::mutex> lock(mutex_);
      task_ = &task;
      gate_ = gate;
      done_.store(0);
      generation = ++generation_;
      ticket_.store(static_cast<uint64_t>(generation) << 32 |
                        static_cast<uint64_t>(chunks) << 16,
                    std::memory_order_release);
    }
    wake_.notify_one();
    if (first != nullptr) (*first)();
    help(generation);   // the chunks the worker has not taken
    // (a chunk the worker claimed is finished before the next run is posted: it reads
    // task_ and gate_ only while it holds one)
    wait_until([&] { return done_.load(std::memory_order_acquire) == chunks; });
  } else {
    if (first != nullptr) (*first)();
    for (int c = 0; c < chunks; ++c) task(c);
  }
  const double cost =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count() /
      std::max(work, 1.0);
  double& mean = paired ? costs.paired : costs.alone;
  mean = mean == 0.0 ? cost : mean + kWeight * (cost - mean);
}

}  // namespace collres
