#include "server/haptic_loop.h"

#include <pthread.h>
#include <sched.h>
#include <sys/prctl.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>

#include "protocol/local_model.h"
#include "server/deadlines.h"

namespace palpate::server {

bool saturate(Vec3& f, double max_force) { return protocol::saturate_force(f.data(), max_force); }

RenderInput render_input_of(const Snapshot& step) {
  RenderInput in;
  in.valid = true;
  in.render_model = step.render_model;
  in.render_force = step.render_force;
  in.force_saturated = step.force_saturated;
  in.target = step.target;
  in.position_mode = step.position_mode;
  in.tick = step.tick;
  in.publish_ns = step.publish_ns;
  in.command_seq = step.command_seq;
  return in;
}

HapticSample render_sample(const RenderInput& model, const DeviceInput& device, double max_force) {
  HapticSample s;
  s.model_tick = model.tick;
  s.model_publish_ns = model.publish_ns;
  s.command_seq = model.command_seq;
  if (model.position_mode) {
    // A setPosition newer than the step's is rendered at once; an older one (or none)
    // is already in the step: its own target.
    const bool newer = device.seq > model.command_seq;
    s.target = newer ? device.target : model.target;
    s.render_force = model.render_model.force_at(s.target, max_force, &s.force_saturated);  // (P.0)
    if (newer) s.command_seq = device.seq;
  } else {
    s.target = model.target;
    s.render_force = model.render_force;
    s.force_saturated = model.force_saturated;
  }
  return s;
}

HapticRenderer::HapticRenderer(double rate_hz, double max_force, double spin_margin_us, bool try_realtime,
                               int wake_fd, const RpcHeartbeat* rpc_heartbeat)
    : rate_hz_(rate_hz),
      max_force_(max_force),
      spin_margin_us_(spin_margin_us),
      try_realtime_(try_realtime),
      wake_fd_(wake_fd),
      rpc_heartbeat_(rpc_heartbeat) {
  TripleBuffer<RenderInput> models;
  model_writer_ = std::move(models.writer);
  model_reader_ = std::move(models.reader);
  TripleBuffer<DeviceInput> devices;
  device_writer_ = std::move(devices.writer);
  device_reader_ = std::move(devices.reader);
  TripleBuffer<HapticSample> samples;
  samples_writer_ = std::move(samples.writer);
  samples_reader_ = std::move(samples.reader);
  thread_ = std::thread([this] { run(); });
}

HapticRenderer::~HapticRenderer() {
  stop_.store(true);
  if (thread_.joinable()) thread_.join();
}

void HapticRenderer::offer_model(const RenderInput& input) {
  model_writer_.back() = input;
  model_writer_.publish();
}

void HapticRenderer::offer_device(const Vec3& target, uint64_t seq) {
  device_writer_.back() = DeviceInput{target, seq};
  device_writer_.publish();
}

HapticCounters HapticRenderer::counters() const {
  HapticCounters c;
  c.ticks = ticks_.load(std::memory_order_relaxed);
  c.misses = misses_.load(std::memory_order_relaxed);
  c.watchdog_rests = watchdog_rests_.load(std::memory_order_relaxed);
  c.lateness_us = lateness_us_.summary();
  c.model_age_us = model_age_us_.summary();
  return c;
}

void HapticRenderer::run() {
  prctl(PR_SET_TIMERSLACK, 1UL, 0, 0, 0);
  sched_param param{};
  bool realtime = false;
  if (try_realtime_) {
    param.sched_priority = 11;  // above the session's loop (10): a render tick is microseconds
    realtime = pthread_setschedparam(pthread_self(), SCHED_FIFO, &param) == 0;
  } else {
    pthread_setschedparam(pthread_self(), SCHED_OTHER, &param);
  }
  Deadlines deadlines(static_cast<int64_t>(std::llround(1e9 / rate_hz_)),
                      static_cast<int64_t>(spin_margin_us_ * 1000.0));
  if (realtime) deadlines.give_way_to(rpc_heartbeat_);
  deadlines.start();
  int64_t tick = 0;
  while (!stop_.load(std::memory_order_relaxed)) {
    const int64_t start = deadlines.wait();
    lateness_us_.add((start - deadlines.deadline()) * 1e-3);
    model_reader_.take();
    device_reader_.take();
    const RenderInput& model = model_reader_.front();
    if (model.valid) {
      HapticSample& s = samples_writer_.back();
      s = render_sample(model, device_reader_.front(), max_force_);
      s.haptic_tick = tick++;
      s.haptic_misses = misses_.load(std::memory_order_relaxed);
      s.publish_ns = now_ns();
      model_age_us_.add((s.publish_ns - model.publish_ns) * 1e-3);
      samples_writer_.publish();
      ticks_.store(tick, std::memory_order_relaxed);
      const uint64_t one = 1;
      [[maybe_unused]] const ssize_t r = write(wake_fd_, &one, sizeof one);  // never blocks (EFD_NONBLOCK)
    }
    const Deadlines::Outcome o = deadlines.finish(start);
    if (o.missed) misses_.fetch_add(1, std::memory_order_relaxed);
    if (o.watchdog_rest) watchdog_rests_.fetch_add(1, std::memory_order_relaxed);
  }
}

}  // namespace palpate::server
