#include "bench/multirate_study.h"

#include <poll.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <stdexcept>

#include "server/haptic_loop.h"
#include "server/local_model.h"
#include "server/sim_loop.h"

namespace palpate::bench {

using server::Snapshot;

HeadlessSession::HeadlessSession(Scene scene, bool contact_stiffness, double touch_lookahead)
    : sim_(config(contact_stiffness, touch_lookahead), std::move(scene)) {
  while (sim_.phase() == server::Phase::starting) wait();
  if (sim_.phase() == server::Phase::failed) throw std::runtime_error(sim_.status().error);
}

const Snapshot& HeadlessSession::step(const Vec3& x) {
  sim_.enqueue(server::CommandType::set_position, x);
  const auto t0 = std::chrono::steady_clock::now();
  sim_.request_steps(1);
  while (!sim_.take_job_done()) wait();
  seconds_ += std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  sim_.frames().take();
  const Snapshot& s = sim_.frames().front();
  if (sim_.status().blow_ups > 0)
    throw std::runtime_error("the run at dt " + std::to_string(sim_.scene().integrator.dt) +
                             " s blew up: " + sim_.status().last_blow_up);
  return s;
}

server::SimConfig HeadlessSession::config(bool contact_stiffness, double touch_lookahead) {
  server::SimConfig c;
  c.headless = true;
  c.try_realtime = false;
  c.contact_stiffness = contact_stiffness;
  c.touch_lookahead = touch_lookahead;
  return c;
}

void HeadlessSession::wait() {
  pollfd p{sim_.wake_fd(), POLLIN, 0};
  if (poll(&p, 1, 60000) != 1) throw std::runtime_error("a headless session did not answer within 60 s");
  uint64_t value = 0;
  [[maybe_unused]] const ssize_t r = read(sim_.wake_fd(), &value, sizeof value);
}

namespace {

Vec3 vec(const haptic::V3& v) { return {v[0], v[1], v[2]}; }

haptic::V3 v3(const Vec3& v) { return {v[0], v[1], v[2]}; }

// The render input of step `now` as if its contact stiffness were that of step `old`
// (a headless session evaluates it at every step, so `old` carries its own state's): the
// server's rule, contact_model_now, then render_model as the session does.
server::RenderInput with_stiffness_of(const Snapshot& now, const Snapshot& old, const CouplingOptions& coupling,
                                      double contact_floor) {
  Snapshot lagged = now;
  lagged.contact_model =
      server::contact_model_now(now.tool_position, now.tool_contact_force, now.tool_touching, old.stiffness_source);
  lagged.render_model =
      server::render_model(lagged.contact_model, true, now.target, now.render_force, coupling, contact_floor);
  return server::render_input_of(lagged);
}

}  // namespace

MultirateResult run_multirate_study(const MultirateConfig& config) {
  SceneOverrides overrides = config.overrides;
  if (std::none_of(overrides.begin(), overrides.end(), [](const auto& o) { return o.first == "indenter.guide"; }))
    overrides.emplace_back("indenter.guide", "free");
  const double h = 1.0 / config.haptic_rate_hz;
  Scene fine_scene = load_scene(config.scene_file, overrides);
  Scene coarse_scene = fine_scene;
  const double model_dt = config.model_dt > 0 ? config.model_dt : fine_scene.integrator.dt;
  const long ratio = std::lround(model_dt / h);
  if (ratio < 1 || std::abs(ratio * h - model_dt) > 1e-9 * model_dt)
    throw std::invalid_argument("the model's step (" + std::to_string(model_dt) +
                                " s) must be a whole number of haptic periods (" + std::to_string(h) + " s)");
  fine_scene.integrator.dt = h;
  coarse_scene.integrator.dt = model_dt;

  HeadlessSession truth(std::move(fine_scene), false);  // the truth needs no local model
  HeadlessSession coarse(std::move(coarse_scene), true, config.touch_lookahead);
  const Model& m = truth.model();

  haptic::Geometry g;
  const Vec3 lo = m.rest_position.rowwise().minCoeff(), hi = m.rest_position.rowwise().maxCoeff();
  g.box_min = v3(lo);
  g.box_max = v3(hi);
  g.touch_height = m.touch_height;
  g.radius = m.indenter_radius;
  g.workspace_min = v3(m.tool_workspace_min);
  g.workspace_max = v3(m.tool_workspace_max);
  const haptic::PalpationPath path(g, v3(m.indenter_start), config.seconds, config.depth);

  MultirateResult r;
  r.segments = path.segments();
  r.particles = m.particle_count;
  r.model_dt = model_dt;
  r.haptic_dt = h;
  const long ticks = std::lround(config.seconds / h);
  r.samples.reserve(static_cast<size_t>(ticks));

  // The last (largest lag + 1) coarse steps (a ring), for the lagged stiffnesses.
  int max_lag = 0;
  for (const int lag : config.stiffness_lags) {
    if (lag < 0) throw std::invalid_argument("a stiffness lag must be >= 0 steps");
    max_lag = std::max(max_lag, lag);
  }
  const size_t lags = config.stiffness_lags.size();
  std::vector<Snapshot> recent(config.stiffness_lags.empty() ? 0 : static_cast<size_t>(max_lag) + 1);
  long coarse_steps = 0;
  const CouplingOptions coupling = coarse.coupling();
  const double contact_floor = 0.5 * coarse.model().min_spacing;  // as Simulation::fill_local_models
  std::vector<server::RenderInput> newest_lagged(lags), pending_lagged(lags);

  server::RenderInput newest;  // the newest coarse step the renderer may use
  server::RenderInput pending;  // the coarse step in progress (usable from its end time)
  double pending_time = 0;      // its state's time
  for (long k = 0; k < ticks; ++k) {
    const double t = k * h;
    const Vec3 x = vec(path.position(t));
    if (k % ratio == 0) {  // a coarse step starts: the device position now
      const Snapshot& s = coarse.step(x);
      pending = server::render_input_of(s);
      if (lags > 0) {
        recent[static_cast<size_t>(coarse_steps) % recent.size()] = s;
        for (size_t l = 0; l < lags; ++l) {
          const long old = std::max(0L, coarse_steps - config.stiffness_lags[l]);
          pending_lagged[l] = with_stiffness_of(s, recent[static_cast<size_t>(old) % recent.size()], coupling,
                                                contact_floor);
        }
      }
      ++coarse_steps;
      pending_time = s.sim_time;
    }
    const Snapshot& f = truth.step(x);  // state at t + h, the device at x
    const double now = t + h;
    if (pending.valid && pending_time <= now + 1e-12) {
      newest = pending;
      newest_lagged = pending_lagged;
    }
    if (!newest.valid) continue;  // nothing to render from yet (the first coarse period)
    server::DeviceInput device{x, newest.command_seq + 1};  // newer than the step's
    const server::HapticSample rendered = server::render_sample(newest, device, 0.0);
    MultirateSample sample{t, path.segment_at(t), f.render_force, rendered.render_force, newest.render_force,
                           {}, now - newest.tick * model_dt};
    for (const server::RenderInput& lagged : newest_lagged)
      sample.lagged.push_back(server::render_sample(lagged, device, 0.0).render_force);
    r.peak = std::max(r.peak, f.render_force.norm());
    r.samples.push_back(sample);
  }
  r.truth_seconds = truth.seconds();
  r.coarse_seconds = coarse.seconds();
  return r;
}

}  // namespace palpate::bench
