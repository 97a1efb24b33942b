#pragma once
// The sliding study (docs/physics.md §4, "The sliding test"): the tool, free in all
// three translations, pressed with a constant commanded normal force and dragged slowly
// across the top face by the virtual coupling (docs/physics.md (2.6)). The contact is
// frictionless, so the tangential force on the tool must vanish in the quasi-static
// limit, and the depth as the tool crosses the middle must be the static indentation
// there. palpate-slide (tools/slide.cpp) prints the table; tests/sliding_test.cpp checks
// a coarse version.
//
// The drag (4.3): before every step the target is put at T = (x_0 + v t, y_m, c_z): it moves
// at the speed v along x, holds the path's y, and its z follows the tool, so the spring
// pulls only sideways and the normal load is the command (0, 0, -F) alone (the coupling's
// damper, -b v_c, acts on the tool's velocity on every axis; at steady sliding its z part
// vanishes with v_z).
#include <Eigen/Core>
#include <string>

#include "core/model.h"
#include "core/options.h"
#include "core/scene.h"

namespace palpate {

struct SlideSpec {
  double force = 82.88;         // N, commanded normal force, pressing down
  double speed = 0.01;          // m/s, v of the target along +x
  Eigen::Vector2d middle{0, 0}; // m, the middle of the path on the top face
  double half_window = 0.1;     // m, the measurement window is [x_m - w, x_m + w]
  double run_in = 0.05;         // m of sliding before the window
  double stiffness = 1e4;       // N/m, the coupling's k
  double damping = -1.0;        // N s/m, the coupling's b; < 0: critical, 2 sqrt(k M)
};

// Where the path starts: (x_m - w - run_in, y_m). The model's indenter must start there
// (place_indenter_at_site, analysis/reference.h).
Eigen::Vector2d slide_start(const SlideSpec& spec);

struct SlideResult {
  double speed = 0;            // m/s
  double mean_fx = NAN;        // N, mean of F_c,x over the window (State::indenter_contact_force)
  double mean_fz = NAN;        // N, mean of F_c,z over the window
  double ratio = NAN;          // |mean F_x| / |mean F_z|  (4.4)
  double rms_ratio = NAN;      // rms(F_x) / |mean F_z| over the window: the corrugation of a discrete surface
  double depth_middle = NAN;   // m, d under the tool as it crosses x_m (interpolated between steps)
  double lag = NAN;            // m, T_x - c_x as the tool crosses x_m
  double max_offset_y = 0;     // m, largest |c_y - y_m| in the window
  long steps = 0;              // steps of the slide (the press to rest before it not counted)
  long press_steps = 0;        // steps of the press to rest at the start
  double sim_time = 0;         // s, of the slide
  double wall_seconds = 0;     // s, press and slide
  std::string status = "ok";   // ok | not at rest (the press) | diverged: <the failed health check>
};

// Presses the tool to rest at the start of the path on the vertical guide, then frees it,
// turns the coupling on and drags it across the window at spec.speed. `opt` are the
// scene's options (its integrator, dt, damping); the model's indenter starts at
// slide_start(spec).
SlideResult slide(const Model& model, const Options& opt, const RestSpec& rest, const SlideSpec& spec);

struct StaticDepth {
  double depth = NAN;          // m, d at rest at the middle on the vertical guide
  bool converged = false;
  std::string message;
};

// The static truth the slide's depth is compared with: the rest state at spec.middle
// under spec.force on the vertical guide, by relax_to_rest (analysis/static_contact.h:
// pseudo-transient continuation, then the damped dynamics if it stalls), from the sphere
// just touching the undeformed surface there, as palpate-verify --solve static starts
// (the continuation to a residual of 1e-6 of the force). No sliding, no coupling: a different path to
// the same equilibrium.
StaticDepth static_depth_at_middle(const Model& model, const Options& opt, const RestSpec& rest,
                                   const SlideSpec& spec);

}  // namespace palpate
