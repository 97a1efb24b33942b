#pragma once
// The client side of haptic rendering against palpate-server (issue #13): a palpation
// path for the device, the servo loop's force from a frame's local model, the
// command-to-force latency and the rendering error of the local model against the
// next full step. The math is in plain functions and classes (tests/haptic_test.cpp);
// Cap'n Proto appears only at the edges (vec3_of, local_model_of, geometry_of, run_palpation).
// haptic.cpp holds the math, haptic_loop.cpp the client loop, haptic_report.cpp the report.
#include <array>
#include <cstdint>
#include <cstdio>
#include <functional>
#include <string>
#include <vector>

#include <kj/async.h>

#include "cli/arguments.h"
#include "protocol/local_model.h"
#include "protocol/palpate.capnp.h"

namespace palpate::haptic {

using V3 = std::array<double, 3>;
inline V3 sub(const V3& a, const V3& b) { return {a[0] - b[0], a[1] - b[1], a[2] - b[2]}; }
V3 vec3_of(wire::Vec3::Reader v);

// ---------------------------------------------------------------------------
// The local model of a frame (wire LocalModel, docs/protocol.md "The local contact model").

// protocol/local_model.h, the server's struct too: origin (m), force at origin (N), stiffness
// row-major (N/m, stiffness[3 i + j] = dF_i / dx_j), valid radius (m; 0 = do not
// extrapolate), stiffness tick (-1: no stiffness computed yet, it is then zero). Its force at
// the device position x, docs/protocol.md (P.0): model.force_at(x, max_force).
using LocalModel = protocol::LocalModel<V3, std::array<double, 9>>;

LocalModel local_model_of(wire::LocalModel::Reader m);

double norm(const V3& v);

// ---------------------------------------------------------------------------
// The palpation path: the device position as a function of time.

// What the path needs of a session (SessionInfo).
struct Geometry {
  V3 box_min{0, 0, 0}, box_max{0, 0, 0};  // bounding box of the rest positions, m
  double touch_height = 0;                // z of the tool's centre at first touch, m
  double radius = 0;                      // tool radius R, m
  V3 workspace_min{0, 0, 0}, workspace_max{0, 0, 0};  // the tool centre's box, m
};

Geometry geometry_of(wire::SessionInfo::Reader info);

enum class Motion { approach, press, hold, slide, lift, move };
const char* motion_name(Motion m);

class PalpationPath {
 public:
  // One piece of the path: from p0 at t0 to p1 at t1 along a cosine ramp.
  struct Segment {
    Motion motion;
    std::string label;  // e.g. "press A", "slide A-B"
    double t0, t1;      // s
    V3 p0, p1;          // m
  };

  // From `start` (the tool's position when the path begins) to above site A, press to
  // `depth` below first touch (SessionInfo.touchHeight; depth 0: R/5), hold, slide at
  // depth to site B, lift to `depth` above first touch, move in the air to site C, press,
  // hold, lift. Sites on the top face of the body's box (w = its width in x, h in y):
  // A = centre - w/4 x, B = centre + w/4 x, C = centre + h/4 y. Every point is clamped
  // into the workspace. `duration` (s, > 0) is shared by the segments in fixed
  // proportions. Throws std::invalid_argument naming the parameter.
  PalpationPath(const Geometry& g, const V3& start, double duration, double depth = 0);

  // The device position at time t (s; clamped to [0, duration]): within a segment
  // p0 + (p1 - p0) s(u), s(u) = (1 - cos(pi u)) / 2, u = (t - t0) / (t1 - t0): continuous
  // with a continuous velocity that is zero at every segment's ends (C1).
  V3 position(double t) const;
  // The index of the segment that holds t (clamped).
  size_t segment_at(double t) const;
  const std::vector<Segment>& segments() const { return segments_; }
  double duration() const { return duration_; }
  double depth() const { return depth_; }
  double press_z() const { return press_z_; }  // the device's z when pressing
  double air_z() const { return air_z_; }      // the device's z when moving in the air

