// Composition of the stages of DESIGN.md (paper §§5-9). Every stage runs before any output is
// written, and outputs are staged and renamed into place, so a failed run leaves nothing behind.
#include "app/pipeline.h"

#include <sys/resource.h>
#include <tbb/global_control.h>
#include <tbb/parallel_invoke.h>
#include <unistd.h>

#include <algorithm>
#include <charconv>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <iomanip>
#include <iostream>
#include <limits>
#include <nlohmann/json.hpp>
#include <optional>
#include <sstream>

#include "app/allocator.h"
#include "app/solver_compare.h"
#include "io/image.h"
#include "io/mesh_io.h"
#include "io/output_dir.h"
#include "mesh/adjacency.h"
#include "mesh/errors.h"
#include "mesh/quality.h"
#include "mesh/shapes.h"
#include "mesh/stopwatch.h"
#include "mesh/transfer.h"
#include "solver/critical_points.h"
#include "solver/gradient.h"
#include "solver/linear_solver.h"

namespace morphmap {
namespace {

// Similarity x -> (x - center) / scale that brings a surface into the common morph frame.
struct Frame {
  Eigen::Vector3d center = Eigen::Vector3d::Zero();
  double scale = 1.0;
  Eigen::MatrixXd to_world(const Eigen::MatrixXd& P) const { return (P * scale).rowwise() + center.transpose(); }
  Eigen::MatrixXd to_frame(const Eigen::MatrixXd& P) const { return (P.rowwise() - center.transpose()) / scale; }
};

Frame normalise(Surface& surface) {
  const Eigen::AlignedBox3d box = bounding_box(surface.V);
  Frame frame;
  frame.center = box.center();
  frame.scale = 0.5 * box.sizes().maxCoeff();
  surface.V = (surface.V.rowwise() - frame.center.transpose()) / frame.scale;
  if (surface.signed_distance)
    surface.signed_distance = [world = surface.signed_distance, frame](const Eigen::Vector3d& x) {
      return world(x * frame.scale + frame.center) / frame.scale;
    };
  return frame;
}

class Progress {
 public:
  explicit Progress(bool enabled) : enabled_(enabled), start_(Clock::now()) {}
  void stage(const std::string& name, double seconds) const {
    if (enabled_)
      std::fprintf(stderr, "[morphmap] %-10s %8.3f s  (elapsed %.1f s)\n", name.c_str(), seconds,
                   seconds_since(start_));
  }

