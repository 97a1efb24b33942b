#pragma once
// Internal to the scene reader (core/scene*.cpp; not installed): the sections of a scene
// file, each read and checked field by field (scene_sections.cpp), and the defaults derived
// from the whole scene once read (scene_defaults.cpp). read_scene (scene.cpp) calls them in
// document order.
#include <cstdint>
#include <filesystem>
#include <vector>

#include "core/scene.h"
#include "core/scene_reader.h"

namespace palpate::scene_io {

// read_distribution's mark for a refine object without a size (never left in a Scene).
inline constexpr double kDeriveRefineSize = -1.0;

void read_body(const Reader& r, const std::filesystem::path& base_dir, Scene& s);
void read_mls(const Reader& r, DistributionType distribution, MlsSpec& m);
void read_hex_fem(const Reader& r, HexFemSpec& h);
void read_material(const Reader& r, MaterialSpec& m);
void read_fixed(const Reader& r, uint32_t& faces, std::vector<FixedRegion>& regions);
void read_indenter(const Reader& r, IndenterSpec& ind);
void read_contact(const Reader& r, ContactSpec& c);
void read_integrator(const Reader& r, IntegratorSpec& in);
void read_gravity(const Reader& r, Vec3& g);
void read_verify(const Reader& r, VerifySpec& v);
void read_health(const Reader& r, HealthSpec& h);

// The defaults derived from the scene once every section is read (scene_defaults.cpp): the
// lengths that scale with the indenter radius, a refinement's size, a graded lattice's first
// spacing (which must then fit its box). `r` is the scene's top-level object, for messages.
void derive_defaults(const Reader& r, Scene& s);

}  // namespace palpate::scene_io
