// The haptic client loop against a real-time session (clients/haptic.h, run_palpation):
// commands at the tick rate, a servo loop rendering the newest frame's local model, and
// the measurements of clients/haptic.cpp fed from the frames as they come.
#include "clients/haptic.h"

#include <pthread.h>
#include <sched.h>
#include <time.h>

#include <algorithm>
#include <cmath>
#include <memory>
#include <stdexcept>

#include <kj/debug.h>

namespace palpate::haptic {

namespace {

int64_t monotonic_ns() {
  timespec ts{};
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return static_cast<int64_t>(ts.tv_sec) * 1000000000 + ts.tv_nsec;
}

void sleep_until_ns(int64_t deadline) {
  timespec ts{};
  ts.tv_sec = static_cast<time_t>(deadline / 1000000000);
  ts.tv_nsec = static_cast<long>(deadline % 1000000000);
  while (clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &ts, nullptr) == EINTR) {
  }
}

// What the sink hands to the loop; shared, because the sink may outlive the loop
// (frames already on their way when the subscription is cancelled).
struct Inbox {
  bool active = true;
  bool have = false;
  size_t frames = 0;
  int64_t t0 = 0;        // path start, ns (0: not started)
  RenderingError::Frame newest{};
  V3 tool{0, 0, 0}, contact{0, 0, 0};
  LatencyTracker* latency = nullptr;
  RenderingError* errors = nullptr;
  const PalpationPath* path = nullptr;
  std::vector<double>* model_age_ms = nullptr;
  std::vector<double>* stiffness_age_ticks = nullptr;
  std::vector<double>* stiffness_age_touching_ticks = nullptr;
  size_t touching_without_stiffness = 0;  // frames with a contact force and no K yet
  std::vector<Result::Served>* served = nullptr;
  uint64_t deadline_misses = 0;  // the newest frame's Frame.deadlineMisses
};

class Sink final : public wire::FrameSink::Server {
 public:
  explicit Sink(std::shared_ptr<Inbox> inbox) : inbox_(std::move(inbox)) {}

 protected:
  kj::Promise<void> frame(FrameContext context) override {
    Inbox& in = *inbox_;
    if (!in.active) return kj::READY_NOW;
    const int64_t now = monotonic_ns();
    auto f = context.getParams().getFrame();
    in.newest.tick = f.getTick();
    in.newest.position_mode = f.getMode() == wire::ControlMode::POSITION;
    in.newest.target = vec3_of(f.getTarget());
    in.newest.render_force = vec3_of(f.getRenderForce());
    in.newest.render_model = local_model_of(f.getRenderModel());
    in.newest.publish_ns = f.getPublishNs();
    in.tool = vec3_of(f.getIndenterPosition());
    in.contact = vec3_of(f.getToolContactForce());
    in.have = true;
    in.deadline_misses = std::max(in.deadline_misses, f.getDeadlineMisses());
    if (in.t0 != 0) {
      ++in.frames;
      const double t = static_cast<double>(now - in.t0) * 1e-9;
      in.latency->on_frame(f.getCommandSeq(), t);
      if (f.getHapticTick() >= 0 && in.model_age_ms->size() < in.model_age_ms->capacity())
        in.model_age_ms->push_back(static_cast<double>(f.getModelAgeNs()) * 1e-6);
      const LocalModel& lm = in.newest.render_model;
      const bool touching = lm.force[0] != 0 || lm.force[1] != 0 || lm.force[2] != 0;
      if (lm.stiffness_tick >= 0 && in.stiffness_age_ticks->size() < in.stiffness_age_ticks->capacity()) {
        const double age = static_cast<double>(in.newest.tick - lm.stiffness_tick);
        in.stiffness_age_ticks->push_back(age);
        if (touching) in.stiffness_age_touching_ticks->push_back(age);  // same capacity, never more
      } else if (lm.stiffness_tick < 0 && touching) {
        ++in.touching_without_stiffness;
      }
      if (f.getHapticTick() >= 0 && in.served->size() < in.served->capacity())
        in.served->push_back({f.getHapticTick(), in.newest.target, in.newest.render_force, t});
      in.errors->on_frame(in.newest, in.path->segment_at(t));
    }
    return kj::READY_NOW;
  }
  kj::Promise<void> done(DoneContext) override { return kj::READY_NOW; }

 private:
  std::shared_ptr<Inbox> inbox_;
};

struct IgnoreErrors final : public kj::TaskSet::ErrorHandler {
  void taskFailed(kj::Exception&&) override {}
};

}  // namespace

