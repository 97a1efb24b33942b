#include "clients/haptic.h"

#include <pthread.h>
#include <sched.h>
#include <time.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <memory>
#include <stdexcept>

#include <kj/debug.h>

#include "protocol/local_model_force.h"

namespace palpate::haptic {

namespace {

constexpr double kPi = 3.14159265358979323846;

V3 vec3_of(wire::Vec3::Reader v) { return {v.getX(), v.getY(), v.getZ()}; }

V3 sub(const V3& a, const V3& b) { return {a[0] - b[0], a[1] - b[1], a[2] - b[2]}; }

V3 clamp_into(const V3& p, const V3& lo, const V3& hi) {
  V3 r;
  for (int i = 0; i < 3; ++i) r[i] = std::min(std::max(p[i], lo[i]), hi[i]);
  return r;
}

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

}  // namespace

// ---------------------------------------------------------------------------

LocalModel local_model_of(wire::LocalModel::Reader m) {
  LocalModel r;
  r.origin = vec3_of(m.getOrigin());
  r.force = vec3_of(m.getForce());
  auto k = m.getStiffness();
  for (unsigned i = 0; i < 9 && i < k.size(); ++i) r.stiffness[i] = k[i];
  r.valid_radius = m.getValidRadius();
  r.stiffness_tick = m.getStiffnessTick();
  return r;
}

double norm(const V3& v) { return std::sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]); }

// docs/protocol.md (P.0), the server's formula (protocol/local_model_force.h).
V3 render(const LocalModel& model, const V3& x, double max_force) {
  V3 f;
  protocol::local_model_force(model.origin.data(), model.force.data(), model.stiffness.data(), model.valid_radius,
                              model.stiffness_tick >= 0, x.data(), max_force, f.data());
  return f;
}

// ---------------------------------------------------------------------------

Geometry geometry_of(wire::SessionInfo::Reader info) {
  auto rest = info.getRestPositions();
  if (rest.size() < 3 || rest.size() % 3 != 0)
    throw std::invalid_argument("SessionInfo.restPositions: needs 3 n coordinates, got " + std::to_string(rest.size()));
  Geometry g;
  const double inf = std::numeric_limits<double>::infinity();
  g.box_min = {inf, inf, inf};
  g.box_max = {-inf, -inf, -inf};
  for (unsigned p = 0; p < rest.size(); p += 3)
    for (unsigned i = 0; i < 3; ++i) {
      g.box_min[i] = std::min(g.box_min[i], static_cast<double>(rest[p + i]));
      g.box_max[i] = std::max(g.box_max[i], static_cast<double>(rest[p + i]));
    }
  g.touch_height = info.getTouchHeight();
  g.radius = info.getRadius();
  g.workspace_min = vec3_of(info.getWorkspaceMin());
  g.workspace_max = vec3_of(info.getWorkspaceMax());
  return g;
}

const char* motion_name(Motion m) {
  switch (m) {
    case Motion::approach: return "approach";
    case Motion::press: return "press";
    case Motion::hold: return "hold";
    case Motion::slide: return "slide";
    case Motion::lift: return "lift";
    case Motion::move: return "move";
  }
  return "?";
}

