// palpate-resolution: the particle spacing a scene asks for (core/resolution.h,
// docs/physics.md §6 "The spacing a scene needs"): across the smallest contact radius of
// its verification sweep, and across every inclusion. scripts/make_mesh.sh --scene reads
// its --shell output to size a tetrahedral mesh for the scene.
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "cli/arguments.h"
#include "core/mesh_reader.h"
#include "core/node_cloud.h"
#include "core/resolution.h"
#include "core/scene.h"

namespace {

using namespace palpate;

const char* kUsage = R"(usage: palpate-resolution --scene FILE [options]
Prints the particle spacing the scene's tool, force sweep and inclusions ask for: three
spacings across the smallest Hertz contact radius of verify.forces, six across the
radius of every inclusion (a mesh group: the radius 3V/A of its tetrahedra, printed with
the spacing the mesh has in it). The scene's mesh or node file need not exist yet: group
inclusions are then named as not sized.
  --scene FILE      scene file (JSON)
  --set KEY=VALUE   override a scene field by its dotted path (repeatable)
  --json            one JSON object on stdout
  --shell           KEY=VALUE lines for a shell (scripts/make_mesh.sh --scene):
                    focus_size, focus (x y z), box (6 numbers), refine_count and
                    refine_K (x y z radius spacing) per inclusion. A mesh body without
                    a box (any shape) has neither box nor focus line (and no JSON
                    focus) unless the scene gives body.distribution.focus: its shape
                    and its surface are the mesh's, not the default box's
Exit status: 0 on success, 1 for a scene that cannot be read, 2 for a usage error.
)";

}  // namespace