 private:
  bool enabled_;
  Clock::time_point start_;
};

// The shortest text that reads back as t: slice_<t>.obj names stay unique (with six digits 0.3 and 0.3000001 both
// named slice_0.3.obj, and the second overwrote the first while report.json listed both).
std::string format_time(double t) {
  char buffer[32];
  const auto result = std::to_chars(buffer, buffer + sizeof buffer, t);
  return std::string(buffer, result.ptr);
}

// What load_inputs did to the inputs (index 0 the source, 1 the target), for report.json's `inputs`.
struct InputNotes {
  // A built-in shape's spec as placed (empty for a mesh), so that `morphmap stretch` can rebuild the very shape the
  // map used: fitted to target.obj's box instead, a sphere came out 0.5% larger than the one fitted to the torus.
  std::string shape[2];
  bool reoriented[2] = {false, false};  // its faces wound inward and were turned
  std::int64_t welded[2] = {0, 0};      // vertices merged into another at the same position (an open mesh closed)
  std::vector<std::string> warnings;    // what the run goes on without (a texture that is not there)
};

// make_shape(spec, fit), and in `placed` the spec as placed (report.json's inputs.*_shape), from which make_shape
// rebuilds the same surface without the box.
Surface placed_shape(const ShapeSpec& spec, const std::optional<Eigen::AlignedBox3d>& fit, std::string& placed) {
  placed = shape_spec_string(resolve_shape_spec(spec, fit));
  return make_shape(spec, fit);
}

// validate_surface(surface, true); a mesh that is not closed as read but is once vertices at bitwise-equal positions
// are merged (exported with its vertices split at texture or normal seams, or as a triangle soup) is taken welded.
// Otherwise the error is the mesh's as read.
SurfaceCheck validate_welding(Surface& surface, std::int64_t& welded) {
  try {
    return validate_surface(surface, true);
  } catch (const InvalidInput& as_read) {
    Surface joined = surface;
    const std::int64_t merged = weld_coincident_vertices(joined);
    if (merged == 0) throw;
    SurfaceCheck check;
    try {
      check = validate_surface(joined, true);
    } catch (const InvalidInput&) {
      throw as_read;
    }
    surface = std::move(joined);
    welded = merged;
    return check;
  }
}

void load_inputs(const PipelineOptions& options, Surface& A, Surface& B, SurfaceCheck& check_a, SurfaceCheck& check_b,
                 InputNotes& notes) {
  const bool a_builtin = is_builtin_shape(options.source), b_builtin = is_builtin_shape(options.target);
  // Parse both specs first so that a bad spec is reported before any file is read.
  std::optional<ShapeSpec> a_spec, b_spec;
  if (a_builtin) a_spec = parse_shape_spec(options.source);
  if (b_builtin) b_spec = parse_shape_spec(options.target);
  if (!b_builtin) B = read_surface(options.target);
  if (!a_builtin) A = read_surface(options.source);
  if (b_builtin) B = placed_shape(*b_spec, a_builtin ? std::nullopt : std::optional(bounding_box(A.V)), notes.shape[1]);
  if (a_builtin) A = placed_shape(*a_spec, std::optional(bounding_box(B.V)), notes.shape[0]);
  check_a = validate_welding(A, notes.welded[0]);
  check_b = validate_welding(B, notes.welded[1]);
  // A mesh whose faces wind inward is mapped as the same solid, its faces turned (measured: a sphere -> bunny map
  // from bunny_closed.obj with its faces reversed counted 12852 folded triangles instead of 135).
  notes.reoriented[0] = orient_outward(A);
  notes.reoriented[1] = orient_outward(B);
  if (!options.texture.empty()) {
    if (!A.has_uv())
      throw InvalidInput(options.texture + ": --texture needs texture coordinates on the source, which " +
                         options.source + " does not have");
    // Read now, so that an unreadable image is reported before any work; the outputs re-encode it as PNG.
    A.texture = std::make_shared<const RgbImage>(read_image(options.texture));
    A.texture_path = options.texture;
  } else if (!A.texture_path.empty() && !A.texture) {
    // The MTL's image, decoded once to check it (the outputs copy the file as it is): an unreadable one, such as a
    // truncated download, was copied and named by target.mtl without a word.
    try {
      (void)read_image(A.texture_path);
    } catch (const IoError& e) {
      throw InvalidInput(options.source + ": the texture its material names is unusable: " + e.what() +
                         " (give another with --texture)");
    }
  } else if (!A.missing_texture.empty() && A.has_uv()) {
    notes.warnings.push_back(
        options.source + ": its material names the texture " + A.missing_texture +
        ", which does not exist: target.obj gets the UVs but no texture (give one with --texture)");
  }
  if (options.texture.empty() && !A.other_textures.empty() && A.has_uv()) {
    // Each face's UVs refer to its own material's image; one image is carried, so the other materials' faces are
    // textured from the wrong one.
    std::string names;
    for (const std::string& name : A.other_textures) names += (names.empty() ? "" : ", ") + name;
    notes.warnings.push_back(options.source +
                             ": its materials name more than one texture; target.obj carries the first " +
                             "for every face, not " + names + " (merge them into one atlas first)");
  }
}

void write_labels(const std::string& path, const Eigen::MatrixXd& labels) {
  // std::to_chars with 17 significant digits is printf's "%.17g", the text `ostream << setprecision(17)` wrote, at a
  // fraction of the cost of the stream's locale-aware formatting.
  std::string text;
  text.reserve(std::size_t(labels.rows()) * 72);
  char buffer[32];
  for (Eigen::Index i = 0; i < labels.rows(); ++i)
    for (int c = 0; c < 3; ++c) {
      const auto result = std::to_chars(buffer, buffer + sizeof buffer, labels(i, c), std::chars_format::general, 17);
      text.append(buffer, result.ptr);
      text.push_back(c < 2 ? ' ' : '\n');
    }
  std::ofstream out(path, std::ios::binary);
  if (!out) throw IoError(path + ": cannot open for writing");
  out.write(text.data(), std::streamsize(text.size()));
  if (!out) throw IoError(path + ": write failed");
}

// --target-mesh: the user's mesh of B (in B's coordinates) as the output surface. Each vertex takes its closest
// point on the extracted B, a point of a boundary face of the 4D mesh, from which `labels_at` (trace or
// interpolation, by method) gives its label. No provenance in the 4D mesh: source_tet and source_edge are zero.
SliceMesh user_target_mesh(const PipelineOptions& options, const Frame& frame_b, const SliceMesh& extracted,
                           const std::function<Eigen::MatrixXd(const std::vector<MeshPoint>&)>& labels_at,
                           bool& reoriented, std::vector<double>& distance) {
  const Surface user = read_surface(options.target_mesh);
  validate_surface(user, false);
  Surface on_b;
  on_b.V = extracted.V;
  on_b.F = extracted.F.cast<int>();
  on_b.name = "the extracted target";
  const SurfaceLocator locator(on_b);
  SliceMesh out;
  out.V = frame_b.to_frame(user.V);
  out.F = user.F;
  // A mesh wound inward is turned, as the inputs are (it may be open, so its winding is compared with the extracted
  // B's, outward, face by face, weighted by area): the fold counts and the repair take its winding as outward, and an
  // inward bunny_closed.obj counted 59619 folded triangles instead of 260.
  {
    Eigen::MatrixXd centroids(out.F.rows(), 3);
    for (Eigen::Index f = 0; f < out.F.rows(); ++f)
      centroids.row(f) = (out.V.row(out.F(f, 0)) + out.V.row(out.F(f, 1)) + out.V.row(out.F(f, 2))) / 3.0;
    const std::vector<SurfaceHit> near = locator.closest_all(centroids);
    const auto normal = [](const Eigen::MatrixXd& V, const auto& F, Eigen::Index t) {
      const Eigen::Vector3d a = V.row(F(t, 0)), b = V.row(F(t, 1)), c = V.row(F(t, 2));
      return Eigen::Vector3d((b - a).cross(c - a));
    };
    double agreement = 0.0;
    for (Eigen::Index f = 0; f < out.F.rows(); ++f) {
      agreement +=
          normal(out.V, out.F, f).dot(normal(extracted.V, extracted.F, near[std::size_t(f)].face).normalized());
    }
    reoriented = agreement < 0.0;
    if (reoriented) out.F.col(1).swap(out.F.col(2));
  }
  const std::vector<SurfaceHit> hits = locator.closest_all(out.V);
  std::vector<MeshPoint> points(hits.size());
  distance.resize(hits.size());
  for (std::size_t i = 0; i < hits.size(); ++i) {
    distance[i] = hits[i].distance;
    for (int k = 0; k < 3; ++k) {
      const int corner = extracted.F(hits[i].face, k);
      // Every vertex of the t = 1 boundary is a mesh vertex (its edge is (v, v)).
      if (extracted.source_edge(corner, 0) != extracted.source_edge(corner, 1))
        throw TopologyError("--target-mesh: the extracted target has a vertex inside a mesh edge");
      points[i].ids[std::size_t(k)] = extracted.source_edge(corner, 0);
      points[i].weights[std::size_t(k)] = hits[i].barycentric(k);
    }
  }
  out.labels = labels_at(points);
  out.source_tet.assign(std::size_t(out.F.rows()), 0);
  out.source_edge = Eigen::MatrixXi::Zero(out.V.rows(), 2);
  out.edge_weight = Eigen::VectorXd::Zero(out.V.rows());
  out.t = 1.0;
  return out;
}

// The mesh point at vertex v.
MeshPoint vertex_point(int v) {
  MeshPoint p;
  p.ids[0] = v;
  p.weights[0] = 1.0;
  return p;
}

// The label at a mesh point: the weighted labels of its vertices.
Eigen::RowVector3d interpolate(const MeshPoint& p, const Eigen::MatrixXd& labels) {
  Eigen::RowVector3d label = Eigen::RowVector3d::Zero();
  for (int k = 0; k < 4; ++k)
    if (p.ids[std::size_t(k)] >= 0) label += p.weights[std::size_t(k)] * labels.row(p.ids[std::size_t(k)]);
  return label;
}

constexpr double kGiB = 1024.0 * 1024.0 * 1024.0;

std::string gib(double bytes) {
  std::ostringstream s;
  s << std::setprecision(3) << bytes / kGiB << " GiB";
  return s.str();
}

}  // namespace

long long estimate_peak_memory(std::int64_t lattice_points, std::int64_t tets, std::int64_t vertices) {
  // Fitted to report.json peak_memory_bytes (refitted 2026-12-03, late night, after the source cells, the volumes,
  // the deflation's triplets and the writers' whole-file buffers left the peak) with 7-17% to spare: demo 0.401 GB
  // (2.37M tets, 0.41M vertices), sphere -> bunny 0.414 GB (2.45M, 0.43M), cow -> horse 0.299 GB (1.66M, 0.30M), at
  // 160 voxels and 16 steps 3.06 GB (21.0M, 3.6M, 3.8M lattice points), and the demo at 20 voxels and 5 steps
  // 0.132 GB (0.34M tets; the base is the libraries and, there, rendering the contact sheet). Per tet: the mesh, the
  // stars, the local stiffness and the CSC matrix; per vertex: positions, s, solver vectors, the field, labels.
  // 2026-12-08: 8 bytes a tet more, the extraction's record of the lattice faces (ExtractResult::faces), held for the
  // tracer through the Laplace stage (demo 0.392 -> 0.409 GB, cow -> horse 0.282 -> 0.305 GB).
  constexpr double kBase = 95e6, kPerLatticePoint = 12.0, kPerTet = 130.0, kPerVertex = 160.0;
  return (long long)(kBase + kPerLatticePoint * double(lattice_points) + kPerTet * double(tets) +
                     kPerVertex * double(vertices));
}

long long parse_memory_size(const std::string& text) {
  std::size_t used = 0;
  double value = 0.0;
  try {
    value = std::stod(text, &used);
  } catch (const std::exception&) {
    throw InvalidInput("--max-memory: cannot read '" + text + "' (examples: 8G, 512M, 2000000000)");
  }
  std::string unit = text.substr(used);
  // 8GB and 8GiB mean 8G (binary units either way, as free(1) and top print them).
  for (const char* suffix : {"iB", "ib", "B", "b"})
    if (unit.size() == 1 + std::strlen(suffix) && unit.compare(1, std::string::npos, suffix) == 0) {
      unit.resize(1);
      break;
    }
  double scale = 1.0;
  if (unit == "K" || unit == "k")
    scale = 1024.0;
  else if (unit == "M" || unit == "m")
    scale = 1024.0 * 1024.0;
  else if (unit == "G" || unit == "g")
    scale = kGiB;
  else if (unit == "T" || unit == "t")
    scale = 1024.0 * kGiB;
  else if (!unit.empty())
    throw InvalidInput("--max-memory: unknown unit in '" + text + "' (use K, M, G or T)");
  if (!(value > 0.0) || !std::isfinite(value))
    throw InvalidInput("--max-memory: '" + text + "' is not a positive size");
  // Beyond 2^63 bytes the cast is undefined (99999999999999999999G passed or failed by chance): no limit then.
  const double bytes = value * scale;
  return bytes >= 9.2e18 ? std::numeric_limits<long long>::max() : (long long)bytes;
}

std::string stretch_json(const StretchResult& r) {
  const nlohmann::json j = {
      {"triangles", r.triangles},    {"measured", r.measured},       {"min_compression", r.min_sigma2},
      {"max_stretch", r.max_sigma1}, {"mean_l2", r.mean_l2},         {"variance_l2", r.variance_l2},
      {"sander_l2", r.sander_l2},    {"folded", r.folded},           {"collapsed", r.collapsed},
      {"degenerate", r.degenerate},  {"coverage", r.coverage},       {"area_source", r.area_a},
      {"area_target", r.area_b},     {"l2_median", r.l2_median},     {"l2_p90", r.l2_p90},
      {"l2_p99", r.l2_p99},          {"area_over_2", r.area_over_2}, {"area_over_10", r.area_over_10}};
  return j.dump(2);
}

namespace {

// The seams section of report.json (also per slice).
nlohmann::json seams_json(const SeamResult& r, const SeamOptions& o) {
  return {{"threshold", r.threshold},
          {"threshold_diagonals", o.label_threshold},
          {"threshold_rule",
           "a source tet spans a topological seam when two of its labels are farther apart than threshold_diagonals "
           "times A's bounding-box diagonal; label_span_histogram shows the gap between ordinary and seam triangles"},
          {"label_span_bin_edges_diagonals", r.span_bin_edges},
          {"label_span_histogram", r.span_histogram},
          {"seam_tets", r.seam_tets},
          {"topological_split", r.topological_split},
          {"topological_seam_curves", r.topological_seam_curves},
          {"topological_seam_regions", r.topological_seam_regions},
          {"topological_seam_vertices", r.topological_seam_points.rows()},
          {"spans_over_threshold", r.spans_over_threshold},
          {"texture_split", r.texture_split},
          {"texture_crossings", r.texture_crossings},
          {"texture_fan_splits", r.texture_fan_splits},
          {"texture_seam_curves", r.texture_seam_curves},
          {"unresolved_edges", r.unresolved_edges},
          {"uv_area_excess", r.uv_area_excess},
          {"uv_area_excess_unsplit", r.uv_area_excess_unsplit},
          {"uv_area_tolerance", o.uv_area_tolerance},
          {"uv_area_rule",
           "a triangle exceeds when its UV area > image UV area + uv_area_tolerance * max(image UV area, mean "
           "image UV area); image = the triangle's preimage sampled 4x4 in one chart of A's atlas"},
          {"tolerance_sweep", r.tolerance_sweep},
          {"uv_area_excess_sweep", r.uv_area_excess_sweep},
          {"uv_area_excess_unsplit_sweep", r.uv_area_excess_unsplit_sweep},
          {"max_uv_area_ratio", r.max_uv_area_ratio},
          {"mean_preimage_uv_area", r.mean_preimage_uv_area},
          {"triangles", r.F.rows()},
          {"vertices", r.V.rows()},
          {"seconds", r.seconds}};
}

// The source shape `map` placed for `source` (report.json's inputs.source_shape beside `target`), if that report is
// there, readable and of the same source.
std::optional<ShapeSpec> mapped_source_shape(const std::string& target, const std::string& source) {
  const std::filesystem::path report_path = std::filesystem::path(target).parent_path() / "report.json";
  std::ifstream in(report_path);
  if (!in) return std::nullopt;
  const nlohmann::json report = nlohmann::json::parse(in, nullptr, false);
  if (report.is_discarded() || !report.is_object()) return std::nullopt;
  const nlohmann::json::json_pointer source_key("/inputs/source"), shape_key("/inputs/source_shape");
  if (!report.contains(source_key) || !report.contains(shape_key) || report.at(source_key) != source ||
      !report.at(shape_key).is_string())
    return std::nullopt;
  try {
    return parse_shape_spec(report.at(shape_key).get<std::string>());
  } catch (const InvalidInput&) {
    return std::nullopt;
  }
}

}  // namespace

StretchInputs read_stretch_inputs(const std::string& target, const std::string& labels, const std::string& source) {
  StretchInputs inputs;
  Surface& B = inputs.B;
  Surface& A = inputs.A;
  B = read_surface(target);
  validate_surface(B, false);
  if (is_builtin_shape(source)) {
    const ShapeSpec spec = parse_shape_spec(source);
    const std::optional<ShapeSpec> mapped =
        spec.center && spec.size ? std::nullopt : mapped_source_shape(target, source);
    if (mapped) {
      A = placed_shape(*mapped, std::nullopt, inputs.source_shape);
    } else {
      inputs.source_fitted_to_target = !spec.center || !spec.size;
      A = placed_shape(spec, std::optional(bounding_box(B.V)), inputs.source_shape);
    }
  } else {
    A = read_surface(source);
  }
  std::int64_t welded = 0;
  validate_welding(A, welded);  // as `map` does
  orient_outward(A);
  std::ifstream in(labels);
  if (!in) throw IoError(labels + ": cannot open file");
  Eigen::MatrixXd& pre = inputs.preimages;
  pre.resize(B.V.rows(), 3);
  std::string line;
  Eigen::Index row = 0;
  while (std::getline(in, line)) {
    if (line.empty()) continue;
    std::istringstream fields(line);
    double x, y, z;
    if (!(fields >> x >> y >> z) || !std::isfinite(x) || !std::isfinite(y) || !std::isfinite(z))
      throw InvalidInput(labels + ": line " + std::to_string(row + 1) + " is not three finite numbers");
    if (row >= pre.rows())
      throw InvalidInput(labels + ": more lines than the " + std::to_string(pre.rows()) + " vertices of " + target);
    pre.row(row++) << x, y, z;
  }
  if (row != pre.rows())
    throw InvalidInput(labels + ": " + std::to_string(row) + " lines for the " + std::to_string(pre.rows()) +
                       " vertices of " + target);
  return inputs;
}

StretchResult stretch_of_files(const std::string& target, const std::string& labels, const std::string& source) {
  const StretchInputs in = read_stretch_inputs(target, labels, source);
  return measure_stretch(in.A, in.B.V, in.B.F, in.preimages);
}

RenderResult render_file(const std::string& mesh, const std::string& labels, const std::string& source,
                         const RenderOptions& options) {
  if (labels.empty() != source.empty()) throw InvalidInput("render: --heat LABELS and --source SOURCE go together");
  if (!labels.empty()) {
    const StretchInputs in = read_stretch_inputs(mesh, labels, source);
    RenderOptions heat = options;
    heat.mode = RenderMode::heat;
    return render_surface(in.B, heat, stretch_per_triangle(in.A, in.B.V, in.B.F, in.preimages));
  }
  const Surface surface = read_surface(mesh);
  validate_surface(surface, false);
  return render_surface(surface, options);
}

PipelineResult run_pipeline(const PipelineOptions& options) {
  const auto start_total = Clock::now();
  std::optional<tbb::global_control> threads;
  if (options.threads > 0) threads.emplace(tbb::global_control::max_allowed_parallelism, std::size_t(options.threads));
  if (options.align != "none" && options.align != "bbox")
    throw InvalidInput("--align: unknown value '" + options.align + "' (choose none, bbox)");
  if (options.seams_mode != "all" && options.seams_mode != "topological" && options.seams_mode != "texture" &&
      options.seams_mode != "none")
    throw InvalidInput("--seams: unknown value '" + options.seams_mode + "' (choose all, topological, texture, none)");
  if (options.morph_method != "distance" && options.morph_method != "vim")
    throw InvalidInput("--morph: unknown value '" + options.morph_method + "' (choose distance, vim)");
  if (options.method != "trace" && options.method != "upwind" && options.method != "closest-point")
    throw InvalidInput("--method: unknown value '" + options.method + "' (choose trace, upwind, closest-point)");
  if (options.source_projection != "inverse" && options.source_projection != "closest")
    throw InvalidInput("--source-projection: unknown value '" + options.source_projection +
                       "' (choose inverse, closest)");
  if (options.morph_topology.mode != "free" && options.morph_topology.mode != "auto" &&
      options.morph_topology.mode != "preserve")
    throw InvalidInput("--morph-topology: unknown value '" + options.morph_topology.mode +
                       "' (choose free, auto, preserve)");
  // An option that would do nothing is refused rather than ignored.
  if (options.morph_method == "vim" && options.morph_topology.mode != "free")
    throw InvalidInput("--morph-topology " + options.morph_topology.mode +
                       ": only the distance-field morph is resampled (--morph vim samples its own time levels)");
  if (options.critical_points && options.method == "closest-point")
    throw InvalidInput("--critical-points: the closest-point method solves no harmonic field to classify");
  // Each time once, in the order given: a repeated time would write the same file twice and list it twice.
  std::vector<double> slice_times;
  for (double t : options.slices) {
    if (!(t > 0.0 && t < 1.0)) throw InvalidInput("--slices: time " + format_time(t) + " is not in (0, 1)");
    if (std::find(slice_times.begin(), slice_times.end(), t) == slice_times.end()) slice_times.push_back(t);
  }
  (void)make_solver(options.laplace.solver, options.laplace.solve);  // rejects an unknown backend before any work
  for (const std::string& name : options.compare_solvers) (void)make_solver(name, options.laplace.solve);

  Progress progress(options.progress);
  nlohmann::json report;
  nlohmann::json& seconds = report["seconds"];

  auto start = Clock::now();
  Surface A, B;
  SurfaceCheck input_check_a, input_check_b;
  InputNotes input_notes;
  load_inputs(options, A, B, input_check_a, input_check_b, input_notes);
  Frame frame_a, frame_b;
  if (options.align == "bbox") {
    frame_a = normalise(A);
    frame_b = normalise(B);
  }
  seconds["load"] = seconds_since(start);
  progress.stage("load", seconds["load"]);

  if (options.morph_method == "vim" && options.max_memory_bytes > 0) {
    const double bytes = vim_constraint_bytes(options.vim);
    if (bytes > double(options.max_memory_bytes))
      throw InvalidInput("--max-memory: the variational morph's constraint system needs about " + gib(bytes) + " (" +
                         std::to_string(options.vim.samples) + " samples per surface), over the limit of " +
                         gib(double(options.max_memory_bytes)) + "; lower --vim-samples");
  }
  if (options.max_memory_bytes > 0) {
    // The lattice alone, before the morph allocates it (the estimate below comes only after the extraction counts):
    // 2000 voxels a side asks for 8 billion points.
    const std::int64_t points = morph_lattice(A, B, options.morph).point_count();
    const long long bytes = estimate_peak_memory(points, 0, 0);
    if (bytes > options.max_memory_bytes)
      throw InvalidInput("--max-memory: the lattice alone (" + std::to_string(points) + " points) needs about " +
                         gib(double(bytes)) + ", over the limit of " + gib(double(options.max_memory_bytes)) +
                         "; lower --voxels or raise --voxel-size");
  }
  const SurfaceCheck input_checks[2] = {input_check_a, input_check_b};  // the topology the thin features keep
  MorphResult morph = options.morph_method == "vim"
                          ? build_vim_morph(A, B, options.morph, options.vim, options.extract.time_steps)
                          : build_morph(A, B, options.morph, input_checks);
  // The variational morph is sampled per level already and changes topology smoothly; only the linear
  // interpolation of two distance fields is resampled.
  MorphTopologyResult morph_topology;
  if (morph.method == "distance") {
    morph_topology = keep_morph_topology(morph.field, options.extract.time_steps, options.morph_topology);
    morph.seconds += morph_topology.seconds;
  }
  seconds["morph"] = morph.seconds;
  progress.stage("morph", morph.seconds);

  long long memory_estimate = 0;
  ExtractOptions extract_options = options.extract;
  extract_options.before_allocate = [&](std::int64_t tets, std::int64_t vertices) {
    memory_estimate = estimate_peak_memory(morph.lattice_points, tets, vertices);
    if (options.max_memory_bytes > 0 && memory_estimate > options.max_memory_bytes)
      throw InvalidInput("--max-memory: this run needs about " + gib(double(memory_estimate)) + " (" +
                         std::to_string(tets) + " tets, " + std::to_string(vertices) +
                         " vertices), over the limit of " + gib(double(options.max_memory_bytes)) +
                         "; lower --voxels or --time-steps");
  };
  // The traced map's tracer takes the face neighbours from the lattice instead of searching the vertex stars.
  extract_options.face_neighbours = options.method == "trace";
  ExtractResult extract = extract_hypersurface(morph.field, extract_options);
  // The samples are read by the extraction only; a resampled morph's levels ((K + 1) floats a lattice point) would
  // otherwise still be held at the run's peak in the Laplace stage.
  std::vector<float>().swap(morph.field.levels);
  std::vector<float>().swap(morph.field.dA);
  std::vector<float>().swap(morph.field.dB);
  seconds["extract"] = extract.seconds;
  progress.stage("extract", extract.seconds);
  const TetMesh4& mesh = extract.mesh;

  // The vertex stars, built once for every stage that walks them.
  start = Clock::now();
  const SharedStars stars = std::make_shared<const VertexTets>(build_vertex_tets(mesh.T, mesh.vertex_count()));
  seconds["stars"] = seconds_since(start);

  // The quality stage reads the Laplace stage's local stiffness (quality_from_stiffness) where there is one: on
  // cow -> horse that took it from 0.19 to 0.13 s (medians of 5 interleaved runs), with identical figures, and its
  // edge figures, read from the assembled rows, to 0.07-0.08 s.
  const bool closest_point = options.method == "closest-point";
  QualityResult quality;
  LaplaceResult laplace;
  if (!closest_point) {
    LaplaceOptions laplace_options = options.laplace;
    laplace_options.measure_quality = true;
    laplace = solve_harmonic(mesh, laplace_options, stars);
    quality = std::move(laplace.quality);
    seconds["quality"] = quality.seconds;
    seconds["laplace"] = laplace.seconds - quality.seconds;
    progress.stage("laplace", laplace.seconds);
  } else {
    quality = measure_quality(mesh, {}, stars);
    seconds["quality"] = quality.seconds;
    progress.stage("quality", quality.seconds);
    laplace.s = Eigen::VectorXd::Zero(mesh.vertex_count());
  }

  CriticalPointResult critical;
  if (options.critical_points) {  // refused above with the closest-point method, which solves no field
    critical = critical_points(mesh, *stars, laplace.s);
    seconds["critical_points"] = critical.seconds;
    progress.stage("critical points", critical.seconds);
  }

  SolverComparisonResult comparison;
  if (!options.compare_solvers.empty() && !closest_point) {
    comparison = compare_solvers(mesh, laplace.s, options.compare_solvers, options.laplace);
    seconds["compare"] = comparison.seconds;
    progress.stage("compare", comparison.seconds);
  }

  start = Clock::now();
  const SurfaceLocator locator(A);
  // Labels (trace ends, and A's side of the upwind sweep) lie on or near the extracted A; "inverse" takes them to
  // A's mesh through the inverse of A's closest-point map onto the extracted A, the way --target-mesh enters B
  // through its closest points on the extracted B, so the two projections undo each other where the morph does
  // nothing: cow -> cow with --target-mesh cow.off maps 96% of the vertices to themselves within 1e-9 of the box
  // diagonal (horse 99%, bunny 100%), where the closest point of A to the closest point of the extracted A moved
  // every one, by a median 9e-4, and folded 310 triangles (now 32). The closest-point baseline keeps its definition.
  std::unique_ptr<SurfaceLocator> projector;
  nlohmann::json projection_report = {{"method", closest_point ? "closest" : options.source_projection}};
  if (!closest_point && options.source_projection == "inverse") {
    const auto projection_start = Clock::now();
    const SliceMesh extracted_a = source_boundary(mesh, Eigen::MatrixXd());
    if (extracted_a.F.rows() == 0) {
      // A vanished on the lattice (smaller than a voxel): nothing to invert, every label is a fallback anyway.
      projection_report = {
          {"method", "closest"}, {"requested", "inverse"}, {"reason", "the extracted source is empty"}};
    } else {
      Surface on_a;
      on_a.V = extracted_a.V;
      on_a.F = extracted_a.F.cast<int>();
      on_a.name = "the extracted source";
      const std::vector<SurfaceHit> offsets = SurfaceLocator(on_a).closest_all(A.V);
      double largest = 0.0;
      for (const SurfaceHit& hit : offsets) largest = std::max(largest, hit.distance);
      projector = std::make_unique<SurfaceLocator>(A, points_of(offsets));
      projection_report["largest_offset_voxels"] = largest / morph.field.voxel_size;
      projection_report["seconds"] = seconds_since(projection_start);
    }
  }
  const SurfaceLocator& to_a = projector ? *projector : locator;
  auto onto_a = [&](TraceResult traced) {
    if (projector) traced.end = points_of(projector->closest_all(traced.end));
    return traced;
  };
  const double locator_seconds = seconds_since(start);
  TransportResult transport;
  GradientResult gradient;
  if (!closest_point) {
    gradient = compute_gradient(mesh, laplace.s, stars);
    // Only the vertex field is read from here on: the per-tet gradients and volumes (40 bytes a tet, 0.84 GB at 21 M
    // tets) are released before the tracer, the slices and the outputs allocate theirs.
    gradient.tet_gradient = Points4();
    gradient.tet_volume = Eigen::VectorXd();
    seconds["gradient"] = gradient.seconds;
    progress.stage("gradient", gradient.seconds);
  }
  if (options.method == "upwind") {
    transport = transport_labels(
        mesh, laplace.s, gradient.vertex_field, [&](const Eigen::Vector3d& x) { return to_a.closest(x).point; },
        options.transport, stars);
    seconds["transport"] = transport.seconds;
    progress.stage("transport", transport.seconds);
  } else {
    // The closest-point baseline labels every mesh vertex with its own position (its closest point on A is
    // taken below, like every label's); the seams then see that map's jumps. The traced map needs no sweep: every
    // label it outputs is traced, and the mesh vertices no surface cuts keep their position, which nothing reads.
    transport.labels = mesh.V.leftCols(3);
  }

  // Characteristics traced back from the vertices of B and of every slice replace their interpolated labels,
  // and those from the vertices of the tets these surfaces cut give the labels there, which the seam split reads
  // (so seams are cut where the traced map jumps; on the target only where a tet may span a seam, see below). A trace
  // whose flow stalls continues down the steepest descent of s; where that cannot move either (s flat: a component born
  // mid-morph) the label is where it stopped, whose closest point on A is taken like every label's.
  TraceResult traced_total;
  Eigen::MatrixXd mesh_labels;  // #mesh.V by 3: traced labels at the vertices of cut tets
  std::vector<char> vertex_traced;
  if (options.method == "trace") {
    mesh_labels = transport.labels;
    vertex_traced.assign(std::size_t(mesh.vertex_count()), 0);
  }
  const Eigen::MatrixXd& seam_labels = options.method == "trace" ? mesh_labels : transport.labels;
  // Built once for the target and every slice.
  std::optional<CharacteristicTracer> tracer;
  if (options.method == "trace") {
    tracer.emplace(mesh, laplace.s, gradient.vertex_field, options.trace, stars, &extract.faces);
    extract.faces = LatticeFaces{};
    traced_total.seconds += tracer->setup_seconds();
  }
  auto add_trace = [&](const TraceResult& traced) {
    traced_total.reached += traced.reached;
    traced_total.stalled += traced.stalled;
    traced_total.descended += traced.descended;
    traced_total.descent_pieces += traced.descent_pieces;
    traced_total.invalid += traced.invalid;
    traced_total.tet_pieces += traced.tet_pieces;
    traced_total.face_pieces += traced.face_pieces;
    traced_total.edge_pieces += traced.edge_pieces;
    traced_total.rate_evaluations += traced.rate_evaluations;
    traced_total.max_pieces = std::max(traced_total.max_pieces, traced.max_pieces);
    traced_total.seconds += traced.seconds;
  };
  auto trace_labels = [&](SliceMesh& slice) {
    if (options.method != "trace") return;
    std::vector<MeshPoint> starts = edge_points(slice.source_edge, slice.edge_weight);
    const std::size_t own = starts.size();
    std::vector<int> vertices;
    for (int t : slice.source_tet)
      for (int k = 0; k < 4; ++k) {
        const int v = mesh.T(t, k);
        if (vertex_traced[std::size_t(v)]) continue;
        vertex_traced[std::size_t(v)] = 1;
        vertices.push_back(v);
        starts.push_back(vertex_point(v));
      }
    const TraceResult traced = onto_a(tracer->trace(starts));
    slice.labels = traced.end.topRows(Eigen::Index(own));
    for (std::size_t j = 0; j < vertices.size(); ++j)
      mesh_labels.row(vertices[j]) = traced.end.row(Eigen::Index(own + j));
    add_trace(traced);
  };

  // The target (the t = 1 boundary): each triangle's source tet has three B vertices and one below B, whose label
  // the topological seam split reads. That vertex is traced only where the tet may span a seam: it first takes
  // the label of a B vertex of its first tet (B triangle order), and the tets whose four labels then span more
  // than a quarter of the seam threshold get their lower vertices traced. Elsewhere the B labels lie well within
  // the threshold, a traced lower vertex could only cut a face whose own labels all agree, and tracing them all
  // was 60% of the tracing on cow -> horse (31 k of 49 k characteristics). The labels the target's seam split
  // reads are kept apart (target_labels_4d), so the traces of slices do not change them.
  Eigen::MatrixXd target_labels_4d;
  LabelFillResult label_fill;
  auto trace_target_labels = [&](SliceMesh& target) {
    if (options.method != "trace") return;
    const TraceResult traced = onto_a(tracer->trace(edge_points(target.source_edge, target.edge_weight)));
    add_trace(traced);
    std::vector<char> provisional(std::size_t(mesh.vertex_count()), 0);
    target.labels = traced.end;
    std::vector<char> stalled(std::size_t(target.V.rows()), 0);
    for (Eigen::Index i = 0; i < target.V.rows(); ++i)
      stalled[std::size_t(i)] = traced.status[std::size_t(i)] == TraceStatus::Stalled;
    LabelFillOptions fill_options;
    fill_options.enabled = options.stalled_fill == "on" || (options.stalled_fill == "auto" && options.untangle.enabled);
    label_fill = fill_stalled_labels(target.V, target.F, stalled, locator, target.labels, fill_options);
    for (Eigen::Index i = 0; i < target.V.rows(); ++i) {
      const int v = target.source_edge(i, 0);  // a B vertex: source_edge(i, 1) == v, weight 0
      mesh_labels.row(v) = target.labels.row(i);
      vertex_traced[std::size_t(v)] = 1;
    }
    for (const int t : target.source_tet)
      for (int k = 0; k < 4; ++k) {
        const int v = mesh.T(t, k);
        if (vertex_traced[std::size_t(v)] || provisional[std::size_t(v)]) continue;
        provisional[std::size_t(v)] = 1;
        for (int j = 0; j < 4; ++j)
          if (vertex_traced[std::size_t(mesh.T(t, j))]) {
            mesh_labels.row(v) = mesh_labels.row(mesh.T(t, j));
            break;
          }
      }
    const double near = 0.25 * options.seams.label_threshold * bounding_box(A.V).diagonal().norm();
    std::vector<MeshPoint> starts;
    std::vector<int> vertices;
    for (const int t : target.source_tet) {
      double span = 0.0;
      for (int a = 0; a < 4; ++a)
        for (int b = a + 1; b < 4; ++b)
          span = std::max(span, (mesh_labels.row(mesh.T(t, a)) - mesh_labels.row(mesh.T(t, b))).norm());
      if (!(span > near)) continue;
      for (int k = 0; k < 4; ++k) {
        const int v = mesh.T(t, k);
        if (provisional[std::size_t(v)] != 1) continue;
        provisional[std::size_t(v)] = 2;  // queued
        vertices.push_back(v);
        starts.push_back(vertex_point(v));
      }
    }
    const TraceResult lower = onto_a(tracer->trace(starts));
    add_trace(lower);
    for (std::size_t j = 0; j < vertices.size(); ++j) {
      mesh_labels.row(vertices[j]) = lower.end.row(Eigen::Index(j));
      vertex_traced[std::size_t(vertices[j])] = 1;
    }
    target_labels_4d = mesh_labels;
  };

  start = Clock::now();
  PipelineResult result;
  result.target = target_boundary(mesh, transport.labels);
  const Eigen::Index extracted_vertices = result.target.V.rows(), extracted_triangles = result.target.F.rows();
  const auto check_b_start = Clock::now();
  const SurfaceCheck extracted_check_b = check_surface(Eigen::MatrixXi(result.target.F), extracted_vertices);
  const double extracted_check_b_seconds = seconds_since(check_b_start);
  const bool user_target = !options.target_mesh.empty();
  bool target_mesh_reoriented = false;
  std::vector<double> target_mesh_distance;  // of each --target-mesh vertex from the extracted B, in the frame
  if (user_target) {
    result.target = user_target_mesh(
        options, frame_b, result.target,
        [&](const std::vector<MeshPoint>& points) {
          Eigen::MatrixXd labels(Eigen::Index(points.size()), 3);
          if (options.method == "trace") {
            const TraceResult traced = onto_a(tracer->trace(points));
            labels = traced.end;
            add_trace(traced);
          } else {
            for (std::size_t i = 0; i < points.size(); ++i)
              labels.row(Eigen::Index(i)) = interpolate(points[i], transport.labels);
          }
          return labels;
        },
        target_mesh_reoriented, target_mesh_distance);
  } else {
    trace_target_labels(result.target);
  }
  std::vector<SurfaceHit> hits = locator.closest_all(result.target.labels);
  // The tracer's set-up (its face neighbours and vertex normals) ran before `start` and is the map's too; B's
  // topology check ran inside it and is the topology stage's.
  const double tracer_setup_seconds = tracer ? tracer->setup_seconds() : 0.0;
  seconds["map"] = seconds_since(start) + locator_seconds + tracer_setup_seconds - extracted_check_b_seconds;
  progress.stage("map", seconds["map"]);

  // Fold repair of B's map (mesh/untangle.h). The repaired labels are points of A; the topological seam split reads
  // the labels of B's 4D vertices, so they move with them (a user's mesh has no 4D vertices).
  UntangleResult untangle;
  Eigen::MatrixXd target_seam_labels;  // the 4D labels the target's seam split reads, when the repair moved some
  std::vector<char> relabelled;        // B's vertices the repair moved (the seam split keeps their triangles whole)
  const bool repair = options.untangle.enabled && !closest_point;
  if (repair) {  // when off, not even its classification runs (a closest-point query per triangle)
    UntangleOptions untangle_options = options.untangle;
    untangle_options.seam_threshold = options.seams.label_threshold;
    const Eigen::MatrixXd before = points_of(hits);
    Eigen::MatrixXd repaired = before;
    untangle = untangle_labels(A, locator, result.target.V, result.target.F, repaired, untangle_options);
    if (untangle.vertices_moved > 0 && !user_target)
      target_seam_labels = target_labels_4d.size() > 0 ? target_labels_4d : seam_labels;
    for (Eigen::Index i = 0; i < repaired.rows() && untangle.vertices_moved > 0; ++i) {
      if (repaired.row(i) == before.row(i)) continue;
      if (relabelled.empty()) relabelled.assign(std::size_t(repaired.rows()), 0);
      relabelled[std::size_t(i)] = 1;
      result.target.labels.row(i) = repaired.row(i);
      hits[std::size_t(i)] = locator.closest(repaired.row(i).transpose());  // its face and weights, for the UVs
      if (!user_target) target_seam_labels.row(result.target.source_edge(i, 0)) = repaired.row(i);
    }
    seconds["repair"] = untangle.seconds;
    progress.stage("repair", untangle.seconds);
  }

  start = Clock::now();
  if (A.has_uv()) result.target_uv = uv_at(A, hits);
  struct SliceOut {
    double t;
    SliceMesh mesh;
    Eigen::MatrixXd uv;
    SeamResult seams;
  };
  std::vector<SliceOut> slices;
  for (double t : slice_times) {
    SliceOut s{t, slice_at(mesh, transport.labels, t), {}, {}};
    trace_labels(s.mesh);
    if (A.has_uv()) s.uv = uv_at(A, locator.closest_all(s.mesh.labels));
    slices.push_back(std::move(s));
  }
  seconds["transfer"] = seconds_since(start);
  progress.stage("transfer", seconds["transfer"]);

  // Seams (§8): target.obj and the slices are written from the split meshes.
  start = Clock::now();
  SeamOptions seam_options = options.seams;
  if (options.seams_mode != "all") {
    seam_options.topological = options.seams_mode == "topological";
    seam_options.texture = options.seams_mode == "texture";
  }
  {
    // A user's mesh has no provenance in the 4D mesh to cut along; its texture seams are still split.
    SeamOptions target_seam_options = seam_options;
    if (user_target) target_seam_options.topological = false;
    const Eigen::MatrixXd& labels_4d = target_seam_labels.size() > 0 ? target_seam_labels
                                       : target_labels_4d.size() > 0 ? target_labels_4d
                                                                     : seam_labels;
    // B's labels have their closest points already (hits, updated where the repair moved a label).
    const Eigen::MatrixXd closest_labels = points_of(hits);
    result.target_seams =
        split_seams(result.target, mesh, labels_4d, A, locator, target_seam_options, relabelled, &closest_labels);
  }
  for (SliceOut& s : slices) s.seams = split_seams(s.mesh, mesh, seam_labels, A, locator, seam_options);
  const Eigen::MatrixXd seam_hits = points_of(locator.closest_all(result.target_seams.labels));
  const Eigen::MatrixXd seam_preimages = frame_a.to_world(seam_hits);
  seconds["seams"] = seconds_since(start);
  progress.stage("seams", seconds["seams"]);

  // Stretch of what target.obj and labels.txt hold (the seam-split B, as `morphmap stretch` measures them), and of
  // B before the seam split, where triangles across a seam interpolate between its sides.
  const StretchResult stretch =
      measure_stretch(A, result.target_seams.V, result.target_seams.F, seam_hits, {}, &locator);
  const StretchResult stretch_unsplit =
      measure_stretch(A, result.target.V, result.target.F, points_of(hits), {}, &locator);
  seconds["metrics"] = stretch.seconds + stretch_unsplit.seconds;

  // Contact sheet (paper Figures 1 and 9) in the morph frame, where A, the slices and B share one camera.
  std::optional<RgbImage> contact_sheet;
  if (options.render && !options.output_dir.empty()) {
    std::vector<Surface> panels;
    panels.push_back(A);
    std::shared_ptr<const RgbImage> texture = A.texture;
    if (!texture && A.has_uv() && A.has_texture())
      texture = std::make_shared<const RgbImage>(read_image(A.texture_path));
    // The seam-split meshes with their per-corner UVs, exactly what target.obj and the slices hold.
    auto panel = [&](const SeamResult& seams, const std::string& name) {
      Surface p;
      p.V = seams.V;
      p.F = seams.F.cast<int>();
      if (seams.UV.rows() > 0 && seams.FUV.rows() == seams.F.rows()) {
        p.UV = seams.UV;
        p.FUV = seams.FUV.cast<int>();
        p.texture = texture;
      }
      p.name = name;
      panels.push_back(std::move(p));
    };
    for (const SliceOut& s : slices) panel(s.seams, "slice " + format_time(s.t));
    panel(result.target_seams, "target");
    const RenderResult sheet = render_contact_sheet(panels, options.render_options);
    contact_sheet = sheet.image;
    seconds["render"] = sheet.seconds;
    report["render"] = {{"file", "contact_sheet.png"},
                        {"panels", panels.size()},
                        {"mode", render_mode_name(sheet.mode)},
                        {"width", sheet.image.width},
                        {"height", sheet.image.height}};
    progress.stage("render", sheet.seconds);
  }

  result.target_labels = frame_a.to_world(points_of(hits));
  result.target.V = frame_b.to_world(result.target.V);
  result.mesh_vertices = mesh.vertex_count();
  result.mesh_tets = mesh.tet_count();
  result.fallbacks = options.method == "trace" ? traced_total.stalled + traced_total.invalid : transport.fallbacks();

  report["inputs"] = {{"source", options.source}, {"target", options.target}};
  for (int which = 0; which < 2; ++which) {
    const std::string side = which == 0 ? "source" : "target";
    if (!input_notes.shape[which].empty()) report["inputs"][side + "_shape"] = input_notes.shape[which];
    report["inputs"][side + "_reoriented"] = input_notes.reoriented[which];
    report["inputs"][side + "_welded_vertices"] = input_notes.welded[which];
  }
  if (user_target) {
    // Where the mesh is the target's, its vertices lie within about a voxel of the extracted B (measured: at most 1.4
    // voxels, median 0.03-0.17, for the bunny, the horse and the Buddha at 16-40 voxels); farther, the closest points
    // that carry the labels are no longer a correspondence (a mesh in other coordinates: median 1272 voxels).
    report["inputs"]["target_mesh_reoriented"] = target_mesh_reoriented;
    std::vector<double> d = target_mesh_distance;
    std::sort(d.begin(), d.end());
    const double h = morph.field.voxel_size;
    const double median = d.empty() ? 0.0 : d[d.size() / 2] / h, largest = d.empty() ? 0.0 : d.back() / h;
    report["inputs"]["target_mesh_distance_voxels"] = {{"median", median}, {"max", largest}};
    if (largest > 3.0) {
      std::ostringstream w;
      w << std::setprecision(3) << options.target_mesh << ": its vertices lie up to " << largest << " voxels (median "
        << median << ") from the extracted target, whose own mesh lies within about one: is it " << options.target
        << ", in its coordinates?";
      input_notes.warnings.push_back(w.str());
    }
  }
  report["inputs"]["warnings"] = input_notes.warnings;
  for (const std::string& w : input_notes.warnings) std::fprintf(stderr, "morphmap: warning: %s\n", w.c_str());
  report["options"] = {{"voxels", options.morph.voxels},
                       {"voxel_size", morph.field.voxel_size},
                       {"padding", options.morph.padding},
                       {"time_steps", options.extract.time_steps},
                       {"time_scale", mesh.time_scale},
                       {"zero_snap", options.extract.zero_snap},
                       {"solver", options.laplace.solver},
                       {"compare_solvers", options.compare_solvers},
                       {"tolerance", options.laplace.solve.tolerance},
                       {"deflation_voxels", options.laplace.deflation_cell_voxels},
                       {"max_iterations", options.laplace.solve.max_iterations},
                       {"change_threshold", options.laplace.solve.change_threshold},
                       {"change_measure", change_measure_name(options.laplace.solve.change_measure)},
                       {"warm_start", options.laplace.warm_start},
                       {"align", options.align},
                       {"method", options.method},
                       {"morph", options.morph_method},
                       {"source_projection", options.source_projection},
                       {"thin_features", options.morph.thin.enabled},
                       {"distances", options.morph.distances},
                       {"trace_order", options.trace.order},
                       {"trace_step", options.trace.step_variation},
                       {"trace_smoothing", options.trace.field_smoothing},
                       {"seams", options.seams_mode},
                       {"seam_threshold", options.seams.label_threshold},
                       {"fold_repair", options.untangle.enabled},
                       {"heal_seams", options.untangle.heal_seams},
                       {"direction_charts", options.untangle.direction_charts},
                       {"compression_seed", options.untangle.compression_seed},
                       {"stalled_fill", options.stalled_fill},
                       {"slices", options.slices},
                       {"threads", options.threads},
                       {"max_memory_bytes", options.max_memory_bytes},
                       {"output_dir", options.output_dir}};
  report["counts"] = {{"vertices", mesh.vertex_count()},
                      {"tets", mesh.tet_count()},
                      {"target_vertices", result.target_seams.V.rows()},
                      {"target_triangles", result.target_seams.F.rows()},
                      {"extracted_target_vertices", extracted_vertices},
                      {"extracted_target_triangles", extracted_triangles},
                      {"source_vertices", A.V.rows()},
                      {"source_triangles", A.F.rows()},
                      {"lattice_points", morph.lattice_points},
                      {"exact_distance_queries", morph.exact_queries},
                      {"band_distance_queries", morph.band_queries},
                      {"lattice_dims", {morph.field.dims.x(), morph.field.dims.y(), morph.field.dims.z()}}};
  report["morph"] = {{"method", morph.method}, {"seconds", morph.seconds}};
  if (morph.method == "distance") {
    report["morph"]["distances"] = options.morph.distances;
    const auto thin = [](const ThinFeatureResult& r) {
      return nlohmann::json{{"sign_disagreements", r.sign_disagreements},
                            {"sign_flips", r.sign_flips},
                            {"grazing_lines", r.grazing_lines},
                            {"edges_tested", r.edges_tested},
                            {"thin_edges", r.thin_edges},
                            {"moved_inside", r.moved_inside},
                            {"moved_outside", r.moved_outside},
                            {"groups", r.groups},
                            {"groups_kept", r.groups_kept},
                            {"sampled_euler", r.sampled_euler},
                            {"sampled_components", r.sampled_components},
                            {"kept_euler", r.kept_euler},
                            {"kept_components", r.kept_components}};
    };
    report["morph"]["thin_features"] = {
        {"enabled", options.morph.thin.enabled}, {"source", thin(morph.thin_a)}, {"target", thin(morph.thin_b)}};
    const auto lattice = [](const LatticeTopology& t) {
      return nlohmann::json{{"euler", t.euler}, {"components", t.components}};
    };
    if (options.morph_topology.mode == "free")
      report["morph"]["topology"] = {{"mode", "free"}, {"applied", false}};
    else
      report["morph"]["topology"] = {{"mode", options.morph_topology.mode},
                                     {"applied", morph_topology.applied},
                                     {"source", lattice(morph_topology.source)},
                                     {"target", lattice(morph_topology.target)},
                                     {"changing_points", morph_topology.changing_points},
                                     {"delayed_points", morph_topology.delayed_points},
                                     {"forced_flips", morph_topology.forced_flips},
                                     {"max_delay", morph_topology.max_delay},
                                     {"levels_changed_free", morph_topology.levels_changed_free},
                                     {"levels_changed_kept", morph_topology.levels_changed_kept},
                                     {"seconds", morph_topology.seconds}};
  }
  if (morph.method == "vim")
    report["morph"].update({{"samples", options.vim.samples},
                            {"separation", options.vim.separation},
                            {"normal_offset", options.vim.normal_offset},
                            {"rbf_centres", morph.rbf_centres},
                            {"fit_residual", morph.fit_residual},
                            {"fit_seconds", morph.fit_seconds}});
  report["extract"] = {{"active_cells", extract.active_cells},
                       {"prisms", extract.prisms},
                       {"snapped_values", extract.snapped_values},
                       {"candidate_cubes", extract.candidate_cubes},
                       {"scratch_bytes", extract.scratch_bytes}};
  report["mesh_quality"] = {
      {"tets", quality.tets},
      {"degenerate_tets", quality.degenerate_tets},
      {"degenerate_handling",
       "lattice values within zero_snap * voxel of zero moved to +-zero_snap * voxel (snapped_values) so no crossing "
       "lands on a lattice point; tets that are still degenerate are kept, contribute nothing to the Laplacian and "
       "are left out of the angle statistics"},
      {"snapped_values", extract.snapped_values},
      {"min_dihedral_degrees", quality.min_dihedral_degrees},
      {"max_dihedral_degrees", quality.max_dihedral_degrees},
      {"obtuse_dihedral_fraction", quality.obtuse_dihedral_fraction},
      {"negative_cotangent_fraction", quality.negative_cotangent_fraction},
      {"min_volume_ratio", quality.min_volume_ratio},
      {"dihedral_histogram_10deg", quality.dihedral_histogram}};
  if (options.critical_points) {
    nlohmann::json listed = nlohmann::json::array();
    for (const int v : critical.listed)
      listed.push_back({{"vertex", v},
                        {"s", laplace.s(v)},
                        {"t", mesh.time_of(v)},
                        {"position", {mesh.V(v, 0), mesh.V(v, 1), mesh.V(v, 2)}}});
    report["critical_points"] = {{"interior_vertices", critical.interior_vertices},
                                 {"minima", critical.minima},
                                 {"maxima", critical.maxima},
                                 {"saddles", critical.saddles},
                                 {"saddle_multiplicity", critical.saddle_multiplicity},
                                 {"listed", listed},
                                 {"listed_rule",
                                  "up to 64 critical vertices by increasing s; positions in the morph "
                                  "frame (the target's coordinates unless --align bbox)"},
                                 {"seconds", critical.seconds}};
  }
  report["stretch"] = nlohmann::json::parse(stretch_json(stretch));
  if (options.method == "trace" && !user_target)
    report["stalled_fill"] = {{"mode", options.stalled_fill},        {"filled", label_fill.filled},
                              {"patches", label_fill.patches},       {"unbounded", label_fill.unbounded},
                              {"coincident", label_fill.coincident}, {"seconds", label_fill.seconds}};
  if (repair)
    report["fold_repair"] = {
        {"enabled", true},
        {"folded_before", untangle.folded_before},
        {"collapsed_before", untangle.collapsed_before},
        {"folded_after", untangle.folded_after},
        {"collapsed_after", untangle.collapsed_after},
        {"seam_triangles", untangle.seam_triangles},
        {"seam_triangles_after", untangle.seam_triangles_after},
        {"seams_healed", untangle.seams_healed},
        {"stretched_before", untangle.stretched_before},
        {"stretched_after", untangle.stretched_after},
        {"patches_tried", untangle.patches_tried},
        {"patches_rebuilt", untangle.patches_rebuilt},
        {"compression_moves", untangle.compression_moves},
        {"compression_sweeps", untangle.compression_sweeps},
        {"compression_parts", untangle.compression_parts},
        {"compression_parts_relieved", untangle.compression_parts_relieved},
        {"layouts_untangled", untangle.layouts_untangled},
        {"patch_vertices", untangle.patch_vertices},
        {"region_vertices", untangle.region_vertices},
        {"vertices_moved", untangle.vertices_moved},
        {"moves", untangle.moves},
        {"rounds", untangle.rounds},
        {"sweeps", untangle.sweeps},
        {"smoothing_sweeps", untangle.smoothing_sweeps},
        {"smoothing_moves", untangle.smoothing_moves},
        {"seconds", untangle.seconds},
        {"note",
         "counts on B before the seam split (seam triangles, whose labels span the seam threshold, not counted); "
         "stretch measures target.obj after it"}};
  report["stretch_unsplit"] = nlohmann::json::parse(stretch_json(stretch_unsplit));
  report["seams"] = seams_json(result.target_seams, seam_options);
  report["solver"] = {{"name", laplace.report.backend},
                      {"iterations", laplace.report.iterations},
                      {"residual", laplace.report.residual},
                      {"change", laplace.report.change},
                      {"memory_bytes", laplace.report.memory_bytes},
                      {"detail", laplace.report.detail},
                      {"deflation_columns", laplace.report.deflation_columns},
                      {"unknowns", laplace.unknowns},
                      {"setup_seconds", laplace.report.setup_seconds},
                      {"solve_seconds", laplace.report.solve_seconds},
                      {"assemble_seconds", laplace.assemble_seconds},
                      {"floating_components", laplace.floating_components},
                      {"floating_vertices", laplace.floating_vertices},
                      {"degenerate_tets", laplace.degenerate_tets}};
  if (!options.compare_solvers.empty()) {
    nlohmann::json solves = nlohmann::json::array();
    for (const SolverComparison& c : comparison.solves)
      solves.push_back({{"name", c.backend},
                        {"iterations", c.iterations},
                        {"residual", c.residual},
                        {"change", c.change},
                        {"setup_seconds", c.setup_seconds},
                        {"solve_seconds", c.solve_seconds},
                        {"memory_bytes", c.memory_bytes},
                        {"max_difference", c.max_difference}});
    report["compare"] = {{"assemble_seconds", comparison.assemble_seconds}, {"solves", solves}};
  }
  report["projection"] = projection_report;
  report["trace"] = {{"method", options.method},
                     {"reached", traced_total.reached},
                     {"descended", traced_total.descended},
                     {"stalled", traced_total.stalled},
                     {"invalid", traced_total.invalid},
                     {"tet_pieces", traced_total.tet_pieces},
                     {"face_pieces", traced_total.face_pieces},
                     {"edge_pieces", traced_total.edge_pieces},
                     {"max_pieces", traced_total.max_pieces},
                     {"rate_evaluations", traced_total.rate_evaluations},
                     {"descent_pieces", traced_total.descent_pieces},
                     {"seconds", traced_total.seconds},
                     {"setup_seconds", tracer_setup_seconds},
                     {"fallback",
                      "a trace whose flow stalls continues down the steepest descent of s (descended); one that "
                      "still cannot reach A (s flat) takes the point of A where it stopped (stalled)"}};
  {
    // The lattice can open or close handles and join or split parts (thin ears, narrow gaps): the extracted B is then
    // not the target's topology, and no map onto it is one-to-one with the target; say so.
    const auto topology_start = Clock::now();
    const SliceMesh extracted_a = source_boundary(mesh, Eigen::MatrixXd());
    const SurfaceCheck extracted_check_a = check_surface(Eigen::MatrixXi(extracted_a.F), extracted_a.V.rows());
    nlohmann::json warnings = nlohmann::json::array();
    auto side = [&](const char* name, const std::string& file, const SurfaceCheck& input,
                    const SurfaceCheck& extracted) {
      if (input.euler() != extracted.euler() || input.components != extracted.components) {
        std::ostringstream w;
        w << "the " << name << " as extracted on the lattice (" << file << ") has Euler characteristic "
          << extracted.euler() << " in " << extracted.components << " component(s), the input " << input.euler()
          << " in " << input.components
          << ": the voxel size joins or splits parts or opens or closes handles; another --voxels may keep them";
        warnings.push_back(w.str());
      }
      return nlohmann::json{{"input_euler", input.euler()},
                            {"input_components", input.components},
                            {"extracted_euler", extracted.euler()},
                            {"extracted_components", extracted.components}};
    };
    report["topology"] = {{"source", side("source", options.source, input_check_a, extracted_check_a)},
                          {"target", side("target", options.target, input_check_b, extracted_check_b)},
                          {"warnings", warnings}};
    for (const auto& w : warnings) std::fprintf(stderr, "morphmap: warning: %s\n", w.get<std::string>().c_str());
    seconds["topology"] = seconds_since(topology_start) + extracted_check_b_seconds;
  }
  {
    // The Laplace stage's components are the census's when it left no tet out (a degenerate one carries no stiffness).
    const bool same_components = laplace.degenerate_tets == 0 && !laplace.component_root.empty();
    const ComponentCensus census = component_census(mesh, same_components ? &laplace.component_root : nullptr);
    report["components"] = {
        {"through", census.through},
        {"born", census.born},
        {"vanishing", census.vanishing},
        {"floating", census.floating},
        {"born_vertices", census.born_vertices},
        {"vanishing_vertices", census.vanishing_vertices},
        {"floating_vertices", census.floating_vertices},
        {"fallback",
         "born components have s = 1 and no upwind source: upwind labels them with the point of A of their "
         "position (fallback_unreached), traces from them stall (s is flat, no descent) and take the point of A "
         "where they stopped (both by the source projection); vanishing components never reach B "
         "(slices through them are labelled from A); floating ones take their mean time as s"}};
  }
  // The upwind sweep's figures; the traced map (the default) runs no sweep.
  if (options.method == "upwind")
    report["transport"] = {{"fallbacks", transport.fallbacks()},
                           {"upwind_exact", transport.upwind_exact},
                           {"fallback_projected", transport.fallback_projected},
                           {"fallback_neighbours", transport.fallback_neighbours},
                           {"fallback_unreached", transport.fallback_unreached},
                           {"cycle_breaks", transport.cycle_breaks},
                           {"wavefronts", transport.wavefronts}};

  // Outputs are staged first and report.json (which says the run is complete) is staged last.
  std::optional<OutputDir> out;
  start = Clock::now();
  if (!options.output_dir.empty()) {
    out.emplace(options.output_dir);
    std::string mtl_name;
    if (A.has_uv() && A.has_texture()) {
      std::string texture_name = "texture.png";
      if (A.texture) {
        write_png(out->staged(texture_name), *A.texture);
      } else {
        texture_name = "texture" + std::filesystem::path(A.texture_path).extension().string();
        std::error_code ec;
        std::filesystem::copy_file(A.texture_path, out->staged(texture_name),
                                   std::filesystem::copy_options::overwrite_existing, ec);
        if (ec) throw IoError(A.texture_path + ": cannot copy texture (" + ec.message() + ")");
      }
      mtl_name = "target.mtl";
      write_mtl(out->staged(mtl_name), texture_name);
    }
    // target.obj is the seam-split B with per-corner UVs; target.ply the same triangles, a vertex split where its
    // corners take different UVs (PLY has per-vertex UVs only; before 2026-12-06 it held the unsplit B, whose
    // triangles across a texture seam interpolated across the texture atlas).
    const Eigen::MatrixXd target_world = frame_b.to_world(result.target_seams.V);
    // Independent files, each formatted on one thread: side by side (staged() is not thread-safe: named first).
    const std::string obj_path = out->staged("target.obj");
    const std::string ply_path = options.write_ply ? out->staged("target.ply") : std::string();
    const std::string labels_path = out->staged("labels.txt");
    tbb::parallel_invoke(
        [&] {
          write_obj(obj_path, target_world, result.target_seams.F, result.target_seams.UV, result.target_seams.FUV,
                    mtl_name);
        },
        [&] {
          if (!options.write_ply) return;
          const SeamResult& t = result.target_seams;
          if (t.FUV.rows() > 0) {
            const PerVertexUvMesh ply = per_vertex_uv(target_world, t.F, t.UV, t.FUV);
            write_ply(ply_path, ply.V, ply.F, ply.UV);
          } else {
            write_ply(ply_path, target_world, t.F, Eigen::MatrixXd());
          }
        },
        [&] { write_labels(labels_path, seam_preimages); });
    nlohmann::json slice_report = nlohmann::json::array();
    for (const SliceOut& s : slices) {
      // Intermediate shapes live between A's and B's frames; interpolate the similarity.
      Frame frame;
      frame.center = (1.0 - s.t) * frame_a.center + s.t * frame_b.center;
      frame.scale = (1.0 - s.t) * frame_a.scale + s.t * frame_b.scale;
      const std::string name = "slice_" + format_time(s.t) + ".obj";
      write_obj(out->staged(name), frame.to_world(s.seams.V), s.seams.F, s.seams.UV, s.seams.FUV, mtl_name);
      slice_report.push_back({{"t", s.t},
                              {"file", name},
                              {"vertices", s.seams.V.rows()},
                              {"triangles", s.seams.F.rows()},
                              {"seams", seams_json(s.seams, seam_options)}});
    }
    report["slices"] = slice_report;
    if (contact_sheet) write_png(out->staged("contact_sheet.png"), *contact_sheet);
  }
  seconds["write"] = seconds_since(start);
  seconds["total"] = seconds_since(start_total);
  report["peak_memory_bytes"] = peak_memory_bytes();
  {
    // CPU time next to wall time: on a shared machine the wall time says little without it.
    struct rusage usage {};
    ::getrusage(RUSAGE_SELF, &usage);
    const auto seconds_of = [](const timeval& t) { return double(t.tv_sec) + 1e-6 * double(t.tv_usec); };
    report["cpu_seconds"] = seconds_of(usage.ru_utime) + seconds_of(usage.ru_stime);
    // The kernel's part apart: on our virtual machines it is nearly all first touches of memory, which cost 20 times
    // more when the host has taken the pages back (docs/performance_log.md, 2026-12-07 from 20:06 UTC), and it is
    // most of what varies from run to run of the same map.
    report["system_cpu_seconds"] = seconds_of(usage.ru_stime);
  }
  report["memory_estimate_bytes"] = memory_estimate;
  // The allocator settings change the run time by a third on our machines (app/allocator.h), so every report says
  // which were in force.
  report["allocator"] = {{"glibc_tunables", allocator_tunables()}, {"openblas_thread_timeout", blas_thread_timeout()}};
  result.report_json = report.dump(2);
  if (out) {
    write_text_atomically(out->staged("report.json"), result.report_json + "\n");
    // An earlier map's outputs in the folder that this run does not write (target.ply without --ply now, slices at
    // other times) would stand beside a report that does not describe them.
    out->commit({"report.json"}, [](const std::string& name) {
      const auto starts = [&](const char* prefix) { return name.rfind(prefix, 0) == 0; };
      const auto ends = [&](const char* suffix) {
        const std::size_t n = std::char_traits<char>::length(suffix);
        return name.size() >= n && name.compare(name.size() - n, n, suffix) == 0;
      };
      return name == "report.json" || name == "labels.txt" || name == "target.obj" || name == "target.mtl" ||
             name == "target.ply" || name == "contact_sheet.png" || (starts("slice_") && ends(".obj")) ||
             (starts("texture.") && name.find('.', 8) == std::string::npos);
    });
    progress.stage("write", seconds["write"]);
  }
  return result;
}

}  // namespace morphmap
