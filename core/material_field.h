#pragma once
// The material field of a heterogeneous body (scene material.inclusions): each
// particle's (hex FEM: each element's) share of every inclusion, sampled on a
// 4 x 4 x 4 midpoint grid of its cell, and the Lame parameters and density blended
// by volume fraction (Voigt, docs/physics.md (1.16)). A pipeline stage of build_model.
#include <string>
#include <vector>

#include "core/node_cloud.h"
#include "core/scene.h"
#include "core/types.h"

namespace palpate {

// Lame parameters of Young's modulus E and Poisson ratio nu.
struct LameParameters {
  double lambda = 0.0, mu = 0.0;  // Pa
};
LameParameters lame_parameters(double young_modulus, double poisson_ratio);

// Samples per axis of a cell (4^3 midpoints).
constexpr int kMaterialSamplesPerAxis = 4;

// The blended material of one cell (an axis-aligned box): sample points (midpoints of
// a kMaterialSamplesPerAxis^3 grid) take the last inclusion that contains them, else
// the matrix; lambda, mu and rho are the volume-fraction averages (1.16). A cell wholly
// inside one inclusion (every sample) gets exactly its parameters, one wholly outside
// exactly the matrix's. inclusion_fraction receives the share of samples in any inclusion.
struct CellMaterial {
  double lambda = 0.0, mu = 0.0, density = 0.0;
  double inclusion_fraction = 0.0;
};
CellMaterial cell_material(const MaterialSpec& material, const Vec3& cell_min, const Vec3& cell_max);

// Per-particle materials (Model::particle_lambda, particle_mu, particle_density) of n particles
// at `positions` with cells given by their bounds (3 x n each).
struct MaterialField {
  std::vector<double> lambda, mu, density, inclusion_fraction;  // n each
};
MaterialField material_field(const MaterialSpec& material, const Points& cell_min, const Points& cell_max);

// The group inclusions (shape "group": a physical volume of a tetrahedral mesh), blended
// into `field` after the shapes, in their order: particle i's share of the group is
// f_i = sum over its tetrahedra t in the group of |V_t| / 4, divided by v_i = sum over all its
// tetrahedra of |V_t| / 4 (the lumped volumes of the mesh, mesh_reader.h), and each of
// lambda, mu, rho becomes (1 - f_i) x (what it was) + f_i x the group's (1.16). A particle
// whose tetrahedra all lie in the group gets exactly its parameters. Throws SceneError at
// /material/inclusions/<k>/group for a cloud without tetrahedra or a name the mesh does
// not have (listing those it has).
void blend_group_inclusions(const MaterialSpec& material, const NodeCloud& cloud, const std::string& source,
                            MaterialField& field);

// The physical volume tag (in cloud.tetrahedron_region) of the group inclusion number k of
// `material`, with the refusals above (a cloud without tetrahedra, an unknown name).
int64_t group_inclusion_tag(const MaterialSpec& material, size_t k, const NodeCloud& cloud, const std::string& source);

// The cell of each lattice node: along each axis from the midpoint to the previous node to
// the midpoint to the next (the box's face at the ends), the cell whose volume is the
// node's lattice volume (node_cloud.cpp). per_axis the lattice's nodes per axis, node
// i = a + nx (b + ny c).
void lattice_cells(const Points& positions, const Eigen::Vector3i& per_axis, Points& cell_min, Points& cell_max);
// A cube of volume v_i centred on each particle (clouds without a lattice).
void cube_cells(const Points& positions, const std::vector<double>& volume, Points& cell_min, Points& cell_max);

}  // namespace palpate