 private:
  std::vector<Segment> segments_;
  double duration_, depth_, press_z_, air_z_;
};

// ---------------------------------------------------------------------------
// Statistics.

// The median, 99th percentile and maximum of a sample by nearest rank (cli::quantile); NaN
// when it is empty.
struct Percentiles {
  double p50 = 0, p99 = 0, max = 0;
  size_t count = 0;
};
Percentiles percentiles(const std::vector<double>& v);

// Command-to-force latency of pipelined commands on one capability. For each command
// sent (on_send, in send order), the time to the first frame whose commandSeq >= its
// seq. Replies come back in send order, so the i-th reply's seq belongs to the i-th
// send (on_reply / on_refused); a frame may come before the reply that names the seq
// it reflects, so the frames since the oldest unnamed send are kept until then.
class LatencyTracker {
 public:
  void on_send(double t);
  void on_reply(uint64_t seq);
  void on_refused();
  void on_frame(uint64_t command_seq, double t);
  const std::vector<double>& latencies() const { return latencies_; }  // s, in completion order
  size_t pending() const { return sends_.size() - first_pending_; }
  size_t refused() const { return refused_; }
  void reserve(size_t commands);

 private:
  struct Send {
    double t;
    uint64_t seq;    // 0: reply not yet received
    double latency;  // s, once resolved
    bool resolved, refused;
  };
  struct Seen {
    uint64_t command_seq;
    double t;
  };
  void advance();  // moves first_pending_ past the resolved and refused sends
  std::vector<Send> sends_;  // [first_pending_, end): unresolved, in send order
  size_t first_pending_ = 0;
  size_t first_unnamed_ = 0;  // the oldest send whose reply has not come
  std::vector<Seen> seen_;    // frames whose commandSeq rose, since the oldest unnamed send
  std::vector<double> latencies_;
  size_t refused_ = 0;
};

// The rendering error between full steps: at each frame j (in position mode, the tick
// right after frame j-1), its renderForce F_j, the full step's force at the target x_j,
// against (a) the local model of frame j-1 at x_j, model_{j-1}.force_at(x_j, max_force),
// and (b) the zero-order hold F_{j-1}. Per segment: the path's segment when frame j arrived.
// Frames whose tick came late (published over 1.5 periods after the previous one: the
// servo loop rendered the older model for longer) are also reported apart (late()).
class RenderingError {
 public:
  RenderingError(size_t segments, double max_force, int64_t period_ns = 0)
      : local_(segments + 1), hold_(segments + 1), max_force_(max_force), period_ns_(period_ns) {}
  struct Frame {
    int64_t tick;
    bool position_mode;
    V3 target, render_force;
    LocalModel render_model;
    int64_t publish_ns = 0;  // Frame.publishNs
  };
  void on_frame(const Frame& f, size_t segment);
  void reserve(size_t frames);

  struct Report {
    Percentiles local, hold;  // |error|, N
  };
  Report overall() const;
  Report segment(size_t k) const;
  Report late() const { return {percentiles(late_local_), percentiles(late_hold_)}; }
  double peak_force() const { return peak_; }  // the largest |renderForce| compared, N
  size_t compared() const { return local_.back().size(); }
  size_t gaps() const { return gaps_; }  // frames not compared: the previous tick was not received

