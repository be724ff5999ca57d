// Variational implicit morph (Turk and O'Brien 1999; paper §5.1, equation 3): one 4D implicit function
// G(x, tau) = P(x, tau) + sum_i w_i |(x, tau) - c_i|^3 whose zero set is A in the plane tau = 0 and B in the
// plane tau = separation, and which is smooth (minimal thin-plate-like energy) in between. The paper's sphere ->
// bunny map (its Figure 4 and Table I) was computed on such a morph; the distance-field morph (mesh/morph.h)
// interpolates linearly in time instead and grows protrusions such as the bunny's ears in fewer, more distorted
// steps.
#pragma once

#include "mesh/morph.h"
#include "mesh/surface.h"

namespace morphmap {

struct VimOptions {
  /// Constraint points per surface: farthest-point samples of its vertices (even spacing whatever the mesh's
  /// density), each with a value-0 constraint and an outward normal constraint, so 2 * samples centres per surface.
  /// The dense constraint system costs (4 * samples)^3 / 3 flops to factorise and every lattice value 4 * samples
  /// kernel evaluations per time level. Measured on sphere -> bunny (40 voxels, 8 steps, separation 0.5): 600
  /// samples max stretch 1082, variance 3.36, 2 stalled traces, morph 2.9 s; 1000: 352, 2.65, none, 3.9 s.
  int samples = 1000;
  /// Distance in R^4 between the planes of A (t = 0) and B (t = 1), as a multiple of the larger side of the union
  /// bounding box. Larger: the in-between shapes blend more smoothly and keep less of either end. Measured on
  /// sphere -> bunny (600 samples): 0.25 max stretch 2e7 (36 stalled traces), 0.5 1082 (2), 0.75 3343 (13), 1 3947
  /// (26), 2 5.5e12 (153, a tangled morph).
  double separation = 0.5;
  /// Normal constraints sit at p + offset * n (n the outward unit vertex normal) with value +offset, so G grows
  /// like a signed distance across the surface; offset as a multiple of the larger side of the union box.
  double normal_offset = 0.01;
};

/// Samples the variational implicit morph between A (t = 0) and B (t = 1) on the lattice build_morph would use
/// (morph_lattice) at the time levels t = l / time_steps, l = 0 .. time_steps: MorphField::levels. G is negative
/// inside, like the distance-field morph, and the corners of the lattice box carry their distances to A and B as
/// constraints too, so that G is positive far from both shapes.
/// The constraint system [Phi P; P^T 0] is solved on the null space of P^T (Householder QR of the 5 polynomial
/// columns), where Phi is positive definite for the conditionally positive definite kernel r^3: one dense
/// Cholesky factorisation. Lattice values are evaluated in parallel over z slabs, each value summed in a fixed
/// order, so the field does not depend on the thread count.
/// Throws InvalidInput for invalid options, SolverError when the constraint system is numerically singular
/// (coincident samples).
MorphResult build_vim_morph(const Surface& A, const Surface& B, const MorphOptions& lattice, const VimOptions& options,
                            int time_steps);

/// Bytes of the constraint system build_vim_morph factorises at most (fewer when a surface has fewer vertices than
/// samples): the pipeline's --max-memory guard checks it before the morph is built.
double vim_constraint_bytes(const VimOptions& options);

/// Indices of `count` farthest-point samples of the rows of V (#V by 3), starting at row 0; all rows when there are
/// no more than count. Ties go to the lower index.
std::vector<int> farthest_point_samples(const Eigen::MatrixXd& V, int count);

}  // namespace morphmap
