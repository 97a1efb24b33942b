// The sections of a scene file (scene_sections.h), in document order: each read through a
// Reader and checked field by field, the checks that involve two fields of one section
// included. The checks across sections are read_scene's (scene.cpp).
#include "core/scene_sections.h"

#include <cmath>
#include <string>
#include <system_error>

#include "core/mesh_reader.h"
#include "core/scene_schema.h"
#include "core/thread_pool.h"

namespace palpate::scene_io {

namespace fs = std::filesystem;

namespace {

void read_box(const Reader& r, BoxSpec& box) {
  r.object(kBoxKeys);
  r["min"].get(box.min);
  r["max"].get(box.max);
  constexpr char kAxis[] = "xyz";
  for (int a = 0; a < 3; ++a) {
    const double edge = box.max[a] - box.min[a];
    if (!(edge > 0.0))
      r.fail(std::string("max must exceed min in every component (") + kAxis[a] + ": max " + format_number(box.max[a]) +
             " <= min " + format_number(box.min[a]) + ")");
    if (edge > 1000.0)
      r.fail(std::string("every edge must be at most 1000 m (") + kAxis[a] + ": " + format_number(edge) + " m)");
  }
}

// A file named in the scene: relative paths are resolved against base_dir; absolute, normalised.
fs::path resolve_file(const std::string& name, const fs::path& base_dir) {
  fs::path p = name;
  if (p.is_relative()) p = base_dir / p;
  std::error_code ec;
  const fs::path abs = fs::absolute(p, ec);
  return (ec ? p : abs).lexically_normal();
}

// Requires `file` (the scene's text `name`, resolved) to exist and not be a folder.
void require_file(const Reader& r, const std::string& what, const std::string& name, const fs::path& file) {
  if (!r.files_required()) return;
  std::error_code ec;
  const auto status = fs::status(file, ec);
  if (!fs::exists(status)) r.fail(what + " '" + name + "' not found (resolved to " + file.string() + ")");
  if (fs::is_directory(status)) r.fail(what + " '" + name + "' is a directory (resolved to " + file.string() + ")");
}


void read_distribution(const Reader& r, const BoxSpec& box, const fs::path& base_dir, DistributionSpec& d) {
  r.object(kDistributionKeys);
  r["type"].get(d.type, "distribution type", kDistributions);
  r["per_edge"].get(d.per_edge, 2, 200);
  r["spacing"].get(d.spacing, at_least(0.0));
  r["jitter"].get(d.jitter, closed_open(0.0, 0.5));
  r["seed"].get(d.seed);
  d.first_spacing = 0.0;  // left out or 0: derived from the scene (read_scene, core/resolution.h)
  r["first_spacing"].get(d.first_spacing, at_least(0.0));
  if (r["focus"].present()) {
    r["focus"].get(d.focus);
    d.focus_given = true;
  }
  std::string node_file, mesh_file;
  r["node_file"].get(node_file);
  r["file"].get(mesh_file);

  const bool lattice = d.type != DistributionType::node_file && d.type != DistributionType::mesh;
  if (d.spacing > 0.0 && lattice) {
    constexpr char kAxis[] = "xyz";
    for (int a = 0; a < 3; ++a) {
      const double edge = box.max[a] - box.min[a];
      const double nodes = std::round(edge / d.spacing) + 1.0;
      if (nodes < 2.0 || nodes > 200.0)
        r["spacing"].fail("gives " + (nodes > 1e6 ? std::string("over a million") : format_number(nodes)) + " nodes along " + kAxis[a] + " (edge " + format_number(edge) +
                          " m); round(edge / spacing) + 1 must be in [2, 200]");
    }
  }

  if (const Reader refine = r["refine"]; refine.present()) {
    refine.object(kRefineKeys);
    d.refine.size = kDeriveRefineSize;  // read_scene derives it when left out (a mesh only)
    if (refine["size"].present()) refine["size"].get(d.refine.size, open_closed(0.0, 1e3));
    refine["growth"].get(d.refine.growth, open_closed(1.0, 10.0));
    refine["max_size"].get(d.refine.max_size, closed(0.0, 1e3));
    if (d.refine.max_size > 0 && d.refine.max_size <= d.refine.size)
      refine["max_size"].fail("must exceed size (else nothing is refined), or be 0 (no limit)");
  }
  if (!node_file.empty()) d.node_file = resolve_file(node_file, base_dir);
  if (!mesh_file.empty()) d.mesh_file = resolve_file(mesh_file, base_dir);
  if (d.type == DistributionType::node_file) {
    const Reader f = r["node_file"];
    if (node_file.empty()) f.fail("required when type is 'node_file' (a text file of \"x y z\" lines)");
    require_file(f, "node file", node_file, d.node_file);
  }
  if (d.type == DistributionType::mesh) {
    const Reader f = r["file"];
    if (mesh_file.empty())
      f.fail("required when type is 'mesh' (a tetrahedral mesh: .msh of gmsh, or .node with its .ele of TetGen)");
    if (!known_mesh_extension(d.mesh_file))
      f.fail("unknown mesh format '" + d.mesh_file.extension().string() + "' of '" + mesh_file +
             "' (known: .msh, gmsh 4.1 or 2.2 ASCII; .node with its sibling .ele, TetGen)");
    require_file(f, "mesh file", mesh_file, d.mesh_file);
    if (d.mesh_file.extension() == ".node") {
      const fs::path ele = tetgen_element_file(d.mesh_file);
      require_file(f, "the TetGen element file of", mesh_file, ele);
    }
  }
}

}  // namespace

void read_body(const Reader& r, const fs::path& base_dir, Scene& s) {
  r.object(kBodyKeys);
  read_box(r["box"], s.box);
  read_distribution(r["distribution"], s.box, base_dir, s.distribution);
  s.box_given = r["box"].present() || s.distribution.type != DistributionType::mesh;
}

void read_mls(const Reader& r, DistributionType distribution, MlsSpec& m) {
  r.object(kMlsKeys);
  r["neighbors"].get(m.neighbors, 4, 64);
  r["max_neighbors"].get(m.max_neighbors, 0, 128);
  if (m.max_neighbors != 0 && m.max_neighbors < m.neighbors)
    r["max_neighbors"].fail("must be 0 (off) or at least neighbors (" + std::to_string(m.neighbors) + "), got " +
                            std::to_string(m.max_neighbors));
  r["support_factor"].get(m.support_factor, open_closed(0.0, 10.0));
  r["support_rule"].get(m.support_rule, "support rule", kSupportRules);
  r["integration"].get(m.integration, "integration rule", kIntegrationRules);
  r["volumes"].get(m.volumes, "volume rule", kVolumeRules);
  r["hourglass"].get(m.hourglass, closed(0.0, 100.0));
  r["regularization"].get(m.regularization, closed_open(0.0, 1.0));
  r["mass_floor"].get(m.mass_floor, closed(0.0, 1.0));
  if (m.volumes == VolumeRule::lattice && distribution == DistributionType::node_file)
    r["volumes"].fail(
        "'lattice' needs a lattice: a node_file cloud has no lattice cell volumes; use 'kernel' "
        "(or a grid distribution)");
  // A mesh cloud's volumes are its tetrahedra's, and only a mesh has tetrahedra. Required
  // rather than defaulted: the wire omits the default ('kernel'), so a default that
  // depended on the distribution could not be told from an explicit 'kernel'.
  if (distribution == DistributionType::mesh && m.volumes != VolumeRule::mesh)
    r["volumes"].fail(std::string("a 'mesh' distribution takes its volumes from the tetrahedra: set \"volumes\": \"mesh\" (got '") +
                      (m.volumes == VolumeRule::kernel ? "kernel" : "lattice") +
                      (r["volumes"].present() ? "')" : "', the default)"));
  if (m.volumes == VolumeRule::mesh && distribution != DistributionType::mesh)
    r["volumes"].fail("'mesh' volumes need a 'mesh' distribution (tetrahedra); use 'kernel' or 'lattice'");
}

void read_hex_fem(const Reader& r, HexFemSpec& h) {
  r.object(kHexFemKeys);
  r["formulation"].get(h.formulation, "formulation", kHexFormulations);
  r["volumetric_integration"].get(h.volumetric_integration, "volumetric integration", kHexVolumetricIntegrations);
  if (h.formulation == HexFormulation::neo_hookean && h.volumetric_integration == HexVolumetricIntegration::reduced)
    r["volumetric_integration"].fail(
        "the neo_hookean formulation integrates fully (2x2x2 Gauss points); 'reduced' applies to linear and "
        "corotational");
}

namespace {

// {"center": [x, y, z], "radius": r}: a ball, m (an inclusion's, a fixed region's).
void read_sphere(const Reader& r, Vec3& center, double& radius) {
  r.object(kSphereKeys);
  if (!r["center"].present()) r["center"].fail("required: the sphere's centre [x, y, z] in m");
  if (!r["radius"].present()) r["radius"].fail("required: the sphere's radius in m");
  r["center"].get(center);
  r["radius"].get(radius, open_closed(0.0, 1e3));
}

// {"min": [x, y, z], "max": [x, y, z]}: a box, m. `solid`: max > min in every component (a
// region of material has volume); else max >= min (a fixed slab may be flat).
void read_box_corners(const Reader& r, Vec3& min, Vec3& max, bool solid) {
  r.object(kInclusionBoxKeys);
  if (!r["min"].present()) r["min"].fail("required: the box's lower corner [x, y, z] in m");
  if (!r["max"].present()) r["max"].fail("required: the box's upper corner [x, y, z] in m");
  r["min"].get(min);
  r["max"].get(max);
  constexpr char kAxis[] = "xyz";
  for (int a = 0; a < 3; ++a)
    if (solid ? !(max[a] > min[a]) : !(max[a] >= min[a]))
      r["max"].fail(std::string(solid ? "must exceed min in every component (" : "must be at least min in every component (") +
                    kAxis[a] + ": " + format_number(max[a]) + (solid ? " <= " : " < ") + format_number(min[a]) + ")");
}

// material.inclusions: [{"sphere": {...} | "box": {...}, "young_modulus", "poisson_ratio", "density"?}, ...],
// the constants in the matrix material's ranges; density defaults to the matrix's.
void read_inclusions(const Reader& r, MaterialSpec& m) {
  if (!r.present()) return;
  m.inclusions.clear();
  for (const Reader& e : r.elements("an array of inclusions")) {
    e.object(kInclusionKeys);
    int shapes = 0;
    for (std::string_view k : kInclusionShapes) shapes += e[k].present();
    if (!e.present() || shapes != 1)
      e.fail("an inclusion needs exactly one shape key (one of: " + join_names(kInclusionShapes) + ")");
    InclusionSpec inc;
    inc.density = m.density;
    if (const Reader group = e["group"]; group.present()) {
      inc.shape = InclusionShape::group;
      group.get(inc.group);
      if (inc.group.empty()) group.fail("the name of a physical volume group of the mesh, not empty");
    } else if (const Reader sphere = e["sphere"]; sphere.present()) {
      inc.shape = InclusionShape::sphere;
      read_sphere(sphere, inc.center, inc.radius);
    } else {
      inc.shape = InclusionShape::box;
      read_box_corners(e["box"], inc.min, inc.max, /*solid=*/true);
    }
    if (!e["young_modulus"].present()) e["young_modulus"].fail("required: the inclusion's Young's modulus in Pa");
    if (!e["poisson_ratio"].present()) e["poisson_ratio"].fail("required: the inclusion's Poisson ratio");
    e["young_modulus"].get(inc.young_modulus, open_closed(0.0, 1e12));
    e["poisson_ratio"].get(inc.poisson_ratio, open(-1.0, 0.5));
    e["density"].get(inc.density, open_closed(0.0, 1e5));
    m.inclusions.push_back(inc);
  }
}

}  // namespace

void read_material(const Reader& r, MaterialSpec& m) {
  r.object(kMaterialKeys);
  r["young_modulus"].get(m.young_modulus, open_closed(0.0, 1e12));
  r["poisson_ratio"].get(m.poisson_ratio, open(-1.0, 0.5));
  r["density"].get(m.density, open_closed(0.0, 1e5));
  r["volume_stiffness"].get(m.volume_stiffness, closed(0.0, 1e12));
  r["law"].get(m.law, "material law", kMaterialLaws);
  read_inclusions(r["inclusions"], m);
}

namespace {

// One object element of `fixed`: exactly one of group / plane / box / sphere.
FixedRegion read_fixed_region(const Reader& e, const std::string& field) {
  e.object(kFixedRegionKeys);
  int shapes = 0;
  for (std::string_view k : kFixedRegionKeys) shapes += e[k].present();
  if (shapes != 1)
    e.fail("a fixed region needs exactly one of the keys " + join_names(kFixedRegionKeys) +
           " (or a face name string)");
  FixedRegion region;
  region.field = field;
  auto required = [](const Reader& r, const char* what) {
    if (!r.present()) r.fail(std::string("required: ") + what);
  };
  if (const Reader g = e["group"]; g.present()) {
    region.kind = FixedRegionKind::group;
    g.get(region.group);
    if (region.group.empty()) g.fail("the name of a physical surface group of the mesh, not empty");
  } else if (const Reader p = e["plane"]; p.present()) {
    region.kind = FixedRegionKind::plane;
    p.object(kFixedPlaneKeys);
    required(p["point"], "a point of the plane [x, y, z] in m");
    required(p["normal"], "the plane's normal [nx, ny, nz]");
    p["point"].get(region.point);
    p["normal"].get(region.normal);
    if (!(region.normal.norm() > 0)) p["normal"].fail("must not be the zero vector");
    region.normal.normalize();
    p["tolerance"].get(region.tolerance, closed(0.0, 1e3));
  } else if (const Reader b = e["box"]; b.present()) {
    region.kind = FixedRegionKind::box;
    read_box_corners(b, region.min, region.max, /*solid=*/false);
  } else {
    region.kind = FixedRegionKind::sphere;
    read_sphere(e["sphere"], region.center, region.radius);
  }
  return region;
}

}  // namespace

void read_fixed(const Reader& r, uint32_t& faces, std::vector<FixedRegion>& regions) {
  if (!r.present()) return;  // absent: the default; [] is a free body
  uint32_t out = 0;
  int index = 0;
  for (const Reader& e : r.elements("an array of face names and fixed regions")) {
    if (e.is_object())
      regions.push_back(read_fixed_region(e, "/fixed/" + std::to_string(index)));
    else
      out |= e.pick("face", kFaces)->value;
    ++index;
  }
  faces = out;
}

void read_indenter(const Reader& r, IndenterSpec& ind) {
  r.object(kIndenterKeys);
  r["radius"].get(ind.radius, open_closed(0.0, 1e3));
  r["mass"].get(ind.mass, open_closed(0.0, 1e6));
  r["position"].get(ind.position);
  ind.position_given = ind.position_given || r["position"].present();
  r["force"].get(ind.force, closed(-1e9, 1e9));
  r["workspace_min"].get(ind.workspace_min);
  r["workspace_max"].get(ind.workspace_max);
  constexpr char kAxis[] = "xyz";
  for (int a = 0; a < 3; ++a)  // (both given: the box must not be empty; the build checks a derived corner)
    if (!(ind.workspace_max[a] > ind.workspace_min[a]))
      r["workspace_max"].fail(std::string("must exceed workspace_min in every component (") + kAxis[a] + ": " +
                              format_number(ind.workspace_max[a]) + " <= " + format_number(ind.workspace_min[a]) + ")");
  r["guide"].get(ind.guide, "tool guide", kToolGuides);
}

void read_contact(const Reader& r, ContactSpec& c) {
  r.object(kContactKeys);
  r["tolerance"].get(c.tolerance, closed(0.0, 1.0));
  r["max_iterations"].get(c.max_iterations, 1, 1000000);
}

void read_integrator(const Reader& r, IntegratorSpec& in) {
  r.object(kIntegratorKeys);
  r["type"].get(in.type, "integrator", kIntegrators);
  r["dt"].get(in.dt, open_closed(0.0, 1.0));
  r["damping"].get(in.damping, closed(0.0, 1e6));
  r["cg_tolerance"].get(in.cg_tolerance, open(0.0, 1.0));
  r["cg_max_iterations"].get(in.cg_max_iterations, 1, 1000000);
  r["allow_unstable_dt"].get(in.allow_unstable_dt);
  r["threads"].get(in.threads, 1, kMaxThreads);
  r["max_interval"].get(in.max_interval, 1, 64);
  if ((in.max_interval & (in.max_interval - 1)) != 0)
    r["max_interval"].fail("must be a power of two (1, 2, 4, ... 64), got " + std::to_string(in.max_interval));
}

void read_health(const Reader& r, HealthSpec& h) {
  r.object(kHealthKeys);
  r["enabled"].get(h.enabled);
  r["energy_factor"].get(h.energy_factor, closed_open(1.0, kInf));
  r["max_indenter_speed"].get(h.max_indenter_speed, closed_open(0.0, kInf));
  r["max_penetration"].get(h.max_penetration, closed_open(0.0, kInf));
  r["inversion_sweep_ticks"].get(h.inversion_sweep_ticks, 1, 1000000);
}

void read_gravity(const Reader& r, Vec3& g) {
  r.get(g);
  if (g.norm() > 1e3) r.fail("norm must be at most 1000 m/s^2, got " + format_number(g.norm()));
}

void read_verify(const Reader& r, VerifySpec& v) {
  r.object(kVerifyKeys);
  if (const Reader forces = r["forces"]; forces.present()) {
    v.forces.clear();
    for (const Reader& e : forces.elements("an array of forces in N")) {
      double f = 0.0;
      e.get(f, open_closed(0.0, 1e9));
      v.forces.push_back(f);
    }
  }
  const Reader rest = r["rest"];
  rest.object(kRestKeys);
  rest["velocity_tolerance"].get(v.rest.velocity_tolerance, at_least(0.0));
  rest["force_tolerance"].get(v.rest.force_tolerance, positive());
  rest["window"].get(v.rest.window, positive());
  rest["max_time"].get(v.rest.max_time, open_closed(0.0, 1e6));
}

}  // namespace palpate::scene_io
