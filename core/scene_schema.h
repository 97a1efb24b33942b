#pragma once
// Internal to the scene reader (core/scene*.cpp; not installed): the vocabulary of a scene
// file. The names of enumerated values (parsing, messages and to_string) and the keys of every
// object in document order (the one list the reader checks keys against and
// scene_field_paths() reports; docs/scene-format.md documents them in this order).
#include <array>
#include <cstddef>
#include <cstdint>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "core/laws/laws.h"
#include "core/scene_reader.h"

namespace palpate::scene_io {

inline constexpr Named<SolidKind> kModels[] = {
    {"mls", SolidKind::mls},
    {"hex_fem", SolidKind::hex_fem},
};

inline constexpr Named<HexFormulation> kHexFormulations[] = {
    {"linear", HexFormulation::linear},
    {"corotational", HexFormulation::corotational},
    {"neo_hookean", HexFormulation::neo_hookean},
};
inline constexpr Named<HexVolumetricIntegration> kHexVolumetricIntegrations[] = {
    {"full", HexVolumetricIntegration::full},
    {"reduced", HexVolumetricIntegration::reduced},
};

inline constexpr Named<SupportRule> kSupportRules[] = {
    {"mean_distance", SupportRule::mean_distance},
    {"kth_distance", SupportRule::kth_distance},
};
inline constexpr Named<IntegrationRule> kIntegrationRules[] = {
    {"nodal", IntegrationRule::nodal},
    {"consistent", IntegrationRule::consistent},
};

// The material laws (material.law): the one list of the laws, core/laws/laws.h.
inline constexpr auto kMaterialLaws = [] {
  std::array<Named<MaterialLaw>, mls::material_law_names.size()> names{};
  for (std::size_t k = 0; k < names.size(); ++k)
    names[k] = {mls::material_law_names[k].first, mls::material_law_names[k].second};
  return names;
}();
inline constexpr Named<DistributionType> kDistributions[] = {
    {"grid", DistributionType::grid},
    {"jittered_grid", DistributionType::jittered_grid},
    {"graded_grid", DistributionType::graded_grid},
    {"node_file", DistributionType::node_file},
    {"mesh", DistributionType::mesh},
};

inline constexpr Named<VolumeRule> kVolumeRules[] = {
    {"kernel", VolumeRule::kernel},
    {"lattice", VolumeRule::lattice},
    {"mesh", VolumeRule::mesh},
};

inline constexpr Named<ToolGuide> kToolGuides[] = {
    {"vertical", ToolGuide::vertical},
    {"free", ToolGuide::free},
};

inline constexpr Named<IntegratorType> kIntegrators[] = {
    {"rk4", IntegratorType::rk4},
    {"symplectic_euler", IntegratorType::symplectic_euler},
    {"implicit_euler", IntegratorType::implicit_euler},
};

inline constexpr Named<uint32_t> kFaces[] = {
    {"bottom", face_bottom}, {"top", face_top},     {"x_min", face_x_min}, {"x_max", face_x_max},
    {"y_min", face_y_min},   {"y_max", face_y_max}, {"sides", faces_sides},
};

// ---------------------------------------------------------------------------
// The keys of every object of a scene file, in document order: the one list the
// reader checks keys against and scene_field_paths() reports.

inline constexpr std::string_view kSceneKeys[] = {"name",     "model",   "body",       "mls",     "hex_fem",
                                           "material", "fixed",   "indenter",   "contact", "integrator",
                                           "gravity",  "verify",  "health"};
inline constexpr std::string_view kBodyKeys[] = {"box", "distribution"};
inline constexpr std::string_view kBoxKeys[] = {"min", "max"};
inline constexpr std::string_view kDistributionKeys[] = {"type",          "per_edge", "spacing",   "jitter", "seed",
                                                  "first_spacing", "focus",    "node_file", "file",
                                                  "refine"};
inline constexpr std::string_view kRefineKeys[] = {"size", "growth", "max_size"};
inline constexpr std::string_view kMlsKeys[] = {"neighbors",   "max_neighbors", "support_factor", "support_rule",
                                         "integration", "volumes",       "hourglass",      "regularization",
                                         "mass_floor"};
inline constexpr std::string_view kHexFemKeys[] = {"formulation", "volumetric_integration"};
inline constexpr std::string_view kMaterialKeys[] = {"young_modulus",    "poisson_ratio", "density",
                                              "volume_stiffness", "law",           "inclusions"};
// Each element of material.inclusions (a leaf field of scene_field_paths: an array of these).
inline constexpr std::string_view kInclusionKeys[] = {"sphere", "box", "group", "young_modulus", "poisson_ratio", "density"};
inline constexpr std::string_view kInclusionShapes[] = {"sphere", "box", "group"};
inline constexpr std::string_view kSphereKeys[] = {"center", "radius"};
inline constexpr std::string_view kInclusionBoxKeys[] = {"min", "max"};
// An object element of `fixed` (docs/scene-format.md, "fixed"); its sphere and box take
// kSphereKeys and kInclusionBoxKeys as an inclusion's do.
inline constexpr std::string_view kFixedRegionKeys[] = {"group", "plane", "box", "sphere"};
inline constexpr std::string_view kFixedPlaneKeys[] = {"point", "normal", "tolerance"};
inline constexpr std::string_view kIndenterKeys[] = {"radius", "mass", "position", "force", "workspace_min", "workspace_max",
                                              "guide"};
inline constexpr std::string_view kContactKeys[] = {"tolerance", "max_iterations"};
inline constexpr std::string_view kIntegratorKeys[] = {"type",         "dt", "damping", "cg_tolerance", "cg_max_iterations",
                                                "allow_unstable_dt", "threads", "max_interval"};
inline constexpr std::string_view kVerifyKeys[] = {"forces", "rest"};
inline constexpr std::string_view kRestKeys[] = {"velocity_tolerance", "force_tolerance", "window", "max_time"};
inline constexpr std::string_view kHealthKeys[] = {"enabled", "energy_factor", "max_indenter_speed", "max_penetration",
                                            "inversion_sweep_ticks"};

// The objects of a scene file by JSON pointer; every other key is a field.
struct Section {
  std::string_view pointer;
  std::span<const std::string_view> keys;
};
inline constexpr Section kSections[] = {
    {"", kSceneKeys},           {"/body", kBodyKeys},         {"/body/box", kBoxKeys},
    {"/body/distribution", kDistributionKeys},                {"/body/distribution/refine", kRefineKeys},
    {"/mls", kMlsKeys},
    {"/hex_fem", kHexFemKeys},  {"/material", kMaterialKeys}, {"/indenter", kIndenterKeys},
    {"/contact", kContactKeys}, {"/integrator", kIntegratorKeys},
    {"/verify", kVerifyKeys},   {"/verify/rest", kRestKeys},  {"/health", kHealthKeys},
};

// The section at `pointer` ("" the top level, "/body/box"), or nullptr for a field.
const Section* section_at(std::string_view pointer);

// Appends the JSON pointer of every field of `section` and its subsections, in document order.
void add_field_paths(const Section& section, std::vector<std::string>& out);

}  // namespace palpate::scene_io