PalpationPath::PalpationPath(const Geometry& g, const V3& start, double duration, double depth)
    : duration_(duration), depth_(depth == 0 ? g.radius / 5.0 : depth) {
  if (!(duration > 0) || !std::isfinite(duration))
    throw std::invalid_argument("palpation path: duration: must be a positive number of seconds");
  if (!std::isfinite(depth) || !(depth_ > 0))
    throw std::invalid_argument("palpation path: depth: must be a positive number of m (or 0 for R/5), got " + std::to_string(depth));
  for (int i = 0; i < 3; ++i)
    if (!(g.workspace_min[i] <= g.workspace_max[i]) || !(g.box_min[i] <= g.box_max[i]))
      throw std::invalid_argument("palpation path: the workspace and the body's box must be non-empty boxes");
  press_z_ = std::max(g.touch_height - depth_, g.workspace_min[2]);
  air_z_ = std::min(g.touch_height + depth_, g.workspace_max[2]);
  const double cx = 0.5 * (g.box_min[0] + g.box_max[0]), cy = 0.5 * (g.box_min[1] + g.box_max[1]);
  const double w = g.box_max[0] - g.box_min[0], h = g.box_max[1] - g.box_min[1];
  auto at = [&](double x, double y, double z) { return clamp_into({x, y, z}, g.workspace_min, g.workspace_max); };
  const V3 a_air = at(cx - w / 4, cy, air_z_), a_pressed = at(cx - w / 4, cy, press_z_);
  const V3 b_pressed = at(cx + w / 4, cy, press_z_), b_air = at(cx + w / 4, cy, air_z_);
  const V3 c_air = at(cx, cy + h / 4, air_z_), c_pressed = at(cx, cy + h / 4, press_z_);
  const V3 from = clamp_into(start, g.workspace_min, g.workspace_max);
  struct Piece {
    Motion motion;
    const char* label;
    double weight;
    V3 p0, p1;
  };
  const Piece pieces[] = {
      {Motion::approach, "approach A", 1.0, from, a_air}, {Motion::press, "press A", 1.5, a_air, a_pressed},
      {Motion::hold, "hold A", 1.0, a_pressed, a_pressed}, {Motion::slide, "slide A-B", 2.0, a_pressed, b_pressed},
      {Motion::lift, "lift B", 1.0, b_pressed, b_air},    {Motion::move, "move B-C", 1.5, b_air, c_air},
      {Motion::press, "press C", 1.5, c_air, c_pressed},  {Motion::hold, "hold C", 1.0, c_pressed, c_pressed},
      {Motion::lift, "lift C", 1.0, c_pressed, c_air},
  };
  double total = 0;
  for (const Piece& p : pieces) total += p.weight;
  double t = 0;
  for (const Piece& p : pieces) {
    const double t1 = std::min(duration, t + duration * p.weight / total);
    segments_.push_back({p.motion, p.label, t, t1, p.p0, p.p1});
    t = t1;
  }
  segments_.back().t1 = duration;
}

size_t PalpationPath::segment_at(double t) const {
  for (size_t k = 0; k < segments_.size(); ++k)
    if (t < segments_[k].t1) return k;
  return segments_.size() - 1;
}

V3 PalpationPath::position(double t) const {
  const Segment& s = segments_[segment_at(t)];
  const double u = s.t1 > s.t0 ? std::min(1.0, std::max(0.0, (t - s.t0) / (s.t1 - s.t0))) : 1.0;
  const double ramp = 0.5 * (1.0 - std::cos(kPi * u));  // C1: zero slope at u = 0 and u = 1
  V3 p;
  for (int i = 0; i < 3; ++i) p[i] = s.p0[i] + (s.p1[i] - s.p0[i]) * ramp;
  return p;
}

// ---------------------------------------------------------------------------

double percentile(std::vector<double>& v, double q) {
  if (v.empty()) return NAN;
  std::sort(v.begin(), v.end());
  const double rank = std::ceil(q * static_cast<double>(v.size()));
  const size_t k = rank < 1 ? 0 : std::min(v.size() - 1, static_cast<size_t>(rank) - 1);
  return v[k];
}

Percentiles percentiles(std::vector<double> v) {
  Percentiles p;
  p.count = v.size();
  p.p50 = percentile(v, 0.5);
  p.p99 = percentile(v, 0.99);
  p.max = percentile(v, 1.0);
  return p;
}

void LatencyTracker::reserve(size_t commands) {
  latencies_.reserve(commands);
  sends_.reserve(std::min<size_t>(commands, 8192));
}

void LatencyTracker::on_send(double t) { sends_.push_back({t, 0, NAN, false, false}); }