 private:
  std::vector<std::vector<double>> local_, hold_;  // per segment; the last: all
  std::vector<double> late_local_, late_hold_;     // frames after a late tick
  double max_force_;
  int64_t period_ns_;
  bool have_ = false;
  Frame previous_{};
  double peak_ = 0;
  size_t gaps_ = 0;
};

// ---------------------------------------------------------------------------
// The haptic client loop (palpate-client --haptic-rate, palpate-bench-haptic).

struct Config {
  double servo_hz = 1000;  // the servo loop's rate, Hz
  double seconds = 5;      // the path's duration, s
  double depth = 0;        // m below first touch; 0 = R/5
  bool record_servo = false;  // keep one ServoSample per servo tick (CSV)
  double live_interval = 0.25;  // s between calls of `live` (when given)
  bool realtime = true;  // ask SCHED_FIFO 5 for the loop's thread (like the server's RPC thread)
};

struct ServoSample {
  double t;          // s since the path started
  uint32_t segment;  // index into PalpationPath::segments()
  V3 device;         // m
  V3 rendered;       // N
  int64_t frame_tick;  // the newest frame's tick (-1: none yet)
  V3 frame_force;    // its renderForce, N
  V3 contact_force;  // its toolContactForce, N
};

struct ServerStats {
  double achieved_hz = 0, target_hz = 0;
  int64_t ticks = 0;
  double step_p50_us = 0, step_p99_us = 0;
  double lateness_p50_us = 0, lateness_p99_us = 0, lateness_max_us = 0;
  uint64_t deadline_misses = 0, skipped_ticks = 0, frames_dropped = 0;
  uint32_t blow_ups = 0;
  bool realtime_priority = false;
  // Multirate (OpenRequest.hapticRateHz): the server's render ticks.
  double haptic_rate_hz = 0;  // 0: off
  int64_t haptic_ticks = 0;
  uint64_t haptic_misses = 0;
  double haptic_lateness_p99_us = 0;
  double model_age_p50_us = 0, model_age_p99_us = 0, model_age_max_us = 0;
  // A scene whose cloud follows the tool: refocuses swapped in, and dropped (Stats.refocuses).
  uint64_t refocuses = 0, refocuses_dropped = 0;
};

struct Result {
  std::vector<PalpationPath::Segment> segments;
  Percentiles latency_ms;
  size_t commands = 0, frames = 0, servo_ticks = 0, servo_skipped = 0;
  double servo_wake_p99_us = 0;  // how late the servo loop woke, p99
  bool client_fifo = false;      // the loop ran with SCHED_FIFO
  std::vector<RenderingError::Report> error_per_segment;
  RenderingError::Report error;
  RenderingError::Report error_late;  // the frames of late ticks (RenderingError::late())
  double peak_force = 0;
  size_t compared = 0, gaps = 0;
  ServerStats server;
  // Frame.modelAgeNs of the frames received (multirate: how old the step a frame's force
  // was rendered from was), ms; and the deadline misses the stream reported as they came
  // (Frame.deadlineMisses: the newest frame's), against the stats' count at the end.
  Percentiles model_age_ms;
  uint64_t misses_seen_in_frames = 0;
  // How many ticks the contact stiffness of a frame's local model lags the frame's own
  // tick (LocalModel.stiffnessTick), and the frames that carried a contact force but no
  // stiffness yet (K = 0: the local model renders the hold).
  Percentiles stiffness_age_ticks;
  Percentiles stiffness_age_touching_ticks;  // the same over the frames with a contact force
  size_t touching_without_stiffness = 0;
  // Multirate: every frame received, by render tick (the force the server rendered and
  // where), for a replay against the scene stepped at the render rate
  // (palpate-bench-haptic --replay-truth).
  struct Served {
    int64_t haptic_tick;
    V3 target, render_force;
    double t;  // s since the path started (0 before it)
  };
  std::vector<Served> served;
  std::vector<ServoSample> servo;  // when Config::record_servo
};

// The device limits of an OpenRequest (0 = none).
void set_device(wire::OpenRequest::Builder request, double max_stiffness, double max_damping, double max_force);

// The flags every haptic front-end takes (palpate-client --haptic-rate, palpate-bench-haptic).
struct DeviceFlags {
  double haptic_rate = 0;  // --haptic-rate HZ: the servo loop, (0, 100000]
  double depth = 0;        // --depth M: below first touch, > 0; 0 = R/5
  double device_stiffness = 0, device_damping = 0, device_force = 0;  // --device-*: 0 = no limit
};
// Takes args.flag() if it is one of DeviceFlags' (true), else leaves it (false); throws
// std::invalid_argument naming the flag on a bad value (cli::parse_or_exit's contract).
bool parse_device_flag(cli::Arguments& args, DeviceFlags& flags);
// The overrides with "indenter.guide=free" added unless they set the guide: a palpation
// slides, which the vertical guide would render as its lateral restoring force.
std::vector<std::string> with_free_guide(std::vector<std::string> overrides);

// Runs the palpation path on a real-time session: subscribes to every tick (scalars
// only), waits for the first frame (the path starts at the tool's position), then for
// Config::seconds sends setPosition(path(t)) once per tick period (1 / info.rateHz; with
// multirate, 1 / info.hapticRateHz: the server renders a force per render tick),
// pipelined, and runs a servo loop at Config::servo_hz that renders the newest frame's
// renderModel at the device position (clock_nanosleep to the next deadline, then
// ws.poll()). `live`, if given, gets a sample every Config::live_interval. Throws
// kj::Exception when the server refuses a command, std::invalid_argument on a bad
// configuration.
Result run_palpation(wire::Session::Client session, wire::SessionInfo::Reader info, kj::WaitScope& ws,
                     const Config& config, const std::function<void(const ServoSample&, const char*)>& live = {});

// The summary of a run as text: command-to-force latency, the server's tick lateness and
// misses, the servo loop, and the rendering error (local model against the zero-order
// hold: median / p99 / max in N and % of the peak force), overall and per segment.
void print_report(std::FILE* out, const Result& r);
// The same as the members of one JSON object (no braces): "latency_p50_ms": ..., ...
std::string json_fields(const Result& r);

}  // namespace palpate::haptic
