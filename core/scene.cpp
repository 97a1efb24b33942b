// Scene files: JSON -> plain structs, validated field by field (docs/scene-format.md).
//
// A Reader pairs a JSON value with its JSON pointer, so every accessor reports the
// path of the value it rejects. Sections are read in document order and the first
// error is thrown as a SceneError(source, pointer, reason).
//
// The reader's parts: scene_reader.h (the Reader, messages, JSON text and overrides),
// scene_schema.h (the names and keys of a scene file), scene_sections.h (each section read
// and checked; the derived defaults in scene_defaults.cpp). Here: the entry points, and
// read_scene, the sections in document order with the checks across them.
#include "core/scene.h"

#include <cerrno>
#include <cstdio>
#include <cstring>
#include <memory>

#include "core/scene_reader.h"
#include "core/scene_schema.h"
#include "core/scene_sections.h"

namespace palpate {

namespace fs = std::filesystem;

SceneError::SceneError(const std::string& source, const std::string& field, const std::string& reason)
    : std::runtime_error(source + ": " + (field.empty() ? std::string() : field + ": ") + reason),
      source_(source),
      field_(field),
      reason_(reason) {}

using namespace scene_io;

namespace {

void read_scene(const Reader& r, const fs::path& base_dir, Scene& s) {
  r.object(kSceneKeys);
  r["name"].get(s.name);
  r["model"].get(s.model, "model", kModels);
  read_body(r["body"], base_dir, s);
  if (s.model == SolidKind::hex_fem && s.distribution.type == DistributionType::mesh)
    r["body"]["distribution"]["type"].fail(
        "the hex_fem model meshes a lattice with bricks and cannot use a tetrahedral 'mesh' cloud: use a 'grid' or "
        "'graded_grid' distribution, or the 'mls' model");
  read_mls(r["mls"], s.distribution.type, s.mls);
  read_hex_fem(r["hex_fem"], s.hex_fem);
  if (s.model == SolidKind::hex_fem && s.distribution.type != DistributionType::grid &&
      s.distribution.type != DistributionType::graded_grid)
    r["body"]["distribution"]["type"].fail("the hex_fem model meshes a lattice: use a 'grid' or 'graded_grid' distribution");
  read_material(r["material"], s.material);
  if (s.model == SolidKind::hex_fem)
    for (size_t k = 0; k < s.material.inclusions.size(); ++k)
      if (s.material.inclusions[k].shape == InclusionShape::group)
        r["material"]["inclusions"].elements("an array of inclusions")[k]["group"].fail(
            "a group names a physical volume of a tetrahedral mesh; the hex_fem model meshes a lattice (use a "
            "sphere or a box)");
  if (s.model == SolidKind::hex_fem && s.material.law != MaterialLaw::stvk)
    r["material"]["law"].fail("applies to the mls model; the hex_fem model's law is hex_fem.formulation");
  read_fixed(r["fixed"], s.fixed_faces, s.fixed_regions);
  read_indenter(r["indenter"], s.indenter);
  s.contact.tolerance = 0.0;  // left out: derived (derive_scale_defaults)
  read_contact(r["contact"], s.contact);
  read_integrator(r["integrator"], s.integrator);
  read_gravity(r["gravity"], s.gravity);
  s.verify.rest.velocity_tolerance = 0.0;  // left out: derived (derive_scale_defaults)
  read_verify(r["verify"], s.verify);
  read_health(r["health"], s.health);
  derive_defaults(r, s);
}

}  // namespace

Scene parse_scene(const std::string& json_text, const std::string& source_name, const fs::path& base_dir,
                  const SceneOverrides& overrides, SceneFiles files) {
  json root = parse_json(json_text, source_name);
  if (!root.is_object()) throw SceneError(source_name, "", "the top-level value must be an object, got " + describe(root));

  Origin origin{source_name, {}, files};
  for (const auto& [key, value] : overrides)
    origin.overrides.emplace_back(apply_override(root, key, value, source_name), key + "=" + value);

  Scene scene;
  scene.source = source_name;
  scene.name = fs::path(source_name).stem().string();
  read_scene(Reader(&root, "", origin), base_dir, scene);
  return scene;
}

Scene load_scene(const fs::path& file, const SceneOverrides& overrides, SceneFiles files) {
  const std::string source = file.string();
  const std::unique_ptr<std::FILE, int (*)(std::FILE*)> f(std::fopen(file.c_str(), "rb"), &std::fclose);
  if (!f) throw SceneError(source, "", std::string("cannot read file: ") + std::strerror(errno));
  std::string text;
  char buf[1 << 16];
  std::size_t n;
  while ((n = std::fread(buf, 1, sizeof buf, f.get())) > 0) text.append(buf, n);
  if (std::ferror(f.get())) throw SceneError(source, "", std::string("cannot read file: ") + std::strerror(errno));
  return parse_scene(text, source, file.parent_path(), overrides, files);
}

}  // namespace palpate
