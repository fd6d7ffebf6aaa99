#include "worker.h"

#include <algorithm>
#include <chrono>
#include <stdexcept>

#ifdef __linux__
#include <sched.h>
#endif

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
// polls (Worker::help) that find the other queue's next chunk ready, not claimed, before
// a thread with nothing else to run takes it: ~2-3 us, where a thread at work claims its
// next chunk within ~0.1 us of the last one (taking it sooner would move the chunk's data
// to the other core, and it races the other thread for it)
constexpr int kPatience = 64;

constexpr uint64_t kClaim = uint64_t{1} << 16;   // a chunk claimed, in a queue's state
inline uint32_t run_of(uint64_t state) { return static_cast<uint32_t>(state >> 32); }
inline int claimed_of(uint64_t state) { return static_cast<int>((state >> 16) & 0xffffu); }
inline int finished_of(uint64_t state) { return static_cast<int>(state & 0xffffu); }

// the core this thread runs on (-1: unknown)
int current_core() {
#ifdef __linux__
  return sched_getcpu();
#else
  return -1;
#endif
}

// (the worker) off the core `caller` when it runs there: its affinity without that core,
// then the one it had (see the file's header); nothing when the process may run on that
// core alone
void leave_core(int caller) {
#ifdef __linux__
  const int here = sched_getcpu();
  if (here < 0 || here != caller) return;
  cpu_set_t allowed;
  if (sched_getaffinity(0, sizeof allowed, &allowed) != 0 || !CPU_ISSET(here, &allowed) ||
      CPU_COUNT(&allowed) < 2)
    return;
  cpu_set_t elsewhere = allowed;
  CPU_CLR(here, &elsewhere);
  if (sched_setaffinity(0, sizeof elsewhere, &elsewhere) == 0)
    sched_setaffinity(0, sizeof allowed, &allowed);
#else
  (void)caller;
#endif
}

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
    : chunk_{std::unique_ptr<std::atomic<int32_t>[]>(new std::atomic<int32_t>[kMaxChunks]()),
             std::unique_ptr<std::atomic<int32_t>[]>(new std::atomic<int32_t>[kMaxChunks]())},
      need_{std::unique_ptr<std::atomic<int32_t>[]>(new std::atomic<int32_t>[kMaxChunks]()),
            std::unique_ptr<std::atomic<int32_t>[]>(new std::atomic<int32_t>[kMaxChunks]())},
      thread_([this] { loop(); }) {}

Worker::~Worker() {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    stay_.store(false, std::memory_order_relaxed);
    stop_ = true;
  }
  wake_.notify_one();
  thread_.join();
}

void Worker::loop() {
  uint32_t seen = 0;   // the last run helped with
  for (;;) {
    // spin for the next run (while the caller stays: stay(true), yielding the core every
    // kSpins polls), then sleep
    for (int i = 0; run_of(queue_[1].state.load()) == seen; ++i) {
      if (i >= kSpins && !stay_.load(std::memory_order_relaxed)) break;
      if (i % kSpins == kSpins - 1) {
        std::this_thread::yield();
      } else {
        COLLRES_PAUSE();
      }
    }
    uint32_t generation;
    {
      std::unique_lock<std::mutex> lock(mutex_);
      wake_.wait(lock, [&] {
        return stop_ || generation_ != seen || stay_.load(std::memory_order_relaxed);
      });
      if (stop_) return;
      if (generation_ == seen) continue;   // (woken to stay: spins for the next run)
      generation = seen = generation_;
    }
    leave_core(caller_core_.load(std::memory_order_relaxed));
    helped_.fetch_add(static_cast<uint64_t>(help(generation, 1)), std::memory_order_relaxed);
  }
}

void Worker::stay(bool on) {
  // only while a kind of run that has run is run paired (or is about to be explored so):
  // on a machine whose other core is busy every kind runs alone, and the worker sleeps
  bool paired = false;
  for (const Costs& costs : costs_)
    paired = paired || (costs.burst > 0 ? costs.explored
                                        : (costs.paired > 0.0 || costs.alone > 0.0) &&
                                              costs.paired <= costs.alone);
  on = on && paired;
  if (stay_.load(std::memory_order_relaxed) == on) return;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    stay_.store(on, std::memory_order_relaxed);
  }
  if (on) wake_.notify_one();
}

