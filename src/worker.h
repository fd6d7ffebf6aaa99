// A second thread for the solver: one persistent worker that runs the second of two
// independent tasks while the caller runs the first.
//
// The caller never waits for the worker to start: when it finishes its own task before the
// worker has taken the other one (the worker asleep, or its core busy with another
// process), it runs that one itself. It waits only for a task the worker has begun. The
// worker spins briefly for the next task (the solver posts one per sweep, back to back),
// then sleeps on a condition variable. Results do not depend on which thread runs a task:
// the two tasks must touch disjoint data (the solver's halves share no movable body).
#pragma once

#include <atomic>
#include <condition_variable>
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

  // Runs `first` on this thread and `second` on the worker (or here, after `first`, when
  // the worker has not taken it yet); returns when both are done.
  void run_pair(const std::function<void()>& first, const std::function<void()>& second);

 private:
  enum State : int { kIdle = 0, kPosted = 1, kTaken = 2, kDone = 3 };
  void loop();

  std::atomic<int> state_{kIdle};
  const std::function<void()>* task_ = nullptr;
  bool stop_ = false;                 // (under mutex_)
  std::mutex mutex_;
  std::condition_variable wake_;
  std::thread thread_;                // last: started once the members above exist
};

}  // namespace collres
