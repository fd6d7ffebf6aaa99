// A second thread for the solver: one persistent worker that helps with the second of two
// independent tasks while the caller runs the first.
//
// The second task comes in `chunks` that must run one after the other, in order (they may
// share data); the first shares nothing with any of them. The worker takes chunks from the
// front while the caller runs the first task; once done with it, the caller takes the
// chunks still left, each after the one before it has finished. So the caller never waits
// for the worker to start (its core busy with another process, or asleep), only, at most,
// for the chunk the worker is running. Whether to post to the worker at all is decided by
// what it has cost: the caller keeps, per kind of run, a running mean of the wall time per
// unit of work with the worker and without it, runs in the cheaper mode and, every 17th
// run, in the other one (so a core that becomes busy or free is noticed): on a machine
// whose other core is busy, or with both threads on one core, the caller ends up alone.
// The worker spins briefly for the next task (the solver posts one per sweep, back to
// back), then sleeps on a condition variable. Results do not depend on which thread runs
// a chunk, nor on the mode.
#pragma once

#include <atomic>
#include <condition_variable>
#include <cstdint>
#include <functional>
#include <mutex>
#include <thread>

namespace collres {

class Worker {
 public:
  static constexpr int kMaxChunks = 0xffff;

  Worker();
  ~Worker();
  Worker(const Worker&) = delete;
  Worker& operator=(const Worker&) = delete;

  // Runs `first` on this thread and second(0), ..., second(chunks - 1) in that order, on
  // the worker or here; returns when all are done. 0 <= chunks <= kMaxChunks. `kind` (0 or 1) names the kind of run
  // whose costs are compared, `work` its size (any unit, the same for the kind).
  void run_pair(const std::function<void()>& first, const std::function<void(int)>& second,
                int chunks, int kind, double work);

  // chunks of the second tasks run so far: by the worker, and by either thread
  uint64_t helped() const { return helped_.load(std::memory_order_relaxed); }
  uint64_t chunks_run() const { return chunks_run_; }

 private:
  void loop();
  // claims and runs chunks of run `generation` until none is left; returns how many
  int help(uint32_t generation);

  // (run generation << 32) | (its chunks << 16) | next chunk to claim: one word, so that
  // a claim is checked against the count of its own run (a thread that read a count of
  // the next run with a ticket of the last one would run a chunk twice)
  std::atomic<uint64_t> ticket_{0};
  std::atomic<int> done_{0};          // chunks of the current run finished
  std::atomic<uint64_t> helped_{0};   // chunks the worker ran
  uint64_t chunks_run_ = 0;           // chunks posted (the caller's thread)
  struct Costs {                      // (the caller's) per kind of run
    double alone = 0.0, paired = 0.0;   // s per unit of work, running means (0: none yet)
    unsigned runs = 0;
  };
  Costs costs_[2];
  const std::function<void(int)>* task_ = nullptr;   // read only with a claimed chunk
  uint32_t generation_ = 0;           // (under mutex_) the run posted last
  bool stop_ = false;                 // (under mutex_)
  std::mutex mutex_;
  std::condition_variable wake_;
  std::thread thread_;                // last: started once the members above exist
};

}  // namespace collres
