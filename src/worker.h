// A second thread for the solver: one persistent worker that helps with the second of two
// independent tasks while the caller runs the first.
//
// The second task comes in `chunks` that must run one after the other, in order (they may
// share data); the first shares nothing with any of them. The worker takes chunks from the
// front while the caller runs the first task; once done with it, the caller takes the
// chunks still left, each after the one before it has finished. So the caller never waits
// for the worker to start (its core busy with another process, or asleep), only, at most,
// for the chunk the worker is running. When that wait takes more than a tenth of a run
// (the worker's core shared with other processes: it was preempted holding a chunk), the
// caller runs the next runs alone, 4 of them, then twice as many after each such wait,
// up to 1024, and halves the count after a run without. The worker spins briefly for the
// next task (the solver posts one per sweep, back to back), then sleeps on a condition
// variable. Results do not depend on which thread runs a chunk.
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
  Worker();
  ~Worker();
  Worker(const Worker&) = delete;
  Worker& operator=(const Worker&) = delete;

  // Runs `first` on this thread and second(0), ..., second(chunks - 1) in that order, on
  // the worker or here; returns when all are done.
  void run_pair(const std::function<void()>& first, const std::function<void(int)>& second,
                int chunks);

  // chunks of the second tasks run so far: by the worker, and by either thread
  uint64_t helped() const { return helped_.load(std::memory_order_relaxed); }
  uint64_t chunks_run() const { return chunks_run_; }

 private:
  void loop();
  // claims and runs chunks of run `generation` until none is left; returns how many
  int help(uint32_t generation);

  // (run generation << 32) | next chunk to claim
  std::atomic<uint64_t> ticket_{0};
  std::atomic<int> done_{0};          // chunks of the current run finished
  std::atomic<int> chunks_{0};        // chunks of the current run
  std::atomic<uint64_t> helped_{0};   // chunks the worker ran
  uint64_t chunks_run_ = 0;           // chunks posted (the caller's thread)
  int alone_ = 0;                     // (the caller's) runs left to run alone
  int backoff_ = 0;                   // (the caller's) runs alone after the next long wait
  const std::function<void(int)>* task_ = nullptr;   // read only with a claimed chunk
  uint32_t generation_ = 0;           // (under mutex_) the run posted last
  bool stop_ = false;                 // (under mutex_)
  std::mutex mutex_;
  std::condition_variable wake_;
  std::thread thread_;                // last: started once the members above exist
};

}  // namespace collres
