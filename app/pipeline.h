// The whole pipeline of DESIGN.md composed: load -> morph -> extract -> laplace -> gradient ->
// transport -> map -> transfer -> outputs (paper §§5-9).
#pragma once

#include <string>
#include <vector>

#include "io/render.h"
#include "mesh/extract.h"
#include "mesh/label_fill.h"
#include "mesh/metrics.h"
#include "mesh/morph.h"
#include "mesh/morph_topology.h"
#include "mesh/seams.h"
#include "mesh/slice.h"
#include "mesh/untangle.h"
#include "mesh/vim.h"
#include "solver/laplace.h"
#include "solver/trace.h"
#include "solver/transport.h"

namespace morphmap {

struct PipelineOptions {
  std::string source;      ///< mesh file or built-in shape spec (see mesh/shapes.h)
  std::string target;      ///< mesh file or built-in shape spec
  std::string output_dir;  ///< outputs go here (created if missing); empty = compute only
  /// Optional mesh file in the target's coordinates (typically the target itself, or a finer/other mesh of it):
  /// its vertices get labels and UVs (each through its closest point on the extracted B) and target.obj keeps its
  /// connectivity. Empty: the extracted B (the t = 1 boundary of the 4D mesh) is the output.
  std::string target_mesh;
  /// Optional image for the source's texture coordinates, in place of the one its MTL names (an OBJ without an MTL,
  /// such as spot.obj beside spot_texture.png, has none). The source must have texture coordinates.
  std::string texture;
  std::string align = "none";  ///< "none": meshes in their own coordinates; "bbox": both normalised to a unit box
  MorphOptions morph;          ///< lattice resolution
  /// "distance": the distance-field morph (mesh/morph.h, Payne and Toga); "vim": the variational implicit morph
  /// (mesh/vim.h, Turk and O'Brien), the paper's morph for sphere -> bunny
  std::string morph_method = "distance";
  VimOptions vim;  ///< samples, plane separation and normal offset of the variational implicit morph
  /// Topology changes of the distance-field morph kept out where the ends do not force them (mesh/morph_topology.h)
  MorphTopologyOptions morph_topology;
  ExtractOptions extract;                    ///< time steps, time scale
  LaplaceOptions laplace;                    ///< solver backend and tolerance
  std::vector<std::string> compare_solvers;  ///< backends also run on the same system, reported under "compare"
                                             ///< in report.json (the map uses laplace.solver only)
  /// How B and the slices get their preimages on A: "trace" follows each vertex's characteristic of grad s back
  /// to A exactly (solver/trace.h); "upwind" reads the paper's label propagation (§7, solver/transport.h);
  /// "closest-point" maps every vertex to its closest point of A (no morph: the baseline other tools use).
  std::string method = "trace";
  /// How a label (a point on or near the extracted A: a trace's end, A's side of the upwind sweep) becomes a point of
  /// A's mesh: "inverse" finds the point of A whose closest point on the extracted A it is (A's vertices are moved
  /// to their closest points there and the label located among A's faces so moved), which undoes --target-mesh's
  /// entry into B through closest points on the extracted B, so a morph of a shape to itself maps its vertices to
  /// themselves; "closest" takes the label's closest point of A. The closest-point method always uses "closest".
  std::string source_projection = "inverse";
  TransportOptions transport;  ///< upwind sweep tolerances (the sweep also labels the 4D mesh for seams)
  TraceOptions trace;          ///< characteristic tracing tolerances
  SeamOptions seams;           ///< topological and texture seam splitting of target.obj and slices (§8)
  /// Repair of folded, collapsed and stretched triangles of B's map before the seam split (mesh/untangle.h; on by
  /// default, --fold-repair off); the closest-point baseline is never repaired. Its seam threshold is
  /// seams.label_threshold.
  UntangleOptions untangle;
  /// Labels of B's vertices whose characteristic stalled, from the traced vertices around them (mesh/label_fill.h;
  /// trace method only): "auto" fills them when the fold repair is on, "on" always, "off" never. Measured on sphere
  /// -> bunny (README, "Fold repair"): with the repair it removes most of the repair's erratic maxima; without it the
  /// filled ear tips enter the statistics folded and stretched (40 voxels: max 378 -> 860, folds 312 -> 377).
  std::string stalled_fill = "auto";
  std::string seams_mode = "all";  ///< "all", "topological", "texture" or "none": overrides seams.topological/texture
  std::vector<double> slices;      ///< morph times in (0, 1) at which to write slice_<t>.obj
  bool write_ply = false;          ///< also write target.ply
  /// Classify the harmonic field's interior vertices (solver/critical_points.h) into report.json's
  /// "critical_points": 0.11 s on sphere -> bunny's 389 k interior vertices, so not by default
  bool critical_points = false;
  int threads = 0;  ///< worker threads; 0 = all cores
  long long max_memory_bytes =
      0;                         ///< refuse (InvalidInput) a run whose estimated peak memory exceeds this; 0 = no limit
  bool progress = false;         ///< print stage names and times to stderr
  bool render = false;           ///< write contact_sheet.png (A, the slices, B with one camera) into output_dir
  RenderOptions render_options;  ///< size and camera of each contact sheet panel
};

struct PipelineResult {
  std::string report_json;  ///< the report.json text (also written to output_dir)
  SliceMesh target;         ///< B as extracted (t = 1 boundary): V in B's coordinates, labels raw (morph frame)
  Eigen::MatrixXd
      target_labels;          ///< #target.V by 3: preimage on A (closest point of A to the raw label), A's coordinates
  Eigen::MatrixXd target_uv;  ///< #target.V by 2 texture coordinates; empty when A has no UVs
  SeamResult target_seams;    ///< B split along seams (what target.obj holds), V and labels in the morph frame
  std::int64_t mesh_vertices = 0;  ///< vertices of the 4D tet mesh
  std::int64_t mesh_tets = 0;
  std::int64_t fallbacks = 0;  ///< transport fallbacks
};

/// Estimated peak resident memory of a whole run (bytes) from the lattice size and the exact mesh counts
/// known after extraction's counting pass. Coefficients measured on sphere -> torus/bunny and cow -> horse.
long long estimate_peak_memory(std::int64_t lattice_points, std::int64_t tets, std::int64_t vertices);

/// Parses "123", "512M", "8G", "1.5T" (binary units) into bytes; throws InvalidInput naming the text.
long long parse_memory_size(const std::string& text);

/// Stretch figures as report.json and `morphmap stretch` print them.
std::string stretch_json(const StretchResult& stretch);

/// `morphmap stretch`: reads TARGET (a mesh file), one preimage per vertex from LABELS, and SOURCE (a file or a
/// built-in shape, placed as read_stretch_inputs says) and returns the stretch figures.
StretchResult stretch_of_files(const std::string& target, const std::string& labels, const std::string& source);

/// What `morphmap stretch` and `render --heat` read: SOURCE (A), TARGET (B) and one preimage per vertex of B. A
/// built-in SOURCE without centre or size is placed where `map` placed it when TARGET's folder holds the map's
/// report.json (its inputs.source_shape, for the same inputs.source), else fitted to TARGET's box, which is the
/// extracted target's and so not quite the box `map` fitted it to (`source_fitted_to_target`).
struct StretchInputs {
  Surface A, B;
  Eigen::MatrixXd preimages;             ///< #B.V by 3, points of A
  std::string source_shape;              ///< a built-in SOURCE's spec as placed (empty for a file)
  bool source_fitted_to_target = false;  ///< placed by TARGET's box, for want of the map's report.json
};
StretchInputs read_stretch_inputs(const std::string& target, const std::string& labels, const std::string& source);

/// `morphmap render`: renders MESH (a file) with `options`; with LABELS and SOURCE (both or neither) as a heat
/// map of the per-triangle L2 stretch of the map MESH -> SOURCE. Throws InvalidInput / IoError naming the file.
RenderResult render_file(const std::string& mesh, const std::string& labels, const std::string& source,
                         const RenderOptions& options);

/// Runs every stage and writes the outputs (target.obj, labels.txt, slices, report.json) atomically
/// into options.output_dir. Throws InvalidInput / IoError / TopologyError / SolverError.
PipelineResult run_pipeline(const PipelineOptions& options);

}  // namespace morphmap
