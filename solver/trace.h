// Characteristics of the flow T traced back from B (and from slices) to A (paper §7: "L is constant along a
// trajectory"). The paper propagates labels with an upwind scheme because tracing particles "must be moved in
// small steps"; in barycentric coordinates no small steps are needed: with T interpolated linearly from the
// vertex field (§6.2) the weights obey a linear ODE in each tet, integrated per tet in a few Runge-Kutta steps
// and ended exactly on a face. Tracing gives each output vertex its preimage with no numerical diffusion, where
// the upwind sweep averages the labels of a whole upwind face at every vertex (first order: labels smear).
//
// The per-tet gradients of s are not used: that field is discontinuous across faces, and its streamlines merge
// on every face both tets flow into (measured on two offset spheres: 4.5 face slides per trace, 600 folded
// triangles, where the interpolated field folds none). They serve only where the flow stalls: from there the
// steepest descent of s (linear in each simplex) continues the trace, since s falls along it in every step
// (measured, cow -> horse 1.7M tets: 1798 of 5958 stalled traces reach A so, the rest stop at discrete local
// minima of s; folded triangles 1945 -> 1538, L2 p99 496 -> 47 against the upwind label where they stopped).
#pragma once

#include <Eigen/Core>
#include <array>
#include <cstdint>
#include <memory>
#include <vector>

#include "mesh/adjacency.h"
#include "mesh/tet_mesh4.h"

namespace morphmap {

struct LatticeFaces;

struct TraceOptions {
  /// A barycentric weight at or below this counts as zero: the point lies on the opposite face.
  double weight_epsilon = 1e-12;
  /// A simplex is entered through a face only when the rate of the weight opposite it exceeds rate_tolerance *
  /// (largest |rate| of the simplex); below that the flow runs along the face, and the face is followed instead.
  double rate_tolerance = 1e-9;
  /// Runge-Kutta steps are limited so that the field's variation over one step, relative to its size, stays
  /// below this (the error of one RK4 step is about its fifth power / 120). Measured on sphere -> bunny: 1 moves
  /// the labels from those at 0.25 by a median 4e-9 and a 99th percentile of 1e-5 (the box is 3.1) and changes no
  /// stretch figure in its third digit, at 60% of the evaluations; 4 moves them by a median 0.06.
  double step_variation = 1.0;
  /// Order of the Runge-Kutta step in a simplex: 2 (Heun: 2 evaluations a piece, the end slope of the exit's
  /// Hermite interpolant taken from the predictor) or 4 (classical: 5; the figures for step_variation above are
  /// its). Measured, 2 against 4: the labels of sphere -> bunny moved by a median 4e-6 and a 99th percentile of
  /// 8e-5 of their box diagonal (a voxel is 1.4e-2 of it), cow -> horse 2e-5 and 3e-3; a dozen traces near
  /// separatrices took the other side. Cow -> horse: half the evaluations (21.6 M -> 10.5 M), tracing 0.96-1.01 s
  /// -> 0.77-0.84 s.
  int order = 2;
  /// Passes of neighbour averaging applied to the vertex field before tracing (each vertex: the mean of its own
  /// and its star's vertices' unit vectors, normalised). Averaged tet gradients are only first-order accurate,
  /// and their noise at the scale of a tet becomes noise of the traced map between neighbouring vertices.
  int field_smoothing = 1;
  /// Give up (status stalled) after this many pieces (a piece ends on a face of its simplex): bounds orbits
  /// around stagnation points of T. Traces on the test morphs need at most a few hundred.
  int max_steps = 20000;
  /// A trace stalls when s at its point has not fallen by `progress` over the last `progress_window` pieces
  /// (orbits around stagnation points of T; measured: cow -> horse at 1.7M tets had 6018 traces circling until
  /// max_steps, 148 s of tracing). Normal traces need at most about 240 pieces for s to fall from 1 to 0.
  int progress_window = 256;
  double progress = 1e-6;
  /// A trace whose flow stalls continues from there down the steepest descent of s (linear in each simplex), which
  /// falls in every step and so cannot circle; status Descended when that reaches A. Without it a stalled trace
  /// ends where it stopped.
  bool descend = true;
};

/// A point of the tet mesh: a convex combination of 1 to 4 mesh vertices (unused ids -1, weights 0).
struct MeshPoint {
  std::array<int, 4> ids{{-1, -1, -1, -1}};
  std::array<double, 4> weights{{0.0, 0.0, 0.0, 0.0}};
};

enum class TraceStatus : std::uint8_t {
  Reached = 0,    ///< the characteristic reached A (the t = 0 boundary)
  Stalled = 1,    ///< it stopped where T vanishes or turns back, and so did the descent of s if it ran (e.g. a
                  ///< component born mid-morph, where s is flat)
  Invalid = 2,    ///< the start point is not a valid mesh point (no tet holds its vertices)
  Descended = 3,  ///< the flow stalled; the steepest descent of s from there reached A (TraceOptions::descend)
};

struct TraceResult {
  Eigen::MatrixXd end;               ///< #starts by 3: x, y, z where each trace ends (on A when Reached or Descended)
  std::vector<MeshPoint> end_point;  ///< #starts: the mesh point where it ended (for fallbacks of stalled traces)
  std::vector<TraceStatus> status;   ///< #starts
  std::int64_t reached = 0, stalled = 0, invalid = 0, descended = 0;
  std::int64_t descent_pieces = 0;    ///< pieces of the descents (also counted by simplex below)
  std::int64_t tet_pieces = 0;        ///< straight pieces through a tet's interior
  std::int64_t face_pieces = 0;       ///< pieces that slide along a face (T of both tets points into it)
  std::int64_t edge_pieces = 0;       ///< pieces along an edge
  std::int64_t max_pieces = 0;        ///< the longest characteristic, in pieces
  std::int64_t rate_evaluations = 0;  ///< evaluations of the weight ODE's right-hand side: the tracer's work
  double seconds = 0.0;
};

/// The tracer as a stateful object: vertex stars, vertex normals and the smoothed field are built once by the
/// constructor (which checks the inputs and throws InvalidInput naming the problem), so the target and every slice
/// are traced without rebuilding them (or the stars are the caller's, `stars`). `mesh`, `s` and `vertex_field` must
/// outlive it. `faces`, the extraction's record of mesh (ExtractOptions::face_neighbours), gives the tet across
/// every face (lattice_face_neighbours) where the stars are searched without it (face_neighbours).
class CharacteristicTracer {
 public:
  CharacteristicTracer(const TetMesh4& mesh, const Eigen::VectorXd& s, const Eigen::MatrixXd& vertex_field,
                       const TraceOptions& options = {}, const SharedStars& stars = nullptr,
                       const LatticeFaces* faces = nullptr);
  ~CharacteristicTracer();
  CharacteristicTracer(const CharacteristicTracer&) = delete;
  CharacteristicTracer& operator=(const CharacteristicTracer&) = delete;

