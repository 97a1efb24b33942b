#include "protocol/scene_wire.h"

#include <capnp/compat/json.h>
#include <capnp/message.h>
#include <kj/exception.h>
#include <nlohmann/json.hpp>

namespace palpate {

namespace {

void configure(capnp::JsonCodec& codec) {
  codec.handleByAnnotation<wire::Scene>();    // snake_case names from $Json.name
  codec.setHasMode(capnp::HasMode::NON_DEFAULT);  // omit defaults: "absent" in the file format
  codec.setRejectUnknownFields(true);
}

nlohmann::json vec3_json(capnp::List<double>::Reader v) {
  nlohmann::json out = nlohmann::json::array();
  for (double x : v) out.push_back(x);
  return out;
}

nlohmann::json sphere_json(wire::Sphere::Reader s) {
  nlohmann::json out = {{"radius", s.getRadius()}};
  if (s.hasCenter()) out["center"] = vec3_json(s.getCenter());
  return out;
}

nlohmann::json box_json(wire::Box::Reader b) {
  nlohmann::json out = nlohmann::json::object();
  if (b.hasMin()) out["min"] = vec3_json(b.getMin());
  if (b.hasMax()) out["max"] = vec3_json(b.getMax());
  return out;
}

// The inclusions, written by hand rather than by the codec: "only what differs from the
// default" would drop a Poisson ratio of 0, which the reader requires to be given.
nlohmann::json inclusions_json(capnp::List<wire::Inclusion>::Reader list) {
  nlohmann::json out = nlohmann::json::array();
  for (const wire::Inclusion::Reader inc : list) {
    nlohmann::json e = {{"young_modulus", inc.getYoungModulus()}, {"poisson_ratio", inc.getPoissonRatio()}};
    switch (inc.which()) {
      case wire::Inclusion::SPHERE: e["sphere"] = sphere_json(inc.getSphere()); break;
      case wire::Inclusion::BOX: e["box"] = box_json(inc.getBox()); break;
      case wire::Inclusion::GROUP: e["group"] = std::string(inc.getGroup().cStr()); break;
    }
    if (inc.getDensity() != 0.0) e["density"] = inc.getDensity();
    out.push_back(std::move(e));
  }
  return out;
}

nlohmann::json fixed_region_json(wire::FixedRegion::Reader region) {
  switch (region.which()) {
    case wire::FixedRegion::GROUP: return {{"group", std::string(region.getGroup().cStr())}};
    case wire::FixedRegion::PLANE: {
      const wire::Plane::Reader p = region.getPlane();
      nlohmann::json plane = {{"tolerance", p.getTolerance()}};
      if (p.hasPoint()) plane["point"] = vec3_json(p.getPoint());
      if (p.hasNormal()) plane["normal"] = vec3_json(p.getNormal());
      return {{"plane", plane}};
    }
    case wire::FixedRegion::BOX: return {{"box", box_json(region.getBox())}};
    case wire::FixedRegion::SPHERE: return {{"sphere", sphere_json(region.getSphere())}};
  }
  return nlohmann::json::object();
}

}  // namespace

std::string scene_to_json(wire::Scene::Reader scene) {
  capnp::JsonCodec codec;
  configure(codec);
  nlohmann::json out = nlohmann::json::parse(codec.encode(scene).cStr());
  if (scene.getMaterial().hasInclusions())
    out["material"]["inclusions"] = inclusions_json(scene.getMaterial().getInclusions());
  out.erase("fixed_regions");
  if (scene.hasFixedRegions() && scene.getFixedRegions().size() > 0) {
    // The file's one `fixed` list: the faces, then the regions.
    if (!scene.hasFixed())
      throw SceneError("", "/fixed", "fixedRegions are given but fixed (the faces) is null: set fixed, to an "
                                     "empty list for the regions alone (null faces would mean the default "
                                     "[\"bottom\", \"sides\"])");
    nlohmann::json& fixed = out["fixed"];
    if (!fixed.is_array()) fixed = nlohmann::json::array();
    for (const wire::FixedRegion::Reader region : scene.getFixedRegions()) fixed.push_back(fixed_region_json(region));
  }
  return out.dump();
}

Scene scene_from_wire(wire::Scene::Reader scene, const std::string& source_name,
                      const std::filesystem::path& base_dir, const SceneOverrides& overrides) {
  std::string text;
  try {
    text = scene_to_json(scene);
  } catch (const SceneError& e) {
    throw SceneError(source_name, e.field(), e.reason());
  } catch (const kj::Exception& e) {
    throw SceneError(source_name, "", std::string("cannot encode the scene: ") + e.getDescription().cStr());
  }
  return parse_scene(text, source_name, base_dir, overrides);
}

void scene_json_to_wire(const std::string& json_text, const std::string& source_name,
                        wire::Scene::Builder out) {
  capnp::JsonCodec codec;
  configure(codec);
  try {
    // The region objects of `fixed` travel in fixedRegions (the faces stay in fixed).
    std::string text = json_text;
    if (nlohmann::json j = nlohmann::json::parse(json_text, nullptr, false);
        j.is_object() && j.contains("fixed") && j["fixed"].is_array()) {
      nlohmann::json faces = nlohmann::json::array(), regions = nlohmann::json::array();
      for (const nlohmann::json& e : j["fixed"]) (e.is_object() ? regions : faces).push_back(e);
      if (!regions.empty()) {
        j["fixed"] = faces;
        j["fixed_regions"] = regions;
        text = j.dump();
      }
    }
    codec.decode(kj::StringPtr(text.c_str()), out);
  } catch (const kj::Exception& e) {
    throw SceneError(source_name, "", std::string("cannot decode the scene: ") + e.getDescription().cStr());
  }
}

std::pair<std::string, std::string> split_override(const std::string& assignment, const std::string& source_name) {
  const auto eq = assignment.find('=');
  if (eq == std::string::npos || eq == 0)
    throw SceneError(source_name, "", "override '" + assignment + "' must be key=value (e.g. mls.neighbors=26)");
  return {assignment.substr(0, eq), assignment.substr(eq + 1)};
}

}  // namespace palpate