void LatencyTracker::advance() {
  while (first_pending_ < first_unnamed_ && (sends_[first_pending_].refused || sends_[first_pending_].resolved)) {
    if (sends_[first_pending_].resolved) latencies_.push_back(sends_[first_pending_].latency);
    ++first_pending_;
  }
  if (first_pending_ >= 4096 && 2 * first_pending_ >= sends_.size()) {  // keep the window small
    sends_.erase(sends_.begin(), sends_.begin() + static_cast<std::ptrdiff_t>(first_pending_));
    first_unnamed_ -= first_pending_;
    first_pending_ = 0;
  }
}

void LatencyTracker::on_reply(uint64_t seq) {
  if (first_unnamed_ >= sends_.size()) throw std::logic_error("LatencyTracker: a reply without a send");
  Send& s = sends_[first_unnamed_++];
  s.seq = seq;
  // A frame that came before the reply. (Every frame in seen_ that reflects seq came after
  // this send: the server assigns seq when the command arrives.)
  for (const Seen& e : seen_)
    if (e.command_seq >= seq) {
      s.latency = e.t - s.t;
      s.resolved = true;
      break;
    }
  // Later sends have larger seqs: the frames below this one's are of no use to them.
  if (first_unnamed_ == sends_.size()) seen_.clear();
  else seen_.erase(seen_.begin(), std::find_if(seen_.begin(), seen_.end(),
                                               [&](const Seen& e) { return e.command_seq >= seq; }));
  advance();
}

void LatencyTracker::on_refused() {
  if (first_unnamed_ >= sends_.size()) throw std::logic_error("LatencyTracker: a refusal without a send");
  sends_[first_unnamed_++].refused = true;
  ++refused_;
  if (first_unnamed_ == sends_.size()) seen_.clear();
  advance();
}

void LatencyTracker::on_frame(uint64_t command_seq, double t) {
  for (size_t k = first_pending_; k < first_unnamed_; ++k) {
    Send& s = sends_[k];
    if (s.refused || s.resolved) continue;
    if (s.seq > command_seq) break;  // seqs rise with the sends
    s.latency = t - s.t;
    s.resolved = true;
  }
  advance();
  if (first_unnamed_ < sends_.size() && (seen_.empty() || command_seq > seen_.back().command_seq))
    seen_.push_back({command_seq, t});
}

void RenderingError::reserve(size_t frames) {
  for (auto& v : local_) v.reserve(frames / local_.size() + 16);
  for (auto& v : hold_) v.reserve(frames / hold_.size() + 16);
  local_.back().reserve(frames);
  hold_.back().reserve(frames);
  late_local_.reserve(frames / 8 + 16);
  late_hold_.reserve(frames / 8 + 16);
}

void RenderingError::on_frame(const Frame& f, size_t segment) {
  if (!f.position_mode) {
    have_ = false;
    return;
  }
  peak_ = std::max(peak_, norm(f.render_force));
  if (have_ && f.tick == previous_.tick + 1) {
    const V3 predicted = render(previous_.render_model, f.target, max_force_);
    const double e_local = norm(sub(f.render_force, predicted));
    const double e_hold = norm(sub(f.render_force, previous_.render_force));
    const size_t k = std::min(segment, local_.size() - 2);
    local_[k].push_back(e_local);
    hold_[k].push_back(e_hold);
    local_.back().push_back(e_local);
    hold_.back().push_back(e_hold);
    if (period_ns_ > 0 && 2 * (f.publish_ns - previous_.publish_ns) > 3 * period_ns_ &&
        late_local_.size() < late_local_.capacity()) {
      late_local_.push_back(e_local);
      late_hold_.push_back(e_hold);
    }
  } else if (have_) {
    ++gaps_;
  }
  previous_ = f;
  have_ = true;
}

RenderingError::Report RenderingError::overall() const { return {percentiles(local_.back()), percentiles(hold_.back())}; }