  /// Traces every start point (see trace_to_source); TraceResult::seconds covers this call only.
  TraceResult trace(const std::vector<MeshPoint>& starts) const;
  double setup_seconds() const;  ///< what the constructor took

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

/// Traces -T (vertex_field, #V by 4, interpolated linearly in each tet and projected into the tet's hull) from
/// every start point back to the side-A boundary. Where the flow leaves a tet through a face whose other tet
/// sends it back (both projections point into the face, where the 3-manifold bends), the characteristic slides
/// along the face with T projected into the face, and likewise along edges. Among the simplices a point can move
/// into, tets come before faces before edges, the one T is best aligned with first; ties go to the lower tet
/// index, so the result does not depend on the thread count. Parallel over start points.
/// `s` (#V, the harmonic field T comes from) only measures progress: a trace along which s has not fallen by
/// TraceOptions::progress over TraceOptions::progress_window pieces circles a stagnation point and stalls.
/// One-shot form of CharacteristicTracer (its seconds include the set-up).
TraceResult trace_to_source(const TetMesh4& mesh, const Eigen::VectorXd& s, const Eigen::MatrixXd& vertex_field,
                            const std::vector<MeshPoint>& starts, const TraceOptions& options = {});

/// Start points for every vertex of a slice / boundary surface whose vertex i lies on the mesh edge
/// (edge(i, 0), edge(i, 1)) at weight w(i) towards edge(i, 1) (SliceMesh::source_edge and edge_weight).
std::vector<MeshPoint> edge_points(const Eigen::MatrixXi& edge, const Eigen::VectorXd& w);

}  // namespace morphmap
