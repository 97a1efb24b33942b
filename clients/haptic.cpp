// The client side of haptic rendering: the palpation path, the local model's force, the
// command-to-force latency and the rendering error (clients/haptic.h). The client loop that
// runs them against a session is haptic_loop.cpp; the report of a run, haptic_report.cpp.
#include "clients/haptic.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>

#include "cli/statistics.h"

namespace palpate::haptic {

namespace {

constexpr double kPi = 3.14159265358979323846;

V3 clamp_into(const V3& p, const V3& lo, const V3& hi) {
  V3 r;
  for (int i = 0; i < 3; ++i) r[i] = std::min(std::max(p[i], lo[i]), hi[i]);
  return r;
}

}  // namespace

V3 vec3_of(wire::Vec3::Reader v) { return {v.getX(), v.getY(), v.getZ()}; }

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

Percentiles percentiles(const std::vector<double>& v) {
  Percentiles p;
  p.count = v.size();
  p.p50 = cli::quantile(v, 0.5);
  p.p99 = cli::quantile(v, 0.99);
  p.max = cli::quantile(v, 1.0);
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
    const V3 predicted = previous_.render_model.force_at(f.target, max_force_);
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

}  // namespace palpate::haptic
