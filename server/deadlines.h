#pragma once
// The pacing of a fixed-rate real-time loop on absolute deadlines, shared by the
// session's loop (sim_loop.h) and the multirate force renderer (haptic_loop.h):
// sleep to a margin before each deadline, spin the rest; count a tick that ends
// after the next deadline as a miss, by cause; abandon deadlines more than a period
// behind (keeping the phase grid); and a watchdog for a SCHED_FIFO loop that never
// sleeps, which would starve every other thread of its core (the RPC thread could
// then answer nothing, not even a SIGTERM), with its server-wide part: every loop gives
// way while the RPC thread has not run for a while (RpcHeartbeat).
#include <atomic>
#include <cstdint>

namespace palpate::server {

int64_t now_ns();  // CLOCK_MONOTONIC
void sleep_until_ns(int64_t t);
void cpu_relax();

// When the RPC thread last ran: it stamps `last_ns` every kPeriodNs from a timer of its
// event loop, so a stamp older than kStarvedNs means the thread is kept from its core
// (it runs below the loops' SCHED_FIFO priority). Shared by every real-time loop of the
// server (Deadlines::give_way_to).
struct RpcHeartbeat {
  static constexpr int64_t kPeriodNs = 2'000'000;
  static constexpr int64_t kStarvedNs = 10'000'000;
  std::atomic<int64_t> last_ns{0};
};

class Deadlines {
 public:
  // period and spin margin in ns. The watchdog: when the loop has not slept for
  // `watchdog_window` ns (it has been behind its deadlines all that time), it sleeps
  // `watchdog_rest` ns at the end of the tick.
  Deadlines(int64_t period, int64_t spin_margin, int64_t watchdog_window = 20'000'000,
            int64_t watchdog_rest = 2'000'000);

  // The loop gives way to the RPC thread (a SCHED_FIFO loop only; null: never): at the end
  // of a tick after which `heartbeat` is older than RpcHeartbeat::kStarvedNs, it sleeps
  // in steps of a millisecond until the RPC thread has stamped it again (at most
  // kMaxGiveWayNs a tick). Every loop of the server does so, so together they leave the
  // core to the RPC thread, and close(), stats() and the health probes are answered
  // while the loops are behind; the ticks lost count as misses and watchdog rests.
  void give_way_to(const RpcHeartbeat* heartbeat) { heartbeat_ = heartbeat; }
  static constexpr int64_t kMaxGiveWayNs = 20'000'000;

  // The first deadline is one period after now.
  void start();
  // Waits for the next deadline (sleeps to the spin margin before it, then spins);
  // returns the tick's start time.
  int64_t wait();

  struct Outcome {
    bool missed = false;      // the tick ended after the next tick's deadline
    bool late_start = false;  // of a miss: the tick started over half a period late (the host's)
    int64_t skipped = 0;      // deadlines abandoned (over a full period behind)
    bool watchdog_rest = false;  // the watchdog made the loop sleep
  };
  // After the tick's work: `tick_start` from wait(). Advances the deadline.
  Outcome finish(int64_t tick_start);

  int64_t deadline() const { return deadline_; }  // the current tick's, until finish()

 private:
  int64_t period_, margin_, watchdog_window_, watchdog_rest_;
  int64_t deadline_ = 0;
  int64_t last_rest_ = 0;  // when the loop last slept
  const RpcHeartbeat* heartbeat_ = nullptr;
};

}  // namespace palpate::server
