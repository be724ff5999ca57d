// The `morphmap` command: map, demo.
#include <unistd.h>

#include <CLI/CLI.hpp>
#include <cstdio>
#include <iostream>
#include <sstream>

#include "app/pipeline.h"
#include "mesh/errors.h"
#include "solver/linear_solver.h"

namespace {

using morphmap::PipelineOptions;

// Options shared by `map` and `demo`.
void add_pipeline_options(CLI::App& cmd, PipelineOptions& o) {
  cmd.add_option("--voxels", o.morph.voxels, "Lattice voxels across the larger side of the union bounding box")
      ->check(CLI::Range(4, 4096))
      ->capture_default_str();
  cmd.add_option("--voxel-size", o.morph.voxel_size, "Explicit voxel size (overrides --voxels)")
      ->check(CLI::NonNegativeNumber);
  cmd.add_option("--time-steps", o.extract.time_steps, "Lattice intervals along the morph time t")
      ->check(CLI::Range(1, 4096))
      ->capture_default_str();
  cmd.add_option("--time-scale", o.extract.time_scale,
                 "Length of one unit of morph time in R^4 (c); 0 = time-steps x voxel size (cubic cells)")
      ->check(CLI::NonNegativeNumber)
      ->capture_default_str();
  const auto names = morphmap::solver_names();
  cmd.add_option("--solver", o.laplace.solver, "Laplace solver backend")
      ->check(CLI::IsMember(names))
      ->capture_default_str();
  cmd.add_option("--tolerance", o.laplace.solve.tolerance, "Relative residual at which iterative solvers stop")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  cmd.add_option("--max-iterations", o.laplace.solve.max_iterations, "Iteration limit of iterative solvers")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  cmd.add_option("--slices", o.slices, "Morph times in (0,1) at which to write slice_<t>.obj")->delimiter(',');
  cmd.add_option("--align", o.align,
                 "none: meshes in their own coordinates; bbox: both normalised, outputs in the target's")
      ->check(CLI::IsMember({"none", "bbox"}))
      ->capture_default_str();
  cmd.add_flag("--ply", o.write_ply, "Also write target.ply");
  cmd.add_option("--threads", o.threads, "Worker threads (0 = all cores)")->check(CLI::NonNegativeNumber);
  cmd.add_option_function<std::string>(
         "--max-memory", [&o](const std::string& text) { o.max_memory_bytes = morphmap::parse_memory_size(text); },
         "Refuse a run whose estimated peak memory exceeds SIZE (e.g. 8G, 512M)")
      ->type_name("SIZE");
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"morphmap: dense correspondence and texture transfer through a 4D implicit morph"};
  app.require_subcommand(1);
  PipelineOptions options;
  options.progress = isatty(fileno(stderr)) != 0;

  CLI::App* map = app.add_subcommand("map", "Map SOURCE onto TARGET and transfer its texture");
  map->add_option("SOURCE", options.source, "Mesh file (.obj/.off/.ply) or built-in shape (sphere, torus, two-spheres)")
      ->required();
  map->add_option("TARGET", options.target, "Mesh file or built-in shape")->required();
  map->add_option("-o,--output", options.output_dir, "Output directory")->required();
  add_pipeline_options(*map, options);

  CLI::App* demo = app.add_subcommand("demo", "Map the built-in textured sphere onto the built-in torus");
  std::string demo_dir = "morphmap-demo";
  demo->add_option("-o,--output", demo_dir, "Output directory")->capture_default_str();
  add_pipeline_options(*demo, options);

  CLI::App* stretch = app.add_subcommand("stretch", "Print the texture stretch (JSON) of a map written by `map`");
  std::string stretch_target, stretch_labels, stretch_source;
  stretch->add_option("TARGET", stretch_target, "The mapped surface (target.obj)")->required();
  stretch->add_option("--labels", stretch_labels, "labels.txt: one preimage per vertex of TARGET")->required();
  stretch->add_option("--source", stretch_source, "The source surface (file or built-in shape)")->required();

  try {
    app.parse(argc, argv);
  } catch (const CLI::CallForHelp& e) {
    return app.exit(e);
  } catch (const CLI::CallForAllHelp& e) {
    return app.exit(e);
  } catch (const CLI::ParseError& e) {
    std::cerr << "morphmap: " << e.what() << '\n';
    return 2;
  } catch (const morphmap::Error& e) {  // option values parsed by morphmap itself (--max-memory)
    std::cerr << "morphmap: " << e.what() << '\n';
    return 2;
  }

  if (demo->parsed()) {
    options.source = "sphere";
    options.target = "torus";
    options.output_dir = demo_dir;
    if (options.slices.empty()) options.slices = {0.25, 0.5, 0.75};
  }

  try {
    if (stretch->parsed()) {
      std::cout << morphmap::stretch_json(morphmap::stretch_of_files(stretch_target, stretch_labels, stretch_source))
                << '\n';
      return 0;
    }
    const morphmap::PipelineResult result = morphmap::run_pipeline(options);
    if (options.progress)
      std::fprintf(stderr, "[morphmap] wrote %s (%lld target vertices, %lld tets, %lld fallbacks)\n",
                   options.output_dir.c_str(), (long long)result.target.V.rows(), (long long)result.mesh_tets,
                   (long long)result.fallbacks);
    return 0;
  } catch (const morphmap::SolverError& e) {  // not the user's input: a numerical failure
    std::cerr << "morphmap: " << e.what() << '\n';
    return 1;
  } catch (const morphmap::Error& e) {  // bad input, unreadable file, unusable mesh, resource guard
    std::cerr << "morphmap: " << e.what() << '\n';
    return 2;
  } catch (const std::exception& e) {
    std::cerr << "morphmap: " << e.what() << '\n';
    return 1;
  }
}
