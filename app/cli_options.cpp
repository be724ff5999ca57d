// Options of a pipeline run on the command line (see app/cli_options.h).
#include "app/cli_options.h"

#include <charconv>
#include <cmath>
#include <cstdlib>
#include <limits>
#include <string>

#include "solver/linear_solver.h"

namespace morphmap {
namespace {

// Validators of numeric options. CLI11's own called a value that is no number "not in range" and printed the
// largest double in full ("--trace-step: Value -1 not in range 0.000000 to 179769313486231570814527...").

bool read_real(const std::string& text, double& value) {
  if (text.empty()) return false;
  char* end = nullptr;
  value = std::strtod(text.c_str(), &end);
  return end == text.c_str() + text.size() && std::isfinite(value);
}

std::string in_quotes(const std::string& text) { return "'" + text + "'"; }

std::string shortest(double x) {
  char buffer[32];
  const auto result = std::to_chars(buffer, buffer + sizeof buffer, x);
  return std::string(buffer, result.ptr);
}

/// A finite number above zero (`strict`) or at least zero.
CLI::Validator real_above_zero(bool strict) {
  return CLI::Validator(
      [strict](std::string& text) -> std::string {
        double value = 0.0;
        if (read_real(text, value) && (strict ? value > 0.0 : value >= 0.0)) return {};
        return std::string(strict ? "must be a positive number" : "must be zero or a positive number") + ", not " +
               in_quotes(text);
      },
      strict ? "NUMBER > 0" : "NUMBER >= 0");
}
const CLI::Validator kPositive = real_above_zero(true);
const CLI::Validator kNonNegative = real_above_zero(false);

/// An on/off option setting `flag`; its default is the flag's value when the option is declared.
void add_switch(CLI::App& cmd, const std::string& name, bool& flag, const std::string& help) {
  cmd.add_option_function<std::string>(
         name, [&flag](const std::string& value) { flag = value == "on"; }, help)
      ->check(CLI::IsMember({"on", "off"}))
      ->default_str(flag ? "on" : "off");
}

/// A finite number in [lo, hi].
CLI::Validator real_in(double lo, double hi) {
  const std::string range = "from " + shortest(lo) + " to " + shortest(hi);
  return CLI::Validator(
      [lo, hi, range](std::string& text) -> std::string {
        double value = 0.0;
        if (read_real(text, value) && value >= lo && value <= hi) return {};
        return "must be a number " + range + ", not " + in_quotes(text);
      },
      "NUMBER in [" + shortest(lo) + ", " + shortest(hi) + "]");
}

}  // namespace

CLI::Validator whole_number(int lo, int hi) {
  const bool bounded = hi != std::numeric_limits<int>::max();
  const std::string range =
      bounded ? "from " + std::to_string(lo) + " to " + std::to_string(hi) : "of at least " + std::to_string(lo);
  return CLI::Validator(
      [lo, hi, range](std::string& text) -> std::string {
        long long value = 0;
        const auto result = std::from_chars(text.data(), text.data() + text.size(), value);
        const bool whole = !text.empty() && result.ec == std::errc() && result.ptr == text.data() + text.size();
        if (whole && value >= lo && value <= hi) return {};
        return "must be a whole number " + range + ", not " + in_quotes(text);
      },
      bounded ? "INT in [" + std::to_string(lo) + ", " + std::to_string(hi) + "]" : "INT >= " + std::to_string(lo));
}

void add_pipeline_options(CLI::App& cmd, PipelineOptions& o) {
  cmd.add_option("--voxels", o.morph.voxels, "Lattice voxels across the larger side of the union bounding box")
      ->check(whole_number(4, 4096))
      ->capture_default_str();
  cmd.add_option("--voxel-size", o.morph.voxel_size, "Explicit voxel size (overrides --voxels)")->check(kNonNegative);
  cmd.add_option("--morph", o.morph_method,
                 "Implicit morph: distance (distance-field interpolation) or vim (variational implicit, 4D r^3 "
                 "radial basis functions through samples of both surfaces)")
      ->check(CLI::IsMember({"distance", "vim"}))
      ->capture_default_str();
  cmd.add_option("--vim-samples", o.vim.samples, "vim: constraint points per surface (farthest-point samples)")
      ->check(whole_number(3, 20000))
      ->capture_default_str();
  cmd.add_option("--vim-separation", o.vim.separation,
                 "vim: distance between the planes of A and B in R^4, in units of the larger side of the union box")
      ->check(kPositive)
      ->capture_default_str();
  cmd.add_option("--vim-offset", o.vim.normal_offset,
                 "vim: distance of the normal constraints from the surface, in units of the larger side of the union "
                 "box")
      ->check(kPositive)
      ->capture_default_str();
  cmd.add_option("--time-steps", o.extract.time_steps, "Lattice intervals along the morph time t")
      ->check(whole_number(1, 4096))
      ->capture_default_str();
  cmd.add_option(
         "--time-scale", o.extract.time_scale,
         "Length of one unit of morph time in R^4 (c); 0 = twice the larger side of the shapes' union bounding box")
      ->check(kNonNegative)
      ->capture_default_str();
  cmd.add_option("--zero-snap", o.extract.zero_snap,
                 "Lattice values within this many voxels of zero move to +-it, keeping crossings (and the slivers they "
                 "make) off lattice points")
      ->check(real_in(0.0, 0.45))
      ->capture_default_str();
  const auto names = solver_names();
  cmd.add_option("--solver", o.laplace.solver, "Laplace solver backend")
      ->check(CLI::IsMember(names))
      ->capture_default_str();
  cmd.add_option("--tolerance", o.laplace.solve.tolerance, "Relative residual at which iterative solvers stop")
      ->check(kPositive)
      ->capture_default_str();
  cmd.add_option("--deflation-voxels", o.laplace.deflation_cell_voxels,
                 "CG solvers deflate the space-time cells of this many voxels (0: no deflation)")
      ->check(kNonNegative)
      ->capture_default_str();
  cmd.add_option("--max-iterations", o.laplace.solve.max_iterations, "Iteration limit of iterative solvers")
      ->check(whole_number(1))
      ->capture_default_str();
  cmd.add_option("--change-threshold", o.laplace.solve.change_threshold,
                 "gauss-seidel stops once the change of s in a sweep (--change-measure) is below this (0: after "
                 "--max-iterations sweeps)")
      ->check(kNonNegative)
      ->capture_default_str();
  cmd.add_option_function<std::string>(
         "--change-measure",
         [&o](const std::string& name) { o.laplace.solve.change_measure = parse_change_measure(name); },
         "gauss-seidel's change of a sweep: total (sum of |change| of s, the paper's) or mean (per unknown)")
      ->check(CLI::IsMember({"total", "mean"}))
      ->default_str(change_measure_name(o.laplace.solve.change_measure));
  cmd.add_option("--slices", o.slices, "Morph times in (0,1) at which to write slice_<t>.obj")->delimiter(',');
  cmd.add_option("--texture", o.texture,
                 "Image for the source's texture coordinates, in place of its MTL's (e.g. spot.obj with "
                 "spot_texture.png)");
  cmd.add_option("--align", o.align,
                 "none: meshes in their own coordinates; bbox: both normalised, outputs in the target's")
      ->check(CLI::IsMember({"none", "bbox"}))
      ->capture_default_str();
  cmd.add_option("--target-mesh", o.target_mesh,
                 "Mesh of the target (its coordinates) whose vertices get the labels and UVs; target.obj keeps its "
                 "connectivity (default: the extracted t = 1 surface)")
      ->check(CLI::ExistingFile);
  cmd.add_option("--method", o.method,
                 "How B and the slices find their preimages on A: trace (exact characteristics of grad s), upwind (the "
                 "paper's label propagation) or closest-point (no morph, the baseline)")
      ->check(CLI::IsMember({"trace", "upwind", "closest-point"}))
      ->capture_default_str();
  cmd.add_option("--source-projection", o.source_projection,
                 "How labels near the extracted source become points of the source mesh: inverse (the point whose "
                 "closest point on the extracted source the label is: a shape morphed to itself maps to itself) or "
                 "closest (the label's closest point)")
      ->check(CLI::IsMember({"inverse", "closest"}))
      ->capture_default_str();
  cmd.add_option("--trace-step", o.trace.step_variation,
                 "Characteristic tracing: largest change of the interpolated field over one Runge-Kutta step, "
                 "relative to its size")
      ->check(kPositive)
      ->capture_default_str();
  cmd.add_option("--trace-order", o.trace.order,
                 "Characteristic tracing: order of the Runge-Kutta step in each tet, 2 (Heun) or 4 (classical)")
      ->check(CLI::IsMember({2, 4}))
      ->capture_default_str();
  cmd.add_option("--trace-smoothing", o.trace.field_smoothing,
                 "Characteristic tracing: passes of neighbour averaging of the flow field before tracing")
      ->check(whole_number(0, 100))
      ->capture_default_str();
  cmd.add_option("--compare-solvers", o.compare_solvers,
                 "Also solve the same system with these backends and report each (Table II's diffusion column)")
      ->check(CLI::IsMember(names))
      ->delimiter(',');
  cmd.add_option("--seams", o.seams_mode,
                 "Split output triangles along seams: all, topological, texture or none (outputs keep the extracted "
                 "connectivity)")
      ->check(CLI::IsMember({"all", "topological", "texture", "none"}))
      ->capture_default_str();
  cmd.add_option("--seam-threshold", o.seams.label_threshold,
                 "A source tet spans a topological seam (its triangles are split there) when two of its labels are "
                 "farther apart than this fraction of the source's bounding-box diagonal")
      ->check(kPositive)
      ->capture_default_str();
  add_switch(cmd, "--fold-repair", o.untangle.enabled,
             "Repair folded and collapsed triangles of the target's map by local untangling in charts of the "
             "source, then symmetric Dirichlet smoothing around them (on or off; the closest-point method is never "
             "repaired)");
  add_switch(cmd, "--heal-seams", o.untangle.heal_seams,
             "With --fold-repair on, also lay out again the patches around topological seams that the ends' topology "
             "does not force (a disk around the seam whose boundary is a simple loop on the source), which closes them "
             "(on or off)");
  add_switch(cmd, "--direction-charts", o.untangle.direction_charts,
             "With --heal-seams on, try a seam's patch that no tangent plane of the source holds again in a "
             "stereographic chart of the directions from the source's centre (for a star-shaped source; on or off)");
  cmd.add_option("--compression-seed", o.untangle.compression_seed,
                 "With --fold-repair on, relieve the parts of the map around triangles compressed below this sigma2 "
                 "(Newton steps of the symmetric Dirichlet smoothing, then each vertex moved to where its worst "
                 "triangle is least compressed; a part is kept only where its figures improve; 0: off)")
      ->check(kNonNegative)
      ->capture_default_str();
  cmd.add_option_function<std::string>(
         "--stalled-fill", [&o](const std::string& value) { o.stalled_fill = value; },
         "Label the target's vertices whose characteristic stalls (parts born during the morph) from the traced "
         "vertices around them, by a mean-value convex combination, instead of the point of the source nearest to "
         "where the trace stopped (auto: with --fold-repair on; on; off)")
      ->check(CLI::IsMember({"auto", "on", "off"}))
      ->default_str("auto");
  cmd.add_option("--distances", o.morph.distances,
                 "A mesh's distances near its surface: exact (closest-point queries within the band, signs from the "
                 "winding number along the lattice lines) or openvdb (OpenVDB's meshToVolume: values a few percent "
                 "of a voxel off, signs flood-filled; slower on meshes of many small triangles)")
      ->check(CLI::IsMember({"exact", "openvdb"}))
      ->capture_default_str();
  add_switch(
      cmd, "--thin-features", o.morph.thin.enabled,
      "Keep sheets, rods and gaps thinner than a voxel on the lattice: a lattice edge crossing a mesh twice moves "
      "its end nearer the surface to the other side, so thin parts open no handles (on or off)");
  cmd.add_option("--morph-topology", o.morph_topology.mode,
                 "Topology changes of the distance-field morph: auto (none that the ends do not force when both ends "
                 "have one topology on the lattice), preserve (always: forced changes come last) or free (the plain "
                 "linear interpolation, as in the paper)")
      ->check(CLI::IsMember({"auto", "preserve", "free"}))
      ->capture_default_str();
  cmd.add_flag("--critical-points", o.critical_points,
               "Count the harmonic field's minima, maxima and saddles on the 4D mesh (report.json's "
               "critical_points; the saddles' separatrices are seams of the traced map)");
  cmd.add_flag("--ply", o.write_ply, "Also write target.ply");
  cmd.add_option("--threads", o.threads, "Worker threads (0 = all cores)")->check(whole_number(0));
  cmd.add_option_function<std::string>(
         "--max-memory", [&o](const std::string& text) { o.max_memory_bytes = parse_memory_size(text); },
         "Refuse a run whose estimated peak memory exceeds SIZE (e.g. 8G, 512M)")
      ->type_name("SIZE");
}

}  // namespace morphmap
