// A second thread for detection and the solver: one persistent worker that runs, with the
// caller, the `chunks` of a task, each chunk once, claimed in order from the front.
//
// Chunk c starts only once chunks 0 .. gate[c] - 1 have finished (gate[c] <= c, not
// decreasing: the chunks before gate[c] are the ones c depends on; chunks from gate[c] on
// share no data with it). Two uses: run_pair, the second of two independent tasks in
// chunks that run one after the other (gate[c] = c) while the caller runs the first; and
// run_waves, the waves of a velocity sweep (the chunks of one wave share a gate: the
// first chunk of the wave), the caller claiming chunks from the start. Either way the
// caller takes every chunk the worker has not claimed, so it never waits for the worker
// to start (its core busy with another process, or asleep), only, at most, for a chunk
// the worker is running that the next one depends on. Whether to post to the worker at all is decided by
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
  // Runs task(0), ..., task(chunks - 1), here and on the worker, chunk c once chunks
  // 0 .. gate[c] - 1 have finished (gate[c] <= c, not decreasing); returns when all are
  // done. One chunk, or more than kMaxChunks, all run here, in order.
  void run_waves(const std::function<void(int)>& task, int chunks, const int32_t* gate,
                 int kind, double work);

  // chunks of the second tasks run so far: by the worker, and by either thread
  uint64_t helped() const { return helped_.load(std::memory_order_relaxed); }
  uint64_t chunks_run() const { return chunks_run_; }

 private:
  void loop();
  // runs `first` here and the chunks of `task` here and on the worker (run_pair, run_waves)
  void run(const std::function<void()>* first, const std::function<void(int)>& task,
           int chunks, const int32_t* gate, int kind, double work);
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
  const int32_t* gate_ = nullptr;     // (of task_) null: gate[c] = c
  uint32_t generation_ = 0;           // (under mutex_) the run posted last
  bool stop_ = false;                 // (under mutex_)
  std::mutex mutex_;
  std::condition_variable wake_;
  std::thread thread_;                // last: started once the members above exist
};

}  // namespace collres