RenderingError::Report RenderingError::segment(size_t k) const { return {percentiles(local_.at(k)), percentiles(hold_.at(k))}; }

// ---------------------------------------------------------------------------

void set_device(wire::OpenRequest::Builder request, double max_stiffness, double max_damping, double max_force) {
  auto d = request.initDevice();
  d.setMaxStiffness(max_stiffness);
  d.setMaxDamping(max_damping);
  d.setMaxForce(max_force);
}

bool parse_device_flag(cli::Arguments& args, DeviceFlags& d) {
  const std::string& flag = args.flag();
  if (flag == "--haptic-rate") {
    d.haptic_rate = args.number();
    if (!(d.haptic_rate > 0 && d.haptic_rate <= 100000))
      throw std::invalid_argument("--haptic-rate: must be in (0, 100000] Hz");
  } else if (flag == "--depth") {
    d.depth = args.number();
    if (!(d.depth > 0)) throw std::invalid_argument("--depth: must be > 0 m");
  } else if (flag == "--device-stiffness") d.device_stiffness = args.number(0, 1e12);
  else if (flag == "--device-damping") d.device_damping = args.number(0, 1e12);
  else if (flag == "--device-force") d.device_force = args.number(0, 1e12);
  else return false;
  return true;
}

std::vector<std::string> with_free_guide(std::vector<std::string> overrides) {
  if (std::none_of(overrides.begin(), overrides.end(),
                   [](const std::string& s) { return s.rfind("indenter.guide=", 0) == 0; }))
    overrides.push_back("indenter.guide=free");
  return overrides;
}

