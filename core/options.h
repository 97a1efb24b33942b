#pragma once
// The options of a step: what a caller may change between two steps without
// rebuilding the Model (MuJoCo's mjModel.opt, kept apart from the constant Model).
// Every stage that needs one takes `const Options&`; nothing in the Model or the
// State depends on them, so a caller can switch the integrator, dt, damping,
// gravity, the contact solve or the health limits of a running State.
//
// A scene gives the initial options (options_of); check_options (time_step.h)
// refuses a dt outside the measured stable envelope of the model.
#include "core/scene.h"
#include "core/types.h"

namespace palpate {

// Position control of the tool (a haptic device's position in, a force out): a virtual
// coupling, the spring-damper between the device position State::tool_target and the
// tool's centre, integrated implicitly with the tool (so any stiffness is stable).
// stiffness 0: off, the tool answers State::force_command alone.
struct CouplingOptions {
  double stiffness = 0.0;  // k, N/m
  double damping = 0.0;    // b, N s/m
};

struct Options {
  IntegratorSpec integrator;   // scene "integrator": type, dt (s), damping (1/s), CG settings, threads
                               // (the force loops' threads, 1 ... kMaxThreads: State::work.threads
                               // follows it at the next step; step() throws std::invalid_argument
                               // outside that range)
  ContactSpec contact;         // scene "contact": tolerance (m), pivots
  Vec3 gravity{0.0, 0.0, 0.0};  // m/s^2, on the body and the indenter
  HealthSpec health;           // scene "health": per-step checks and their limits
  // kg, the indenter's inertia. An option rather than a model constant: it only sets
  // how the sphere answers its command (a quasi-static solve makes it heavy; a
  // haptic coupling tunes it) and no precomputed quantity depends on it.
  double indenter_mass = 1.0;
  ToolGuide tool_guide = ToolGuide::vertical;  // scene indenter.guide: which translations the tool has
  CouplingOptions coupling;  // off unless a caller sets it (position commands)
};

// The translations the tool has, as the diagonal of a projection: 1 on a free axis, 0 on
// one the guide holds (ToolGuide::vertical: z only).
inline Vec3 tool_axes(const Options& opt) {
  return opt.tool_guide == ToolGuide::free ? Vec3(1.0, 1.0, 1.0) : Vec3(0.0, 0.0, 1.0);
}

// The options a scene starts with.
inline Options options_of(const Scene& scene) {
  Options o;
  o.integrator = scene.integrator;
  o.contact = scene.contact;
  o.gravity = scene.gravity;
  o.health = scene.health;
  o.indenter_mass = scene.indenter.mass;
  o.tool_guide = scene.indenter.guide;
  return o;
}

}  // namespace palpate
