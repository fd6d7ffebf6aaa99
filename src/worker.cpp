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
// pauses (~25-40 ns each) a waiting thread spins before it sleeps (the worker) or yields its
// core (the caller): short, so that a busy machine loses little to spinning
constexpr int kSpins = 256;
// the most runs of a kind between two in the mode not chosen (Costs::every doubles up to
// it while that mode keeps costing more: on a loaded machine a paired run can wait for a
// descheduled worker)
constexpr unsigned kExploreMost = Worker::kExplore << 6;
constexpr double kWeight = 0.2;     // of a run's cost in the running mean
constexpr int kBurst = 4;           // runs in a row in the mode not chosen
constexpr double kGiveUp = 2.0;     // (Worker::run) a burst's run costing this many times more

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

Worker::Worker()
    : gate_(new std::atomic<int32_t>[kMaxChunks]()),
      thread_([this] { loop(); }) {}

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
    helped_.fetch_add(static_cast<uint64_t>(help(generation, finished_[1].count)),
                      std::memory_order_relaxed);
  }
}

int Worker::help(uint32_t generation, std::atomic<int>& finished) {
  for (int ran = 0, waits = 0;;) {
    const uint64_t ticket = ticket_.load(std::memory_order_acquire);
    const int chunk = static_cast<int>(ticket & 0xffffu);
    const int chunks = static_cast<int>((ticket >> 16) & 0xffffu);
    if (static_cast<uint32_t>(ticket >> 32) != generation || chunk >= chunks) return ran;
    // its gate first: the chunks it depends on, every chunk claimed before it, finish
    // (each counts once: done() reaches the gate only when all before it are done); a
    // ticket of a finished run may read the next run's gate (its claim then fails)
    if (done() < gate_[chunk].load(std::memory_order_relaxed)) {
      if (++waits < kSpins) {
        COLLRES_PAUSE();
      } else {
        std::this_thread::yield();
      }
      continue;
    }
    uint64_t expected = ticket;
    if (!ticket_.compare_exchange_strong(expected, ticket + 1, std::memory_order_acq_rel))
      continue;
    waits = 0;
    (*task_)(chunk);
    finished.store(finished.load(std::memory_order_relaxed) + 1, std::memory_order_release);
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
  bool chain = true;   // (each chunk waits for every one before it: nothing to share)
  for (int c = 0; c < chunks && chain; ++c) chain = gate[c] == c;
  if (chain || chunks > kMaxChunks) {
    for (int c = 0; c < chunks; ++c) task(c);
    return;
  }
  run(nullptr, task, chunks, gate, kind, work);
}

void Worker::run(const std::function<void()>* first, const std::function<void(int)>& task,
                 int chunks, const int32_t* gate, int kind, double work) {
  chunks_run_ += static_cast<uint64_t>(chunks);
  Costs& costs = costs_[kind & 1];
  // the mode that has cost less per unit of work (an unmeasured mode first), the other
  // one for kBurst runs in a row every costs.every-th run: the first of those wakes the
  // worker (or brings the data back to the caller's core), the others measure the mode
  if (costs.burst == 0 && ++costs.runs >= costs.every) {
    costs.burst = kBurst;
    costs.explored = costs.paired > costs.alone;
    costs.sum = 0.0;
    costs.measured = 0;
  }
  const bool explore = costs.burst > 0;
  const bool paired = explore ? costs.explored : costs.paired <= costs.alone;
  const auto start = std::chrono::steady_clock::now();
  if (paired) {
    uint32_t generation;
    {
      std::lock_guard<std::mutex> lock(mutex_);
      task_ = &task;
      generation = ++generation_;
      for (int c = 0; c < chunks; ++c)
        gate_[c].store(gate != nullptr ? gate[c] : c, std::memory_order_relaxed);
      for (Finished& f : finished_) f.count.store(0, std::memory_order_relaxed);
      ticket_.store(static_cast<uint64_t>(generation) << 32 |
                        static_cast<uint64_t>(chunks) << 16,
                    std::memory_order_release);
    }
    wake_.notify_one();
    if (first != nullptr) (*first)();
    help(generation, finished_[0].count);   // the chunks left to claim
    // then the worker's last ones (a chunk the worker began is finished before the next
    // run is posted: it reads task_ only while it runs one)
    wait_until([&] { return done() == chunks; });
  } else {
    if (first != nullptr) (*first)();
    for (int c = 0; c < chunks; ++c) task(c);
  }
  const double cost =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count() /
      std::max(work, 1.0);
  if (explore) {
    // (an explored mode's mean is the cost of its last kBurst - 1 runs: it may have
    // changed since it was chosen; or of a run that costs more than kGiveUp times the
    // chosen mode's mean, which ends the burst: a loaded machine pays for one run)
    const double other = paired ? costs.alone : costs.paired;
    const bool wake = costs.burst-- == kBurst;
    if (cost > kGiveUp * other) {
      costs.burst = 0;
      costs.sum = cost;
      costs.measured = 1;
    } else if (!wake) {
      costs.sum += cost;
      ++costs.measured;
    }
    if (costs.burst == 0) {
      double& mean = paired ? costs.paired : costs.alone;
      mean = costs.sum / costs.measured;
      costs.every = mean > other ? std::min(2 * costs.every, kExploreMost) : kExplore;
      costs.runs = 0;
    }
    return;
  }
  double& mean = paired ? costs.paired : costs.alone;
  mean = mean == 0.0 ? cost : mean + kWeight * (cost - mean);
}

}  // namespace collres