int main(int argc, char** argv) {
  std::string scene_file;
  SceneOverrides overrides;
  bool json = false, shell = false;
  cli::parse_or_exit(argc, argv, "palpate-resolution", kUsage, [&](cli::Arguments& args) {
    const std::string& arg = args.flag();
    if (arg == "--scene") scene_file = args.value();
    else if (arg == "--set") overrides.push_back(cli::scene_override(args.value()));
    else if (arg == "--json") json = true;
    else if (arg == "--shell") shell = true;
    else return false;
    return true;
  });
  if (scene_file.empty()) cli::usage_error("palpate-resolution", "--scene FILE is required", kUsage);
  if (json && shell) cli::usage_error("palpate-resolution", "--json and --shell exclude each other", kUsage);
  Scene scene;
  try {
    scene = load_scene(scene_file, overrides, SceneFiles::not_required);
  } catch (const std::exception& e) {
    std::cerr << "palpate-resolution: " << e.what() << "\n";
    return 1;
  }
  // Group inclusions are sized from the body's mesh, when it exists (scripts/make_mesh.sh
  // --scene asks before the mesh is made).
  std::vector<std::string> unsized_groups;
  std::string unsized_reason;
  Resolution res;
  try {
    std::vector<std::string> groups;
    for (const InclusionSpec& inc : scene.material.inclusions)
      if (inc.shape == InclusionShape::group) groups.push_back(inc.group);
    const std::filesystem::path& mesh_file = scene.distribution.mesh_file;
    std::error_code ec;
    if (groups.empty()) {
      res = required_resolution(scene);
    } else if (scene.distribution.type == DistributionType::mesh && std::filesystem::is_regular_file(mesh_file, ec)) {
      res = required_resolution(scene, read_mesh(mesh_file));
    } else {
      res = required_resolution(scene);
      unsized_groups = groups;
      unsized_reason = scene.distribution.type == DistributionType::mesh
                           ? "the mesh " + mesh_file.string() + " does not exist yet"
                           : std::string("the body is not a mesh");
    }
  } catch (const std::exception& e) {  // a mesh that cannot be read, a group it does not have
    std::cerr << "palpate-resolution: " << e.what() << "\n";
    return 1;
  }
  // A mesh body without a box has any shape: the default box is not its box, and the focus
  // graded_focus derives from that box is not on its surface (the tool's site is found on the
  // mesh, core/node_cloud.h). Such a body has a box and a focus only when the scene gives them,
  // as its reference key is its mesh file (reference_file.h).
  const bool has_box = scene.box_given || scene.distribution.type != DistributionType::mesh;
  const bool has_focus = has_box || scene.distribution.focus_given;
  const Vec3 focus = graded_focus(scene);
  if (json) {
    nlohmann::json out;
    out["scene"] = scene.name;
    out["smallest_force"] = res.smallest_force;
    out["smallest_depth"] = res.smallest_depth;
    out["smallest_contact_radius"] = res.smallest_contact_radius;
    out["contact_spacing"] = res.contact_spacing;
    out["finest_spacing"] = res.finest_spacing();
    if (has_focus) out["focus"] = {focus[0], focus[1], focus[2]};
    out["inclusions"] = nlohmann::json::array();
    for (const RegionResolution& r : res.inclusions) {
      nlohmann::json inc = {
          {"center", {r.center[0], r.center[1], r.center[2]}}, {"radius", r.radius}, {"spacing", r.spacing}};
      if (!r.group.empty()) {
        inc["group"] = r.group;
        inc["mesh_spacing"] = r.mesh_spacing;
      }
      out["inclusions"].push_back(inc);
    }
    out["unsized_groups"] = unsized_groups;
    if (!unsized_groups.empty()) out["unsized_because"] = unsized_reason;
    std::cout << out.dump(2) << "\n";
  } else if (shell) {
    std::printf("focus_size=%.9g\n", res.contact_spacing);
    if (has_focus) std::printf("focus='%.17g %.17g %.17g'\n", focus[0], focus[1], focus[2]);
    if (has_box)
      std::printf("box='%.17g %.17g %.17g %.17g %.17g %.17g'\n", scene.box.min[0], scene.box.min[1], scene.box.min[2],
                  scene.box.max[0], scene.box.max[1], scene.box.max[2]);
    std::printf("refine_count=%zu\n", res.inclusions.size());
    for (size_t k = 0; k < res.inclusions.size(); ++k) {
      const RegionResolution& r = res.inclusions[k];
      std::printf("refine_%zu='%.17g %.17g %.17g %.17g %.9g'\n", k, r.center[0], r.center[1], r.center[2], r.radius,
                  r.spacing);
    }
  } else {
    std::printf("%s: the smallest sweep force %.4g N gives a Hertz depth %.4g m and contact radius %.4g m\n",
                scene.name.c_str(), res.smallest_force, res.smallest_depth, res.smallest_contact_radius);
    std::printf("  spacing under the tool: <= %.4g m (%.0f across the contact radius)\n", res.contact_spacing,
                kSpacingsPerContactRadius);
    for (const RegionResolution& r : res.inclusions)
      if (r.group.empty())
        std::printf("  inclusion at (%.4g, %.4g, %.4g), radius %.4g m: spacing <= %.4g m\n", r.center[0], r.center[1],
                    r.center[2], r.radius, r.spacing);
      else
        std::printf("  inclusion group '%s' at (%.4g, %.4g, %.4g), within %.4g m, size 3V/A %.4g m: spacing <= %.4g m "
                    "(the mesh has %.4g m there%s)\n",
                    r.group.c_str(), r.center[0], r.center[1], r.center[2], r.radius,
                    r.spacing * kSpacingsPerInclusionRadius, r.spacing, r.mesh_spacing,
                    r.mesh_spacing <= r.spacing ? "" : ": refine it");
    for (const std::string& g : unsized_groups)
      std::printf("  inclusion group '%s': not sized, %s (a group's size is its tetrahedra's)\n", g.c_str(),
                  unsized_reason.c_str());
    std::printf("  finest: %.4g m\n", res.finest_spacing());
  }
  return 0;
}
