#pragma once
// Wire scenes (protocol/palpate.capnp Scene) <-> the JSON scene format.
//
// A wire scene is converted to JSON holding only the fields that differ from
// the schema defaults (which equal the file format's defaults) and the lists
// that are set, then validated by palpate::parse_scene: files and the wire share
// one validator, and its SceneError names the JSON pointer of the bad field.
#include <filesystem>
#include <string>

#include "core/scene.h"
#include "protocol/palpate.capnp.h"

namespace palpate {

// The scene's JSON text (snake_case keys, as in a scene file).
std::string scene_to_json(wire::Scene::Reader scene);

// Validates and converts; throws SceneError naming source_name and the field.
// base_dir resolves relative node_file paths.
Scene scene_from_wire(wire::Scene::Reader scene, const std::string& source_name,
                      const std::filesystem::path& base_dir, const SceneOverrides& overrides = {});

// Fills a wire scene from a JSON scene text (strict: unknown keys rejected).
// Throws SceneError (field empty: the codec does not report paths).
void scene_json_to_wire(const std::string& json_text, const std::string& source_name,
                        wire::Scene::Builder out);

// "key=value" -> (key, value); throws SceneError when there is no '='.
std::pair<std::string, std::string> split_override(const std::string& assignment, const std::string& source_name);

}  // namespace palpate
