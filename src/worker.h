// A second thread for detection and the solver: one persistent worker that runs, with the
// caller, the `chunks` of a task, each chunk once.
//
// The chunks are in two queues: queue 0 the caller's, queue 1 the worker's. A queue's
// chunks run one at a time, in order, and chunk c of a queue starts only once `need[c]`
// chunks of the other queue have finished (the ones it depends on: the other queue's
// chunks from need[c] on share no data with it). Each thread runs the chunks of its own
// queue; a thread whose next chunk is not ready (or whose queue is done) runs the other
// queue's next chunk if it is ready and nobody runs one of that queue (the other thread
// descheduled, asleep, or behind; not while the other thread runs a chunk of its own
// queue: the two then ran each other's chunks, each after the polls of Worker::help's
// patience), so the caller never waits for the worker to be scheduled, only, at most, for
// the one chunk the worker is running when the next one depends on it or the run ends.
// Each queue's state (its run, chunks claimed, chunks finished) is one word on a cache
// line of its own, written by the thread that claims or finishes a chunk of it: a thread
// that keeps to its own queue claims its chunks on its own line, and a chunk costs the two
// cores, per gate, the other's word. A task whose
// chunks touch data by queue (the sweeps: each thread the same bodies sweep after sweep)
// keeps that data in its thread's cache.
//
// Whether to post to the worker at all is decided by what it has cost: the caller keeps,
// per kind of run, a running mean of the wall time per unit of work with the worker and
// without it, runs in the cheaper mode and, after every 17th run, four runs in the other
// one, whose mean the last three replace (the first wakes the worker, or brings the data
// back to the caller's core: what a mode costs in a row of runs, as the sweeps come, is
// measured; a core that became busy or free is noticed at once), or the first run that
// costs more than twice the chosen mode's mean (then the burst ends there: a loaded
// machine pays for one run); every 34th, 68th, ... up to 1088th run while the other one
// keeps costing more: on a machine whose other core is busy, or with both threads on one
// core, the caller ends up alone, running the chunks in their order (0, 1, ...: it must
// be one in which each chunk follows the ones it depends on). A run counts in the chosen
// mode's mean at most kGiveUp times that mean (one run the system delayed does not turn
// the choice), and when the means turn the choice the mode left is explored again after 17
// runs. A kind's runs should cost alike per unit of work in each mode (a solve's first
// sweep, which readies its groups, is a kind apart). A run with nothing in one of the
// queues and no first task is run here. The worker spins briefly for the next task (the
// solver posts one per sweep, back to back), then sleeps on a condition variable (a
// sleeping thread woken gets its core back sooner than a spinning one that has used up its
// share of it); between stay(true) and stay(false) (a solver step, whose stages between
// its runs last 0.1-1.5 ms on 1000 bodies, where a wake costs ~0.1 ms) it spins on,
// yielding its core now and then, while a kind of run is chosen paired. A worker that
// finds itself, at a run's start, on the core the caller posted it from (the kernel
// places a woken thread on its waker's core when it sees no idle one: the two then take
// turns on one core, and the run costs what it costs alone; a caller that slept between
// its steps, a node paced at 30 Hz, found its worker there in 72-100 % of its detections)
// moves to another core the process may run on, at once (its affinity without that core,
// then as it was: the kernel migrates it, and it runs there or waits its turn; the next
// wake places it on that core again, its last one, when it is idle). Results do not
// depend on which thread runs a chunk, nor on the mode.
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
  static constexpr int kMaxChunks = 0xffff;  // per queue
  static constexpr unsigned kExplore = 17;   // runs of a kind between two in the mode not chosen
  static constexpr int kKinds = 6;           // kinds of run (costs compared apart)

  Worker();
  ~Worker();
  Worker(const Worker&) = delete;
  Worker& operator=(const Worker&) = delete;

  // Runs `first` on this thread and second(0), ..., second(chunks - 1) in that order, on
  // the worker or here; returns when all are done. 0 <= chunks <= kMaxChunks. `kind` (0
  // to kKinds - 1) names the kind of run whose costs are compared, `work` its size (any
  // unit, the same for the kind).
  void run_pair(const std::function<void()>& first, const std::function<void(int)>& second,
                int chunks, int kind, double work);
  // Runs task(0), ..., task(chunks - 1), chunk c in queue side[c] (0 or 1), once need[c]
  // chunks of the other queue have finished; returns when all are done. The chunks of a
  // queue, in their order, and `need` must leave each chunk after the ones it depends on
  // in the order 0, 1, ... (need[c] counts the other queue's chunks before c at most). A
  // run with an empty queue, or more than kMaxChunks in one, runs here, in order; one
  // with chunks in queue 0 only (built for one thread: pairs(kind) was false when its
  // caller cut its chunks) counts in the kind's cost alone, unless the kind's next run is
  // to run paired (the mode turned, or a burst of paired runs is due, since): then it
  // counts nowhere, and the burst waits for a run that can pair. Either counts in no
  // runs() or chunks_run() (it is not posted for two threads).
  void run_sides(const std::function<void(int)>& task, int chunks, const uint8_t* side,
                 const int32_t* need, int kind, double work);

  // whether the next run of `kind` runs paired (in a burst: the burst's mode; a burst of
  // paired runs starts at a run cut for one thread and waits, run_sides): for a caller
  // that cuts a run's chunks for two threads or for one (sweep_waves.h: a sweep cut for
  // one thread costs less than its two sides run alone)
  bool pairs(int kind) const;

  // on: the worker spins between runs (yielding its core now and then) until stay(false),
  // instead of sleeping after a few polls, and is woken now, so that its wake (~0.1 ms on
  // a virtual machine) overlaps the caller's work before the first run: for a caller that
  // posts runs with stages of its own between them (a solver step: a run per sweep, and
  // its per-contact passes). Only while a kind of run is chosen paired; else it sleeps.
  void stay(bool on);

  // chunks of the second tasks run so far: by the worker, and by either thread
  uint64_t helped() const { return helped_.load(std::memory_order_relaxed); }
  uint64_t chunks_run() const { return chunks_run_; }
  // runs posted so far for two threads (a run with a chunk in each queue, or a first task
  // and chunks), and of those the ones the cost model ran paired (the worker woken)
  uint64_t runs() const { return runs_; }
  uint64_t paired_runs() const { return paired_runs_; }

 private:
  void loop();
  // runs `first` here and the chunks of `task` here and on the worker (run_pair, run_sides)
  // (lone: a run cut for one thread, run here)
  void run(const std::function<void()>* first, const std::function<void(int)>& task,
           int chunks, const uint8_t* side, const int32_t* need, int kind, double work,
           bool lone);
  // claims and runs chunks of run `generation`, its own queue's first (`own`), until none
  // is left to claim, each once it is ready; returns how many it ran
  int help(uint32_t generation, int own);

  // per queue: (run generation << 32) | (chunks claimed << 16) | chunks finished: one
  // word, so that a claim is checked against its run (a thread that read a count of the
  // next run with a claim of the last one would run a chunk twice) and against the
  // queue's chunk running (claimed == finished: none); a cache line each
  struct alignas(64) Queue {
    std::atomic<uint64_t> state{0};
    std::atomic<int32_t> size{0};   // chunks of the current run
  };
  Queue queue_[2];
  alignas(64) std::atomic<uint64_t> helped_{0};   // chunks the worker ran
  uint64_t chunks_run_ = 0;           // chunks posted (the caller's thread)
  uint64_t runs_ = 0, paired_runs_ = 0;   // (the caller's) runs(), paired_runs()
  // the core the caller posted the last paired run from (-1: unknown), read by the worker
  std::atomic<int> caller_core_{-1};
  struct Costs {                      // (the caller's) per kind of run
    double alone = 0.0, paired = 0.0;   // s per unit of work, running means (0: none yet)
    unsigned runs = 0;                  // since the last runs in the mode not chosen
    unsigned every = kExplore;          // runs between two bursts in the mode not chosen (now)
    int burst = 0;                      // runs left of the burst in that mode (run)
    bool explored = false;              // its mode: paired?
    double sum = 0.0;                   // its runs' costs so far (but the first's) ...
    int measured = 0;                   // ... and their count
  };
  Costs costs_[kKinds];
  const std::function<void(int)>* task_ = nullptr;   // read only with a started chunk
  // per queue and place in it (kMaxChunks each): the chunk and its need, copied here when
  // the run is posted: a thread whose claim is of a finished run reads no freed memory
  // (and its claim fails)
  std::unique_ptr<std::atomic<int32_t>[]> chunk_[2], need_[2];
  uint32_t generation_ = 0;           // (under mutex_) the run posted last
  bool stop_ = false;                 // (under mutex_)
  std::atomic<bool> stay_{false};     // stay(true) on (written under mutex_)
  std::mutex mutex_;
  std::condition_variable wake_;
  std::thread thread_;                // last: started once the members above exist
};

}  // namespace collres
