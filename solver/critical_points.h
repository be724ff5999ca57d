// Critical points of the harmonic field s on the 4D mesh (paper §6: s has none in the continuum between A and B
// when the morph is a product, and then its gradient's characteristics carry A onto B one to one). The discrete s can
// have them: minima where the cotangent weights go negative (the traces that stall) and saddles, whose separatrices
// are the seams of the traced map. Classified by piecewise-linear Morse theory (Banchoff; Edelsbrunner, Harer and
// Zomorodian 2003): an interior vertex's link is a 2-sphere, and the vertex is regular when the part of its link
// below it and the part above are each connected.
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <vector>

#include "mesh/adjacency.h"
#include "mesh/tet_mesh4.h"

namespace morphmap {

struct CriticalPointOptions {
  int keep = 64;  ///< how many saddle and extremum vertices to list (lowest s first), for reports and debugging
};

struct CriticalPointResult {
  std::int64_t interior_vertices = 0;  ///< vertices not on A or B
  std::int64_t minima = 0;             ///< interior vertices with no link vertex below (a trace stalls there)
  std::int64_t maxima = 0;             ///< interior vertices with no link vertex above
  std::int64_t saddles = 0;            ///< interior vertices whose lower or upper link has two or more parts
  /// The multiplicities: sum over saddles of (parts of the lower link - 1) + (parts of the upper link - 1), so a
  /// monkey saddle counts twice.
  std::int64_t saddle_multiplicity = 0;
  std::vector<int> listed;  ///< up to CriticalPointOptions::keep critical vertices, by increasing s (ties: index)
  double seconds = 0.0;
};

/// Classifies every interior vertex of `mesh` (side Interior) by the parts of its lower and upper link under `s`
/// (#V values; ties broken by vertex index, so no two vertices compare equal). `stars` are the mesh's vertex stars.
/// Parallel over vertices; the counts and the list do not depend on the thread count. Throws InvalidInput when s has
/// the wrong size.
CriticalPointResult critical_points(const TetMesh4& mesh, const VertexTets& stars, const Eigen::VectorXd& s,
                                    const CriticalPointOptions& options = {});

}  // namespace morphmap
