// A second thread for detection and the solver: one persistent worker that runs, with the
// caller, the `chunks` of a task, each chunk once, claimed in order from the front.
//
// Chunk c starts only once chunks 0 .. gate[c] - 1 have finished (gate[c] <= c, not
// decreasing: the chunks before gate[c] are the ones c depends on; chunks from gate[c] on
// share no data with it). Two uses: run_pair, the second of two independent tasks in
// chunks that run one after the other (gate[c] = c) while the caller runs the first; and
// run_waves, the waves of a velocity sweep (the chunks of one wave share a gate: the
// first chunk of the wave), the caller claiming chunks from the start. A thread claims
// the next chunk only once its gate is open and then runs it at once, so a chunk claimed
// is a chunk begun: the caller never waits for the worker to be scheduled (its core busy
// with another process, or asleep), only, at most, for the one chunk the worker is
// running when the next one depends on it or the run ends. Each thread counts the chunks
// it finished on a cache line of its own (a gate reads both): a chunk costs the two
// cores one claim of the shared ticket and, per gate, the other's count. Whether to post
// to the worker at all is decided by what it has cost: the caller keeps, per kind of
// run, a running mean of the wall time per unit of work with the worker and without it,
// runs in the cheaper mode and, after every 17th run, four runs in the other one, whose
// mean the last three replace (the first wakes the worker, or brings the data back to the
// caller's core: what a mode costs in a row of runs, as the sweeps come, is measured; a
// core that became busy or free is noticed at once), or the first run that costs more
// than twice the chosen mode's mean (then the burst ends there: a loaded machine pays for
// one run); every 34th, 68th, ... up to 1088th run while the other one keeps costing
// more: on a machine whose other core is busy, or with both threads on one core, the
// caller ends up alone. A run of waves none of whose chunks may run beside another (a
// chain) is run here. The worker spins briefly for the next task (the solver posts one
// per sweep, back to back), then sleeps on a condition variable (a sleeping thread woken
// gets its core back sooner than a spinning one that has used up its share of it).
// Results do not depend on which thread runs a chunk, nor on the mode.
#pragma once

#include <atomic>
#include <condition_variable>
#include <cstdint>
#include <functional>
#include <memory>
#include <mutex>
#include <thread>

namespace collres {

class Worker {
 public:
  static constexpr int kMaxChunks = 0xffff;
  static constexpr unsigned kExplore = 17;   // runs of a kind between two in the mode not chosen

  Worker();
  ~Worker();
  Worker(const Worker&) = delete;
  Worker& operator=(const Worker&) = delete;

  // Runs `first` on this thread and second(0), ..., second(chunks - 1) in that order, on
  // the worker or here; returns when all are done. 0 <= chunks <= kMaxChunks. `kind` (0
  // or 1) names the kind of run whose costs are compared, `work` its size (any unit, the
  // same for the kind).
  void run_pair(const std::function<void()>& first, const std::function<void(int)>& second,
                int chunks, int kind, double work);
  // Runs task(0), ..., task(chunks - 1), here and on the worker, chunk c once chunks
  // 0 .. gate[c] - 1 have finished (gate[c] <= c, not decreasing); returns when all are
  // done. A chain (gate[c] = c for every c: one chunk, say), or more than kMaxChunks, all
  // run here, in order.
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
  // claims and runs chunks of run `generation` until none is left to claim, each once its
  // gate is open, counting them in `finished` (this thread's); returns how many it ran
  int help(uint32_t generation, std::atomic<int>& finished);
  // chunks of the current run finished, by both threads
  int done() const {
    return finished_[0].count.load(std::memory_order_acquire) +
           finished_[1].count.load(std::memory_order_acquire);
  }

  // (run generation << 32) | (its chunks << 16) | next chunk to claim: one word, so that
  // a claim is checked against the count of its own run (a thread that read a count of
  // the next run with a ticket of the last one would run a chunk twice)
  alignas(64) std::atomic<uint64_t> ticket_{0};
  // chunks of the current run finished by the caller [0] and by the worker [1], each
  // written by its own thread (and reset by the post), a cache line apart
  struct alignas(64) Finished {
    std::atomic<int> count{0};
  };
  Finished finished_[2];
  alignas(64) std::atomic<uint64_t> helped_{0};   // chunks the worker ran
  uint64_t chunks_run_ = 0;           // chunks posted (the caller's thread)
  struct Costs {                      // (the caller's) per kind of run
    double alone = 0.0, paired = 0.0;   // s per unit of work, running means (0: none yet)
    unsigned runs = 0;                  // since the last runs in the mode not chosen
    unsigned every = kExplore;          // runs between two bursts in the mode not chosen (now)
    int burst = 0;                      // runs left of the burst in that mode (run)
    bool explored = false;              // its mode: paired?
    double sum = 0.0;                   // its runs' costs so far (but the first's) ...
    int measured = 0;                   // ... and their count
  };
  Costs costs_[2];
  const std::function<void(int)>* task_ = nullptr;   // read only with a started chunk
  // per chunk (kMaxChunks): its gate, copied here when the run is posted: a thread whose
  // claim is of a finished run reads no freed memory (and its claim fails)
  std::unique_ptr<std::atomic<int32_t>[]> gate_;
  uint32_t generation_ = 0;           // (under mutex_) the run posted last
  bool stop_ = false;                 // (under mutex_)
  std::mutex mutex_;
  std::condition_variable wake_;
  std::thread thread_;                // last: started once the members above exist
};

}  // namespace collres