Result run_palpation(wire::Session::Client session, wire::SessionInfo::Reader info, kj::WaitScope& ws,
                     const Config& config, const std::function<void(const ServoSample&, const char*)>& live) {
  if (!(config.servo_hz > 0 && config.servo_hz <= 100000))
    throw std::invalid_argument("haptic: servo rate: must be in (0, 100000] Hz");
  if (!(config.seconds > 0 && std::isfinite(config.seconds)))
    throw std::invalid_argument("haptic: seconds: must be a positive number");
  if (info.getHeadless() || !(info.getRateHz() > 0))
    throw std::invalid_argument("haptic: the session must be real time (SessionInfo.rateHz > 0)");
  const Geometry geometry = geometry_of(info);
  const double max_force = info.getDevice().getMaxForce();
  // Multirate: a command per render tick (the server renders each at once).
  const double command_rate = info.getHapticRateHz() > 0 ? info.getHapticRateHz() : info.getRateHz();
  const int64_t command_period = static_cast<int64_t>(std::llround(1e9 / command_rate));
  const int64_t servo_period = static_cast<int64_t>(std::llround(1e9 / config.servo_hz));

  auto inbox = std::make_shared<Inbox>();
  auto sub = session.subscribeRequest();
  sub.setSink(kj::heap<Sink>(inbox));
  sub.getOptions().setRateHz(0);  // every tick, scalars only
  auto subscription = sub.send().wait(ws).getSubscription();

  // The path starts where the tool is.
  for (const int64_t until = monotonic_ns() + 10 * 1000000000LL; !inbox->have;) {
    if (monotonic_ns() > until) throw std::runtime_error("haptic: no frame from the session within 10 s");
    sleep_until_ns(monotonic_ns() + 1000000);
    ws.poll();
  }
  PalpationPath path(geometry, inbox->tool, config.seconds, config.depth);
  LatencyTracker latency;
  RenderingError errors(path.segments().size(), max_force,
                        static_cast<int64_t>(std::llround(1e9 / info.getRateHz())));
  const size_t ticks = static_cast<size_t>(config.seconds * command_rate) + 16;
  latency.reserve(ticks);
  errors.reserve(ticks);
  std::vector<double> model_age_ms;
  model_age_ms.reserve(2 * ticks);
  inbox->model_age_ms = &model_age_ms;
  std::vector<double> stiffness_age_ticks;
  stiffness_age_ticks.reserve(2 * ticks);
  inbox->stiffness_age_ticks = &stiffness_age_ticks;
  std::vector<double> stiffness_age_touching_ticks;
  stiffness_age_touching_ticks.reserve(2 * ticks);
  inbox->stiffness_age_touching_ticks = &stiffness_age_touching_ticks;
  Result result;
  if (info.getHapticRateHz() > 0) result.served.reserve(2 * ticks);
  inbox->served = &result.served;
  result.segments = path.segments();
  const size_t servo_ticks = static_cast<size_t>(config.seconds * config.servo_hz) + 16;
  if (config.record_servo) result.servo.reserve(servo_ticks);
  std::vector<double> wake_us;
  wake_us.reserve(servo_ticks);

  IgnoreErrors ignore;
  kj::TaskSet tasks(ignore);
  kj::Maybe<kj::Exception> refusal;

  // A haptic front-end runs real time: SCHED_FIFO 5 when allowed (restored at the end).
  int old_policy = SCHED_OTHER;
  sched_param old_param{};
  pthread_getschedparam(pthread_self(), &old_policy, &old_param);
  if (config.realtime) {
    sched_param param{};
    param.sched_priority = 5;
    result.client_fifo = pthread_setschedparam(pthread_self(), SCHED_FIFO, &param) == 0;
  }
  KJ_DEFER(if (result.client_fifo) pthread_setschedparam(pthread_self(), old_policy, &old_param));

  const int64_t t0 = monotonic_ns();
  inbox->t0 = t0;
  inbox->latency = &latency;
  inbox->errors = &errors;
  inbox->path = &path;
  KJ_DEFER(inbox->active = false);  // the sink may outlive these (frames still on their way)
  const int64_t end = t0 + static_cast<int64_t>(std::llround(config.seconds * 1e9));
  int64_t next_command = t0, next_servo = t0, next_live = t0;
  for (;;) {
    const int64_t due = std::min(next_command, next_servo);
    if (due >= end) break;
    sleep_until_ns(due);
    ws.poll();
    KJ_IF_MAYBE(e, refusal) { kj::throwFatalException(kj::mv(*e)); }
    int64_t now = monotonic_ns();
    if (now >= next_command) {
      const V3 x = path.position(static_cast<double>(now - t0) * 1e-9);
      auto req = session.setPositionRequest();
      auto p = req.initPosition();
      p.setX(x[0]);
      p.setY(x[1]);
      p.setZ(x[2]);
      latency.on_send(static_cast<double>(now - t0) * 1e-9);
      ++result.commands;
      tasks.add(req.send().then(
          [&latency](capnp::Response<wire::Session::SetPositionResults>&& r) { latency.on_reply(r.getSeq()); },
          [&latency, &refusal](kj::Exception&& e) {
            latency.on_refused();
            if (refusal == nullptr) refusal = kj::mv(e);
          }));
      ws.poll();  // the call goes out now
      next_command += command_period;
      if (next_command <= now) next_command += (now - next_command) / command_period * command_period + command_period;
      now = monotonic_ns();
    }
    if (now >= next_servo) {
      wake_us.push_back(static_cast<double>(now - next_servo) * 1e-3);
      const double t = static_cast<double>(now - t0) * 1e-9;
      ServoSample s;
      s.t = t;
      s.segment = static_cast<uint32_t>(path.segment_at(t));
      s.device = path.position(t);
      s.rendered = inbox->newest.render_model.force_at(s.device, max_force);
      s.frame_tick = inbox->newest.tick;
      s.frame_force = inbox->newest.render_force;
      s.contact_force = inbox->contact;
      ++result.servo_ticks;
      if (config.record_servo && result.servo.size() < result.servo.capacity()) result.servo.push_back(s);
      if (live && now >= next_live) {
        live(s, path.segments()[s.segment].label.c_str());
        next_live = now + static_cast<int64_t>(config.live_interval * 1e9);
      }
      next_servo += servo_period;
      if (next_servo <= now) {  // overran a whole period: keep the phase grid, count what was skipped
        const int64_t behind = (now - next_servo) / servo_period + 1;
        result.servo_skipped += static_cast<size_t>(behind);
        next_servo += behind * servo_period;
      }
    }
  }
  // The last replies and frames.
  for (const int64_t until = monotonic_ns() + 200000000; latency.pending() > 0 && monotonic_ns() < until;) {
    sleep_until_ns(monotonic_ns() + 1000000);
    ws.poll();
  }
  KJ_IF_MAYBE(e, refusal) { kj::throwFatalException(kj::mv(*e)); }
  auto stats_response = session.statsRequest().send().wait(ws);
  auto stats = stats_response.getStats();
  inbox->active = false;  // before cancel(): its wait may deliver frames already sent
  subscription.cancelRequest().send().wait(ws);

  ServerStats& s = result.server;
  s.achieved_hz = stats.getAchievedRateHz();
  s.target_hz = stats.getTargetRateHz();
  s.ticks = stats.getTicks();
  s.step_p50_us = stats.getStepUs().getP50();
  s.step_p99_us = stats.getStepUs().getP99();
  s.lateness_p50_us = stats.getLatenessUs().getP50();
  s.lateness_p99_us = stats.getLatenessUs().getP99();
  s.lateness_max_us = stats.getLatenessUs().getMax();
  s.deadline_misses = stats.getDeadlineMisses();
  s.skipped_ticks = stats.getSkippedTicks();
  s.blow_ups = stats.getBlowUps();
  s.realtime_priority = stats.getRealtimePriority();
  s.refocuses = stats.getRefocuses();
  s.refocuses_dropped = stats.getRefocusesDropped();
  for (auto sub_stats : stats.getSubscribers())
    if (sub_stats.getRateHz() == 0) s.frames_dropped += sub_stats.getDropped();
  s.haptic_rate_hz = stats.getHapticRateHz();
  s.haptic_ticks = stats.getHapticTicks();
  s.haptic_misses = stats.getHapticMisses();
  s.haptic_lateness_p99_us = stats.getHapticLatenessUs().getP99();
  s.model_age_p50_us = stats.getModelAgeUs().getP50();
  s.model_age_p99_us = stats.getModelAgeUs().getP99();
  s.model_age_max_us = stats.getModelAgeUs().getMax();
  result.model_age_ms = percentiles(std::move(model_age_ms));
  result.stiffness_age_ticks = percentiles(std::move(stiffness_age_ticks));
  result.stiffness_age_touching_ticks = percentiles(std::move(stiffness_age_touching_ticks));
  result.touching_without_stiffness = inbox->touching_without_stiffness;
  result.misses_seen_in_frames = inbox->deadline_misses;

  std::vector<double> ms;
  ms.reserve(latency.latencies().size());
  for (double l : latency.latencies()) ms.push_back(1e3 * l);
  result.latency_ms = percentiles(std::move(ms));
  result.frames = inbox->frames;
  result.servo_wake_p99_us = percentiles(std::move(wake_us)).p99;
  result.error = errors.overall();
  result.error_late = errors.late();
  for (size_t k = 0; k < path.segments().size(); ++k) result.error_per_segment.push_back(errors.segment(k));
  result.peak_force = errors.peak_force();
  result.compared = errors.compared();
  result.gaps = errors.gaps();
  return result;
}

}  // namespace palpate::haptic
