#include "protocol/scene_wire.h"

#include <capnp/compat/json.h>
#include <capnp/message.h>
#include <kj/exception.h>

namespace palpate {

namespace {

void configure(capnp::JsonCodec& codec) {
  codec.handleByAnnotation<wire::Scene>();    // snake_case names from $Json.name
  codec.setHasMode(capnp::HasMode::NON_DEFAULT);  // omit defaults: "absent" in the file format
  codec.setRejectUnknownFields(true);
}

}  // namespace

std::string scene_to_json(wire::Scene::Reader scene) {
  capnp::JsonCodec codec;
  configure(codec);
  return std::string(codec.encode(scene).cStr());
}

Scene scene_from_wire(wire::Scene::Reader scene, const std::string& source_name,
                      const std::filesystem::path& base_dir, const SceneOverrides& overrides) {
  std::string text;
  try {
    text = scene_to_json(scene);
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
    codec.decode(kj::StringPtr(json_text.c_str()), out);
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
