// palpate-example-embed-core: the core library without the server (docs/guide/embedding-the-core.md).
// Reads a scene, builds its model, presses the tool down with a constant force for a number of
// steps and compares the indentation with Hertz theory. Links palpate_core and nothing else.
//
//   palpate-example-embed-core SCENE [FORCE_N [STEPS]]
//   palpate-example-embed-core scenes/hertz_cube_haptic.json 53.83 3000
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <exception>
#include <string>

#include "core/hertz.h"        // Hertz theory: F(d), d(F), the finite-layer correction
#include "core/indentation.h"  // d, the indentation Hertz measures
#include "core/model.h"        // Model build_model(const Scene&): constant once built
#include "core/options.h"      // Options options_of(const Scene&): changeable between steps
#include "core/scene.h"        // Scene load_scene(file): reads and validates a scene file
#include "core/state.h"        // State make_state(const Model&, const Options&): all memory of a run
#include "core/step.h"         // StepStatus step(const Model&, const Options&, State&)

namespace {

const char* kUsage = R"(usage: palpate-example-embed-core SCENE [FORCE_N [STEPS]]
Presses the scene's tool down with FORCE_N newtons (default 53.83) for STEPS steps
(default 3000) and compares the indentation with Hertz theory.
Exit status: 0 when done; 1 when the scene cannot be built or a step fails its
health checks; 2 for a wrong argument.
)";

// A whole positive number from the command line, or exit 2 naming it.
double positive(const char* text, const char* what) {
  try {
    size_t used = 0;
    const double v = std::stod(text, &used);
    if (used == std::string(text).size() && v > 0 && std::isfinite(v)) return v;
  } catch (const std::exception&) {
  }
  std::fprintf(stderr, "palpate-example-embed-core: %s: '%s' is not a positive number\n\n%s", what, text, kUsage);
  std::exit(2);
}

}  // namespace

int main(int argc, char** argv) {
  if (argc < 2 || argc > 4 || std::string(argv[1]) == "--help" || std::string(argv[1]) == "-h") {
    std::fputs(kUsage, argc == 2 ? stdout : stderr);
    return argc == 2 ? 0 : 2;
  }
  const double force = argc > 2 ? positive(argv[2], "FORCE_N") : 53.83;         // N
  const long steps = argc > 3 ? std::lround(positive(argv[3], "STEPS")) : 3000;  // ticks of the scene's dt
  try {
    // Built once: the reference configuration and everything precomputed from it. Steps never
    // change it, so several States (threads) may share one Model.
    const palpate::Scene scene = palpate::load_scene(argv[1]);
    const palpate::Model model = palpate::build_model(scene);
    // The scene's integrator, dt, damping, contact and health settings, which a caller may
    // change between any two steps (check_options then checks a new dt against the envelope).
    palpate::Options options = palpate::options_of(scene);
    options.tool_guide = palpate::ToolGuide::vertical;  // held on a vertical guide over the site, as in Hertz's test
    // Everything a run changes, its scratch included: make_state allocates, step() does not.
    palpate::State state = palpate::make_state(model, options);

    state.force_command = palpate::press_down(force);  // the real-time input: (0, 0, -F) on the tool
    for (long k = 0; k < steps; ++k) {
      const palpate::StepStatus status = palpate::step(model, options, state);
      if (palpate::is_fault(status)) {  // a health check failed: the state is not to be trusted
        std::fprintf(stderr, "palpate-example-embed-core: step %ld: %s (value %g, limit %g)\n", k,
                     palpate::to_string(status), state.health.report.value, state.health.report.limit);
        return 1;
      }
    }

    const double d = palpate::indentation(model, state);      // m, below first touch
    const double contact = state.indenter_contact_force.z();  // N, the body's push on the tool, up
    const double e_star = palpate::hertz::effective_modulus(scene.material.young_modulus, scene.material.poisson_ratio);
    const double d_hertz = palpate::hertz::depth(force, model.indenter_radius, e_star);
    const double thickness = model.rest_position.row(2).maxCoeff() - model.rest_position.row(2).minCoeff();  // m
    const double d_layer = palpate::hertz::depth_finite_layer(
        force, model.indenter_radius, scene.material.young_modulus, scene.material.poisson_ratio, thickness);
    std::printf("%s: %d particles, %ld steps of %g s pressed with %g N\n", scene.name.c_str(), model.particle_count,
                steps, options.integrator.dt, force);
    std::printf("indentation %.5f m, contact force %.4f N\n", d, contact);
    std::printf("Hertz %.5f m: d/d_Hertz - 1 = %+.2f %% (finite-layer Hertz %.5f m: %+.2f %%)\n", d_hertz,
                100 * (d / d_hertz - 1), d_layer, 100 * (d / d_layer - 1));
    return 0;
  } catch (const std::exception& e) {  // palpate::SceneError names the file, the field and the reason
    std::fprintf(stderr, "palpate-example-embed-core: %s\n", e.what());
    return 1;
  }
}
