// The scene file's vocabulary (scene_schema.h): its field paths and the names of its
// enumerated values.
#include "core/scene_schema.h"

namespace palpate {

namespace scene_io {

const Section* section_at(std::string_view pointer) {
  for (const Section& s : kSections)
    if (s.pointer == pointer) return &s;
  return nullptr;
}

void add_field_paths(const Section& section, std::vector<std::string>& out) {
  for (std::string_view key : section.keys) {
    const std::string path = std::string(section.pointer) + "/" + std::string(key);
    if (const Section* child = section_at(path)) add_field_paths(*child, out);
    else out.push_back(path);
  }
}

}  // namespace scene_io

using namespace scene_io;

std::vector<std::string> scene_field_paths() {
  std::vector<std::string> paths;
  add_field_paths(*section_at(""), paths);
  return paths;
}

const char* to_string(SolidKind s) { return name_for(kModels, s); }
const char* to_string(IntegratorType t) { return name_for(kIntegrators, t); }
const char* to_string(ToolGuide g) { return name_for(kToolGuides, g); }
const char* to_string(MaterialLaw l) { return name_for(kMaterialLaws, l); }
const char* to_string(HexFormulation f) { return name_for(kHexFormulations, f); }
const char* to_string(DistributionType t) { return name_for(kDistributions, t); }
const char* to_string(HexVolumetricIntegration v) { return name_for(kHexVolumetricIntegrations, v); }
const char* to_string(SupportRule r) { return name_for(kSupportRules, r); }
const char* to_string(IntegrationRule r) { return name_for(kIntegrationRules, r); }
const char* to_string(VolumeRule r) { return name_for(kVolumeRules, r); }

}  // namespace palpate
