#pragma once
// A small persistent worker pool for the step's parallel loops (Options' integrator.threads):
// size() - 1 worker threads and the calling thread, which takes part. run(task) calls
// task(t) once for every t in [0, size()) -- t = 0 on the caller, t >= 1 on worker t -- and
// returns when all have returned. A dispatch allocates nothing and takes no lock: the caller
// bumps a generation counter; a worker spins on it for a short while after its last task
// (so the dispatches of one step find it awake), then sleeps on it (C++20 atomic wait, a
// futex on Linux). Which part of the work task(t) does is the task's business: the loops
// that use the pool split their work statically by t, so a result depends on the thread
// count only, never on timing.
//
// Not re-entrant: one run at a time, from one thread at a time (the pool belongs to one
// State). A task must not throw (a worker's exception terminates the program).
#include <algorithm>
#include <atomic>
#include <cstdint>
#include <memory>
#include <thread>
#include <type_traits>
#include <vector>

#include "core/types.h"

namespace palpate {

class ThreadPool {
 public:
  // threads >= 1 (1: no workers, run() calls task(0) on the caller). spin_microseconds:
  // how long a worker keeps polling for the next task before it sleeps.
  explicit ThreadPool(int threads, int spin_microseconds = 50);
  ~ThreadPool();  // wakes the workers and joins them
  ThreadPool(const ThreadPool&) = delete;
  ThreadPool& operator=(const ThreadPool&) = delete;

  int size() const { return static_cast<int>(workers_.size()) + 1; }

  // Calls task(t) for t = 0 ... size() - 1, t = 0 on the calling thread; returns when every
  // call has returned (their writes are then visible to the caller).
  template <class Task>
  void run(Task&& task) {
    if (workers_.empty()) return task(0);
    run_erased(&call<std::remove_reference_t<Task>>, const_cast<void*>(static_cast<const void*>(&task)));
  }

 private:
  using Function = void (*)(void*, int);
  template <class Task>
  static void call(void* task, int t) {
    (*static_cast<Task*>(task))(t);
  }
  void run_erased(Function function, void* context);
  void worker(int index);

  std::vector<std::thread> workers_;
  const int spin_microseconds_;
  // The task of the current generation; written by the caller before it bumps generation_.
  Function function_ = nullptr;
  void* context_ = nullptr;
  bool stop_ = false;
  alignas(64) std::atomic<uint32_t> generation_{0};
  alignas(64) std::atomic<int> sleeping_{0};   // workers asleep (or about to be) on generation_
  alignas(64) std::atomic<int> remaining_{0};  // workers still running the current task
  std::atomic<bool> caller_sleeping_{false};
};

// The threads of one State's loops (Workspace::threads): the pool of Options'
// integrator.threads, and the scratch of the blocked MLS loops (mls_loops.h): on one
// thread, positions and forces as padded rows (x, y, z, 0 per particle, 32-byte aligned;
// two buffers, six for three directions at once); on T threads, the force buffers of
// threads 1 ... T - 1 (thread 0 accumulates into the result, then the buffers are added
// into it in a fixed order).
// A copy of a Workspace gets no threads (it makes its own at its first step: a pool
// belongs to one State); assigning one keeps the target's.
struct WorkerThreads {
  std::unique_ptr<ThreadPool> pool;  // null: one thread, the caller's
  std::vector<double> rows;          // the loops' scratch (row_buffers); grown, never shrunk
  int particles = 0;                 // what resize() sized rows for

  WorkerThreads() = default;
  explicit WorkerThreads(int threads, int particles = 0) { resize(threads, particles); }
  WorkerThreads(const WorkerThreads&) {}
  WorkerThreads& operator=(const WorkerThreads&) { return *this; }
  WorkerThreads(WorkerThreads&&) noexcept = default;
  WorkerThreads& operator=(WorkerThreads&&) noexcept = default;

  int count() const { return pool ? pool->size() : 1; }
  // Makes the pool `threads` strong (a new one only if the count changes; 1: none) and
  // sizes the scratch for `particles` (allocates and touches it only when either grows), so
  // that no step allocates.
  void resize(int threads, int particles);
  // `count` buffers of 4 x particles doubles each, consecutive, the first 32-byte aligned
  // (grows the scratch if it is smaller: only a caller that skipped resize()).
  double* row_buffers(int count, int particles);
};

// Buffers the loops take at most: the threads' but the first, or the rows of up to three
// directions and their forces (mls_force_differentials).
inline int row_buffers_needed(int threads) { return std::max(threads - 1, 6); }

// The largest thread count the scenes and options accept (integrator.threads).
constexpr int kMaxThreads = 64;

}  // namespace palpate