int Worker::help(uint32_t generation, int own) {
  // the other queue's state as last seen, and the polls it stayed so while this thread had
  // nothing to run: its thread is away (asleep, descheduled) once kPatience polls found
  // its next chunk ready and not claimed
  uint64_t watched = 0;
  int still = 0;
  for (int ran = 0, waits = 0;;) {
    bool left = false;   // a chunk of the run not claimed yet
    bool over = false;   // the run finished (a later one posted)
    bool lent = false;   // a chunk of its own queue running (on the other thread)
    int taken = -1;      // the queue of the chunk claimed
    uint64_t state = 0;
    for (int j = 0; j < 2 && taken < 0 && !over; ++j) {
      const int q = own ^ j;
      state = queue_[q].state.load(std::memory_order_acquire);
      if (run_of(state) != generation) {
        over = true;
        break;
      }
      if (j == 1 && state != watched) {
        watched = state;
        still = 0;
      }
      const int claimed = claimed_of(state);
      if (j == 0) lent = claimed != finished_of(state);
      if (claimed >= queue_[q].size.load(std::memory_order_relaxed)) continue;
      left = true;
      if (claimed != finished_of(state)) continue;   // (its chunk running)
      // the chunks of the other queue it depends on; a state of a finished run may read
      // the next run's need (its claim then fails)
      const int32_t need = need_[q][claimed].load(std::memory_order_relaxed);
      if (need > 0) {
        const uint64_t other = queue_[q ^ 1].state.load(std::memory_order_acquire);
        if (run_of(other) != generation) {
          over = true;
          break;
        }
        if (finished_of(other) < need) continue;
      }
      // the other queue's next chunk only from a thread away, and not while that thread
      // runs one of this queue's: it is at work, and taking its chunk in turn made the two
      // run each other's chunks for the rest of the run, each after kPatience polls
      if (j == 1 && (lent || still < kPatience)) continue;
      uint64_t expected = state;
      if (queue_[q].state.compare_exchange_strong(expected, state + kClaim,
                                                  std::memory_order_acq_rel))
        taken = q;
    }
    if (over || (!left && taken < 0)) return ran;
    if (taken < 0) {
      ++still;
      if (++waits < kSpins) {
        COLLRES_PAUSE();
      } else {
        std::this_thread::yield();
      }
      continue;
    }
    waits = 0;
    (*task_)(chunk_[taken][claimed_of(state)].load(std::memory_order_relaxed));
    queue_[taken].state.fetch_add(1, std::memory_order_release);
    if (taken != own) watched = state + kClaim + 1;   // (its thread still away)
    ++ran;
  }
}

void Worker::run_pair(const std::function<void()>& first, const std::function<void(int)>& second,
                      int chunks, int kind, double work) {
  if (chunks < 0 || chunks > kMaxChunks) throw std::invalid_argument("Worker: chunks out of range");
  run(&first, second, chunks, nullptr, nullptr, kind, work, false);
}

void Worker::run_sides(const std::function<void(int)>& task, int chunks, const uint8_t* side,
                       const int32_t* need, int kind, double work) {
  int in[2] = {0, 0};   // chunks per queue
  for (int c = 0; c < chunks; ++c) ++in[side[c] & 1];
  if (in[0] == 0 || std::max(in[0], in[1]) > kMaxChunks) {
    for (int c = 0; c < chunks; ++c) task(c);
    return;
  }
  run(nullptr, task, chunks, side, need, kind, work, in[1] == 0);
}

bool Worker::pairs(int kind) const {
  const Costs& costs = costs_[std::clamp(kind, 0, kKinds - 1)];
  return costs.burst > 0 ? costs.explored : costs.paired <= costs.alone;
}

void Worker::run(const std::function<void()>* first, const std::function<void(int)>& task,
                 int chunks, const uint8_t* side, const int32_t* need, int kind,
                 double work, bool lone) {
  if (!lone) chunks_run_ += static_cast<uint64_t>(chunks);
  Costs& costs = costs_[std::clamp(kind, 0, kKinds - 1)];
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
  if (lone && paired) {
    // (cut for one thread where pairing is chosen now: its cost is neither mode's, and a
    // burst due waits for the next run cut for two, which pairs(kind) now asks for)
    for (int c = 0; c < chunks; ++c) task(c);
    return;
  }
  const auto start = std::chrono::steady_clock::now();
  if (!lone) ++runs_;
  if (paired) {
    ++paired_runs_;
    uint32_t generation;
    {
      std::lock_guard<std::mutex> lock(mutex_);
      caller_core_.store(current_core(), std::memory_order_relaxed);
      task_ = &task;
      generation = ++generation_;
      int size[2] = {0, 0};
      for (int c = 0; c < chunks; ++c) {
        const int q = side != nullptr ? side[c] & 1 : 1;   // (run_pair's: the worker's)
        chunk_[q][size[q]].store(c, std::memory_order_relaxed);
        need_[q][size[q]++].store(need != nullptr ? need[c] : 0, std::memory_order_relaxed);
      }
      for (int q = 0; q < 2; ++q) {
        queue_[q].size.store(size[q], std::memory_order_relaxed);
        queue_[q].state.store(static_cast<uint64_t>(generation) << 32,
                              std::memory_order_release);
      }
    }
    wake_.notify_one();
    if (first != nullptr) (*first)();
    help(generation, 0);   // the chunks left to claim
    // then the worker's last one (a chunk the worker began is finished before the next
    // run is posted: it reads task_ only while it runs one)
    wait_until([&] {
      for (const Queue& q : queue_)
        if (finished_of(q.state.load(std::memory_order_acquire)) <
            q.size.load(std::memory_order_relaxed))
          return false;
      return true;
    });
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
  // (a run's cost counts at most kGiveUp times the mean: a run that the system delayed
  // moves it by kWeight at most; a mode that keeps costing more, by that at every run)
  double& mean = paired ? costs.paired : costs.alone;
  mean = mean == 0.0 ? cost : mean + kWeight * (std::min(cost, kGiveUp * mean) - mean);
  // the mode it leaves (the other one's mean is lower now) is explored again after
  // kExplore runs, not after the runs a burst of it found costlier last time
  if ((costs.paired <= costs.alone) != paired) {
    costs.every = kExplore;
    costs.runs = 0;
  }
}

}  // namespace collres