namespace {

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
      s.rendered = render(inbox->newest.render_model, s.device, max_force);
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

namespace palpate::haptic {

namespace {

std::string number(double x) {
  if (!std::isfinite(x)) return "null";
  char b[64];
  std::snprintf(b, sizeof b, "%.6g", x);
  return b;
}

double percent(double x, double peak) { return peak > 0 ? 100.0 * x / peak : NAN; }

void print_error_row(std::FILE* out, const char* name, const RenderingError::Report& e, double peak) {
  std::fprintf(out, "  %-12s %6zu   %9.3g %9.3g %9.3g (%6.2f %%)   %9.3g %9.3g %9.3g (%6.2f %%)\n", name, e.local.count,
               e.local.p50, e.local.p99, e.local.max, percent(e.local.p99, peak), e.hold.p50, e.hold.p99, e.hold.max,
               percent(e.hold.p99, peak));
}

std::string json_percentiles(const std::string& prefix, const Percentiles& p, double peak) {
  return "\"" + prefix + "_p50_n\": " + number(p.p50) + ", \"" + prefix + "_p99_n\": " + number(p.p99) + ", \"" +
         prefix + "_max_n\": " + number(p.max) + ", \"" + prefix + "_p50_pct\": " + number(percent(p.p50, peak)) +
         ", \"" + prefix + "_p99_pct\": " + number(percent(p.p99, peak)) + ", \"" + prefix +
         "_max_pct\": " + number(percent(p.max, peak));
}

}  // namespace

void print_report(std::FILE* out, const Result& r) {
  const ServerStats& s = r.server;
  std::fprintf(out, "command->force    p50 %.3f ms, p99 %.3f ms, max %.3f ms (%zu of %zu setPosition matched)\n",
               r.latency_ms.p50, r.latency_ms.p99, r.latency_ms.max, r.latency_ms.count, r.commands);
  std::fprintf(out, "server            %.1f Hz achieved (target %.0f Hz), step p50 %.0f us, p99 %.0f us\n",
               s.achieved_hz, s.target_hz, s.step_p50_us, s.step_p99_us);
  std::fprintf(out, "tick lateness     p50 %.0f us, p99 %.0f us, max %.0f us; deadline misses %llu of %lld ticks, "
               "%llu skipped, blow-ups %u%s\n",
               s.lateness_p50_us, s.lateness_p99_us, s.lateness_max_us,
               static_cast<unsigned long long>(s.deadline_misses), static_cast<long long>(s.ticks),
               static_cast<unsigned long long>(s.skipped_ticks), s.blow_ups, s.realtime_priority ? ", SCHED_FIFO" : "");
  if (s.haptic_rate_hz > 0) {
    std::fprintf(out, "multirate         render ticks at %.0f Hz: %lld, misses %llu, lateness p99 %.0f us; model age "
                 "p50 %.2f ms, p99 %.2f ms, max %.2f ms (frames received: p50 %.2f ms, p99 %.2f ms)\n",
                 s.haptic_rate_hz, static_cast<long long>(s.haptic_ticks),
                 static_cast<unsigned long long>(s.haptic_misses), s.haptic_lateness_p99_us, 1e-3 * s.model_age_p50_us,
                 1e-3 * s.model_age_p99_us, 1e-3 * s.model_age_max_us, r.model_age_ms.p50, r.model_age_ms.p99);
  }
  std::fprintf(out, "contact stiffness age p50 %.0f, p99 %.0f, max %.0f ticks behind its frame (%.1f / %.1f / %.1f ms); "
               "touching: p50 %.0f, p99 %.0f ticks; %zu frames touching before the first\n",
               r.stiffness_age_ticks.p50, r.stiffness_age_ticks.p99, r.stiffness_age_ticks.max,
               1e3 * r.stiffness_age_ticks.p50 / s.target_hz, 1e3 * r.stiffness_age_ticks.p99 / s.target_hz,
               1e3 * r.stiffness_age_ticks.max / s.target_hz, r.stiffness_age_touching_ticks.p50,
               r.stiffness_age_touching_ticks.p99, r.touching_without_stiffness);
  std::fprintf(out, "misses in frames  %llu reported by the stream as they happened (Frame.deadlineMisses)\n",
               static_cast<unsigned long long>(r.misses_seen_in_frames));
  std::fprintf(out, "frames            %zu received, %llu dropped by the server, %zu compared, %zu gaps\n", r.frames,
               static_cast<unsigned long long>(s.frames_dropped), r.compared, r.gaps);
  std::fprintf(out, "servo loop        %zu ticks, %zu skipped, wake-up lateness p99 %.0f us%s\n", r.servo_ticks,
               r.servo_skipped, r.servo_wake_p99_us, r.client_fifo ? ", SCHED_FIFO" : "");
  std::fprintf(out, "rendering error   |F_next - prediction|, N (peak |F| %.4g N): local model vs zero-order hold\n",
               r.peak_force);
  std::fprintf(out, "  %-12s %6s   %9s %9s %9s %10s   %9s %9s %9s %10s\n", "segment", "frames", "local p50", "p99",
               "max", "(p99/peak)", "hold p50", "p99", "max", "(p99/peak)");
  for (size_t k = 0; k < r.segments.size() && k < r.error_per_segment.size(); ++k)
    print_error_row(out, r.segments[k].label.c_str(), r.error_per_segment[k], r.peak_force);
  print_error_row(out, "all", r.error, r.peak_force);
  print_error_row(out, "late ticks", r.error_late, r.peak_force);
  std::fflush(out);
}

std::string json_fields(const Result& r) {
  const ServerStats& s = r.server;
  std::string j = "\"latency_p50_ms\": " + number(r.latency_ms.p50) + ", \"latency_p99_ms\": " +
                  number(r.latency_ms.p99) + ", \"latency_max_ms\": " + number(r.latency_ms.max) +
                  ", \"commands\": " + std::to_string(r.commands) + ", \"commands_matched\": " +
                  std::to_string(r.latency_ms.count) + ", \"achieved_rate_hz\": " + number(s.achieved_hz) +
                  ", \"target_rate_hz\": " + number(s.target_hz) + ", \"ticks\": " + std::to_string(s.ticks) +
                  ", \"step_p50_us\": " + number(s.step_p50_us) + ", \"step_p99_us\": " + number(s.step_p99_us) +
                  ", \"lateness_p50_us\": " + number(s.lateness_p50_us) + ", \"lateness_p99_us\": " +
                  number(s.lateness_p99_us) + ", \"lateness_max_us\": " + number(s.lateness_max_us) +
                  ", \"deadline_misses\": " + std::to_string(s.deadline_misses) + ", \"skipped_ticks\": " +
                  std::to_string(s.skipped_ticks) + ", \"blow_ups\": " + std::to_string(s.blow_ups) +
                  ", \"realtime_priority\": " + (s.realtime_priority ? "true" : "false") +
                  ", \"haptic_rate_hz\": " + number(s.haptic_rate_hz) + ", \"haptic_ticks\": " +
                  std::to_string(s.haptic_ticks) + ", \"haptic_misses\": " + std::to_string(s.haptic_misses) +
                  ", \"haptic_lateness_p99_us\": " + number(s.haptic_lateness_p99_us) +
                  ", \"model_age_p50_us\": " + number(s.model_age_p50_us) + ", \"model_age_p99_us\": " +
                  number(s.model_age_p99_us) + ", \"model_age_max_us\": " + number(s.model_age_max_us) +
                  ", \"misses_seen_in_frames\": " + std::to_string(r.misses_seen_in_frames) +
                  ", \"stiffness_age_ticks_p50\": " + number(r.stiffness_age_ticks.p50) +
                  ", \"stiffness_age_ticks_p99\": " + number(r.stiffness_age_ticks.p99) +
                  ", \"stiffness_age_touching_ticks_p50\": " + number(r.stiffness_age_touching_ticks.p50) +
                  ", \"stiffness_age_touching_ticks_p99\": " + number(r.stiffness_age_touching_ticks.p99) +
                  ", \"touching_without_stiffness\": " + std::to_string(r.touching_without_stiffness) +
                  ", \"frames\": " + std::to_string(r.frames) + ", \"frames_dropped\": " +
                  std::to_string(s.frames_dropped) + ", \"frames_compared\": " + std::to_string(r.compared) +
                  ", \"frame_gaps\": " + std::to_string(r.gaps) + ", \"servo_ticks\": " +
                  std::to_string(r.servo_ticks) + ", \"servo_skipped\": " + std::to_string(r.servo_skipped) +
                  ", \"servo_wake_p99_us\": " + number(r.servo_wake_p99_us) +
                  ", \"client_fifo\": " + (r.client_fifo ? "true" : "false") + ", \"peak_force_n\": " +
                  number(r.peak_force) + ", \"error\": {" + json_percentiles("local", r.error.local, r.peak_force) +
                  ", " + json_percentiles("hold", r.error.hold, r.peak_force) + "}, \"error_late_ticks\": {" +
                  "\"frames\": " + std::to_string(r.error_late.local.count) + ", " +
                  json_percentiles("local", r.error_late.local, r.peak_force) + ", " +
                  json_percentiles("hold", r.error_late.hold, r.peak_force) + "}, \"segments\": [";
  for (size_t k = 0; k < r.segments.size() && k < r.error_per_segment.size(); ++k) {
    const auto& e = r.error_per_segment[k];
    j += std::string(k ? ", " : "") + "{\"segment\": \"" + r.segments[k].label + "\", \"motion\": \"" +
         motion_name(r.segments[k].motion) + "\", \"t0_s\": " + number(r.segments[k].t0) + ", \"t1_s\": " +
         number(r.segments[k].t1) + ", \"frames\": " + std::to_string(e.local.count) + ", " +
         json_percentiles("local", e.local, r.peak_force) + ", " + json_percentiles("hold", e.hold, r.peak_force) +
         "}";
  }
  return j + "]";
}

}  // namespace palpate::haptic
