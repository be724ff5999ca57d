// Laplace-Beltrami operator on the tetrahedral 3-manifold in R^4 and the harmonic field s with
// s = 0 on A and s = 1 on B (paper §6.1, equation 4 in its 3D cotangent form).
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <string>
#include <vector>

#include "mesh/adjacency.h"
#include "mesh/quality.h"
#include "mesh/tet_mesh4.h"
#include "solver/linear_solver.h"

namespace morphmap {

/// Edge frame of tet t: E = [v1 - v0, v2 - v0, v3 - v0] (4 by 3), the inverse of its Gram matrix E^T E and
/// the 3-volume sqrt(det E^T E) / 6. Returns false (volume 0, gram_inverse unset) for a degenerate tet, one
/// whose det E^T E is at rounding level relative to the product of its squared edge lengths: such a tet
/// has no usable hull and every stage skips it.
bool tet_frame(const Points4& V, const TetIndices& T, Eigen::Index t, Eigen::Matrix<double, 4, 3>& E,
               Eigen::Matrix3d& gram_inverse, double& volume);
/// tet_frame without the Gram inverse: E and the volume, and the same answer for degenerate tets.
bool tet_frame(const Points4& V, const TetIndices& T, Eigen::Index t, Eigen::Matrix<double, 4, 3>& E, double& volume);

/// Barycentric gradients and volumes of every tet, computed in the tet's own 3D hull from the Gram
/// matrix of its edge vectors (no 3D embedding needed).
/// G: #T*4 by 4, row 4*t + i is the gradient (in R^4) of the hat function of T(t, i). vol: #T.
/// Degenerate tets (see tet_frame) get zero gradients and zero volume, so they contribute nothing.
void barycentric_gradients(const Points4& V, const TetIndices& T, Eigen::MatrixXd& G, Eigen::VectorXd& vol);

/// P1 stiffness matrix K = sum over tets of vol * G_t^T G_t (#V by #V, symmetric positive semidefinite,
/// rows sum to zero). Off-diagonals equal -(1/6) l_kl cot(theta_kl) summed over tets of edge ij.
/// Assembly is TBB-parallel over rows, each row summed in incident-tet order straight into compressed
/// storage, so K is bitwise the same for any thread count.
SparseMatrixD cotangent_stiffness(const Points4& V, const TetIndices& T);

struct LaplaceOptions {
  std::string solver = "cg-amg";  ///< backend name for make_solver. In one interleaved bench/bench_solve.cpp run over
                                  ///< the 9 morph systems (0.2M-1.7M tets, to residual 1e-8, medians of 5) cg-amg
                                  ///< took 6-8x fewer iterations than cg and 1.5-2.2x less time from 0.7M tets up;
                                  ///< at 0.2M it tied with cg (0.9-1.2x). 180-410x faster than ldlt, 4-7x than
                                  ///< gauss-seidel, 10-24x than cholmod
  SolveOptions solve;             ///< tolerance, iteration limit and (gauss-seidel) change threshold
  bool warm_start = true;  ///< iterative backends (cg, cg-ic, cg-amg, gauss-seidel, auto) start from s = t instead of 0
  /// Also measure the mesh quality (LaplaceResult::quality) from the local stiffness, which the assembly computes
  /// anyway (quality_from_stiffness): on cow -> horse 0.13 s instead of the 0.19 s of measure_quality's own pass over
  /// the tets' geometry (medians of 5 interleaved runs), and 0.07-0.08 s against 0.11-0.14 s since its edge figures
  /// read the assembled rows (add_edge_figures; 3 interleaved runs, identical figures).
  bool measure_quality = false;
  /// Deflate the CG backends' solve by the space-time cells of this many voxels (space_time_cells); 0 = off.
  /// See README "Solvers" for the measurement that chose it.
  double deflation_cell_voxels = 6.0;
};

/// The Dirichlet problem of solve_harmonic as one linear system A x = b over the unknowns: the interior vertices
/// of components that touch A or B, numbered in vertex order. A = K_II (SPD), b = -K_IB s_B.
struct DirichletSystem {
  SparseMatrixD A;                       ///< #unknowns by #unknowns, both triangles stored
  Eigen::VectorXd b;                     ///< #unknowns
  Eigen::VectorXd x0;                    ///< #unknowns: morph time t of each unknown, the warm start s = t
  Eigen::VectorXd s;                     ///< #V: 0 on A, 1 on B, floating components' mean t; 0 at unknowns
  std::vector<int> unknown;              ///< #V: the vertex's unknown, or -1 for a fixed vertex
  std::int64_t floating_components = 0;  ///< see LaplaceResult
  std::int64_t floating_vertices = 0;
  std::int64_t degenerate_tets = 0;
  double assemble_seconds = 0.0;  ///< local stiffness, components, A and b
  /// #V: component_labels of the tets with stiffness, which are every tet when degenerate_tets is 0 (and then these
  /// are the census's labels, component_census)
  std::vector<int> component_root;
};

/// Assembles the system solve_harmonic solves (it calls this), for benchmarks and external solvers. `stars`: the
/// mesh's vertex stars when the caller has them (built here otherwise). `quality`, when given, receives
/// quality_from_stiffness's figures of the local stiffness, its edge figures summed from the assembled rows
/// (quality_angles_from_stiffness, then add_edge_figures; its seconds are not in assemble_seconds). Throws InvalidInput
/// for inconsistent mesh arrays.
DirichletSystem dirichlet_system(const TetMesh4& mesh, const SharedStars& stars = nullptr,
                                 QualityResult* quality = nullptr);

/// space_time_cells' default max_columns.
constexpr int kMaxDeflationColumns = 20000;

/// The coarse space that deflates the solve (DeflationSpace): functions piecewise constant on cubes of
/// `cell_voxels` lattice voxels in space and piecewise linear in t between the lattice's time levels (the hats of
/// the K + 1 levels), restricted to the unknowns (`unknown`: #V, a vertex's unknown or -1). CG's slow modes on these
/// systems are smooth in space-time: the tets are many times longer in time than wide, so an aggregation hierarchy,
/// which coarsens along the strong spatial couplings, keeps nearly every time level and corrects modes that vary
/// slowly in t poorly. A hat whose cell holds too few unknowns spread over t to keep the columns independent is
/// left out: each kept hat gets an unknown of its own in its support, with increasing t along the cell's hats
/// (Schoenberg and Whitney's condition, which makes the columns of a cell independent). 0 columns when
/// cell_voxels <= 0 or the mesh has no voxel size. A space of more than max_columns columns is rebuilt with cells
/// 1.5 times larger until it has at most that many: the factor of Z^T A Z, solved once per CG iteration on one
/// thread, grows faster than the columns (cow -> horse at 21 M tets has 12903 with 6-voxel cells).
/// `couplings` (the system matrix: #unknowns by #unknowns, symmetric), when given, splits each cell into the connected
/// parts of its unknowns along the matrix's nonzeros: a cube can hold two sheets of the surface that meet only far away
/// (the horse's legs, the sides of a thin part), and one column for both ties values that the solve keeps apart. On cow
/// -> horse the split takes cg-amg from 34 to 29 iterations (1309 -> 1347 columns); the other Table II morphs
/// keep their iteration counts within one. Throws InvalidInput for a couplings matrix of another size.
DeflationSpace space_time_cells(const TetMesh4& mesh, const std::vector<int>& unknown, int unknowns, double cell_voxels,
                                int max_columns = kMaxDeflationColumns, const SparseMatrixD* couplings = nullptr);

struct LaplaceResult {
  Eigen::VectorXd s;                     ///< #V harmonic field, 0 on A, 1 on B
  SolveReport report;                    ///< backend diagnostics
  std::int64_t unknowns = 0;             ///< interior vertices solved for
  std::int64_t floating_components = 0;  ///< components touching neither A nor B: s set to their mean t
  std::int64_t floating_vertices = 0;
  std::int64_t degenerate_tets = 0;  ///< zero-volume tets left out of the operator (see tet_frame)
  std::vector<int> component_root;   ///< DirichletSystem::component_root
  double assemble_seconds = 0.0;
  QualityResult quality;  ///< with LaplaceOptions::measure_quality (its seconds are part of `seconds`)
  double seconds = 0.0;   ///< whole stage
};

/// Solves the Dirichlet problem. Components with no boundary vertex would make the system singular:
/// they are detected, excluded from the solve, and get s = their mean morph time (counted).
LaplaceResult solve_harmonic(const TetMesh4& mesh, const LaplaceOptions& options, const SharedStars& stars = nullptr);

}  // namespace morphmap
