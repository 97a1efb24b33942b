#include "core/thread_pool.h"

#include <chrono>
#include <stdexcept>
#include <string>

namespace palpate {

namespace {

inline void cpu_relax() {
#if defined(__x86_64__) || defined(__i386__)
  __builtin_ia32_pause();
#elif defined(__aarch64__)
  asm volatile("yield");
#endif
}

using Clock = std::chrono::steady_clock;

// Polls done() with pauses for about `microseconds` (the clock read every 64 polls);
// returns whether it came true.
template <class Done>
bool spin_until(const Done& done, int microseconds) {
  const auto deadline = Clock::now() + std::chrono::microseconds(microseconds);
  for (unsigned k = 1;; ++k) {
    if (done()) return true;
    cpu_relax();
    if (k % 64 == 0 && Clock::now() > deadline) return done();
  }
}

}  // namespace

ThreadPool::ThreadPool(int threads, int spin_microseconds) : spin_microseconds_(spin_microseconds) {
  if (threads < 1 || threads > 1024)
    throw std::invalid_argument("ThreadPool: " + std::to_string(threads) + " threads (1 ... 1024)");
  workers_.reserve(static_cast<size_t>(threads - 1));
  for (int t = 1; t < threads; ++t) workers_.emplace_back([this, t] { worker(t); });
}

ThreadPool::~ThreadPool() {
  stop_ = true;  // published by the release of the generation's increment
  generation_.fetch_add(1, std::memory_order_seq_cst);
  generation_.notify_all();
  for (std::thread& w : workers_) w.join();
}

void ThreadPool::run_erased(Function function, void* context) {
  function_ = function;
  context_ = context;
  remaining_.store(static_cast<int>(workers_.size()), std::memory_order_relaxed);
  // The increment publishes the task (release); a worker that reads the new generation
  // (acquire) sees it. A worker that went to sleep before the increment counted itself in
  // sleeping_ first (seq_cst on both sides: either it sees the new generation and does not
  // block, or this load sees it and wakes it).
  generation_.fetch_add(1, std::memory_order_seq_cst);
  if (sleeping_.load(std::memory_order_seq_cst) > 0) generation_.notify_all();
  function(context, 0);
  auto done = [this] { return remaining_.load(std::memory_order_acquire) == 0; };
  if (spin_until(done, spin_microseconds_)) return;
  for (;;) {
    caller_sleeping_.store(true, std::memory_order_seq_cst);
    const int r = remaining_.load(std::memory_order_seq_cst);
    if (r == 0) break;
    remaining_.wait(r, std::memory_order_seq_cst);
  }
  caller_sleeping_.store(false, std::memory_order_relaxed);
}

void ThreadPool::worker(int index) {
  uint32_t seen = 0;  // the pool is built with generation 0 and no task
  for (;;) {
    auto changed = [&] { return generation_.load(std::memory_order_acquire) != seen; };
    while (!spin_until(changed, spin_microseconds_)) {
      sleeping_.fetch_add(1, std::memory_order_seq_cst);
      generation_.wait(seen, std::memory_order_seq_cst);
      sleeping_.fetch_sub(1, std::memory_order_relaxed);
    }
    seen = generation_.load(std::memory_order_acquire);
    if (stop_) return;
    function_(context_, index);
    // The last worker to finish wakes the caller if it went to sleep (the same pairing as
    // above, on remaining_ and caller_sleeping_).
    if (remaining_.fetch_sub(1, std::memory_order_seq_cst) == 1 && caller_sleeping_.load(std::memory_order_seq_cst))
      remaining_.notify_all();
  }
}

void WorkerThreads::resize(int threads, int particles) {
  if (threads < 1 || threads > kMaxThreads)
    throw std::invalid_argument("threads: " + std::to_string(threads) + " (1 ... " + std::to_string(kMaxThreads) + ")");
  if (threads != count()) pool = threads > 1 ? std::make_unique<ThreadPool>(threads) : nullptr;
  this->particles = particles;
  (void)row_buffers(row_buffers_needed(threads), particles);
}

double* WorkerThreads::row_buffers(int count, int particles) {
  const size_t needed = 4 * static_cast<size_t>(count) * static_cast<size_t>(particles) + 4;
  if (rows.size() < needed) rows.assign(needed, 0.0);  // assign: every page touched now
  double* p = rows.data();
  return p + (4 - reinterpret_cast<uintptr_t>(p) / sizeof(double) % 4) % 4;  // 32-byte aligned
}

}  // namespace palpate
