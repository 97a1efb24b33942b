#include "server/deadlines.h"

#include <time.h>

#include <cerrno>

namespace palpate::server {

int64_t now_ns() {
  timespec ts;
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return static_cast<int64_t>(ts.tv_sec) * 1000000000 + ts.tv_nsec;
}

void sleep_until_ns(int64_t t) {
  timespec ts{static_cast<time_t>(t / 1000000000), static_cast<long>(t % 1000000000)};
  while (clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &ts, nullptr) == EINTR) {
  }
}

void cpu_relax() {
#if defined(__x86_64__) || defined(__i386__)
  __builtin_ia32_pause();
#endif
}

Deadlines::Deadlines(int64_t period, int64_t spin_margin, int64_t watchdog_window, int64_t watchdog_rest)
    : period_(period), margin_(spin_margin), watchdog_window_(watchdog_window), watchdog_rest_(watchdog_rest) {}

void Deadlines::start() {
  const int64_t now = now_ns();
  deadline_ = now + period_;
  last_rest_ = now;
}

int64_t Deadlines::wait() {
  int64_t now = now_ns();
  if (now < deadline_ - margin_) {
    sleep_until_ns(deadline_ - margin_);
    last_rest_ = now_ns();
  } else if (now < deadline_) {
    last_rest_ = now;  // it spins, but is in time: not starving anyone for long
  }
  while ((now = now_ns()) < deadline_) cpu_relax();
  return now;
}

Deadlines::Outcome Deadlines::finish(int64_t tick_start) {
  Outcome o;
  int64_t end = now_ns();
  deadline_ += period_;
  if (end - last_rest_ > watchdog_window_) {
    // Behind for the whole window without a sleep: a SCHED_FIFO loop would keep its core
    // from every other thread. Rest, and let the deadlines below account for it.
    sleep_until_ns(end + watchdog_rest_);
    end = now_ns();
    last_rest_ = end;
    o.watchdog_rest = true;
  }
  if (heartbeat_ != nullptr && end - heartbeat_->last_ns.load(std::memory_order_relaxed) > RpcHeartbeat::kStarvedNs) {
    // The RPC thread has not run for kStarvedNs: give way until it has (bounded).
    const int64_t give_up = end + kMaxGiveWayNs;
    while (end < give_up && end - heartbeat_->last_ns.load(std::memory_order_relaxed) > RpcHeartbeat::kStarvedNs) {
      sleep_until_ns(end + 1'000'000);
      end = now_ns();
    }
    last_rest_ = end;
    o.watchdog_rest = true;
  }
  if (end > deadline_) {
    o.missed = true;
    o.late_start = tick_start - (deadline_ - period_) > period_ / 2;
    if (end > deadline_ + period_) {  // over a full period behind: abandon deadlines, keep the phase grid
      const int64_t behind = (end - deadline_) / period_;
      deadline_ += behind * period_;
      o.skipped = behind;
    }
  }
  return o;
}

}  // namespace palpate::server
