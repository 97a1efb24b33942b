#include "protocol/scene_wire.h"

#include <capnp/compat/json.h>
#include <capnp/dynamic.h>
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

// RFC 3629 UTF-8: no overlong forms, no surrogates, nothing above U+10FFFF.
bool valid_utf8(kj::ArrayPtr<const char> text) {
  const auto* s = reinterpret_cast<const unsigned char*>(text.begin());
  const size_t n = text.size();
  for (size_t i = 0; i < n;) {
    const unsigned char c = s[i];
    if (c < 0x80) { ++i; continue; }
    size_t len = 0;
    unsigned char lo = 0x80, hi = 0xBF;  // the allowed range of the second byte
    if (c >= 0xC2 && c <= 0xDF) len = 2;
    else if (c >= 0xE0 && c <= 0xEF) { len = 3; if (c == 0xE0) lo = 0xA0; if (c == 0xED) hi = 0x9F; }
    else if (c >= 0xF0 && c <= 0xF4) { len = 4; if (c == 0xF0) lo = 0x90; if (c == 0xF4) hi = 0x8F; }
    else return false;
    if (i + len > n || s[i + 1] < lo || s[i + 1] > hi) return false;
    for (size_t k = 2; k < len; ++k)
      if (s[i + k] < 0x80 || s[i + k] > 0xBF) return false;
    i += len;
  }
  return true;
}

// The field's name in the scene file: its $Json.name, else its schema name.
std::string json_field_name(capnp::StructSchema::Field field) {
  constexpr uint64_t kJsonNameAnnotation = 0xfa5b1fd61c2e7c3dull;  // capnp/compat/json.capnp `name`
  for (const auto annotation : field.getProto().getAnnotations())
    if (annotation.getId() == kJsonNameAnnotation) return annotation.getValue().getText().cStr();
  return field.getProto().getName().cStr();
}

// The JSON pointer of the first text in `value` that is not UTF-8 (empty if all are): the
// codec copies text bytes verbatim, and JSON text must be UTF-8.
std::string first_invalid_text(const capnp::DynamicValue::Reader& value, const std::string& pointer) {
  switch (value.getType()) {
    case capnp::DynamicValue::TEXT: {
      const capnp::Text::Reader text = value.as<capnp::Text>();
      return valid_utf8(text.asArray()) ? std::string() : pointer;
    }
    case capnp::DynamicValue::LIST: {
      const auto list = value.as<capnp::DynamicList>();
      for (unsigned i = 0; i < list.size(); ++i) {
        std::string bad = first_invalid_text(list[i], pointer + "/" + std::to_string(i));
        if (!bad.empty()) return bad;
      }
      return {};
    }
    case capnp::DynamicValue::STRUCT: {
      const auto s = value.as<capnp::DynamicStruct>();
      for (const capnp::StructSchema::Field field : s.getSchema().getFields()) {
        if (!s.has(field)) continue;
        std::string bad = first_invalid_text(s.get(field), pointer + "/" + json_field_name(field));
        if (!bad.empty()) return bad;
      }
      return {};
    }
    default: return {};
  }
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
  const std::string bad_text = first_invalid_text(capnp::DynamicStruct::Reader(scene), "");
  if (!bad_text.empty()) throw SceneError("", bad_text, "the text is not valid UTF-8");
  capnp::JsonCodec codec;
  configure(codec);
  const kj::String encoded = codec.encode(scene);
  nlohmann::json out;
  try {
    out = nlohmann::json::parse(encoded.cStr());
  } catch (const nlohmann::json::exception& e) {  // an internal error: the walk above checks all text
    throw SceneError("", "", std::string("the encoded scene is not JSON: ") + e.what());
  }
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
