// The `morphmap` command: map, demo, stretch, batch.
#include <unistd.h>

#include <CLI/CLI.hpp>
#include <cstdio>
#include <iostream>
#include <sstream>

#include "app/batch.h"
#include "app/cli_options.h"
#include "app/pipeline.h"
#include "mesh/errors.h"
#include "solver/linear_solver.h"

using morphmap::PipelineOptions;

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
  morphmap::add_pipeline_options(*map, options);
  map->add_flag("--progress", options.progress, "Print stage times to stderr also when it is not a terminal");

  CLI::App* demo = app.add_subcommand("demo", "Map the built-in textured sphere onto the built-in torus");
  std::string demo_dir = "morphmap-demo";
  demo->add_option("-o,--output", demo_dir, "Output directory")->capture_default_str();
  morphmap::add_pipeline_options(*demo, options);

  CLI::App* stretch = app.add_subcommand("stretch", "Print the texture stretch (JSON) of a map written by `map`");
  std::string stretch_target, stretch_labels, stretch_source;
  stretch->add_option("TARGET", stretch_target, "The mapped surface (target.obj)")->required();
  stretch->add_option("--labels", stretch_labels, "labels.txt: one preimage per vertex of TARGET")->required();
  stretch->add_option("--source", stretch_source, "The source surface (file or built-in shape)")->required();

  CLI::App* batch = app.add_subcommand("batch", "Run the map jobs of a JSON manifest one after another (see README)");
  morphmap::BatchOptions batch_options;
  batch->add_option("MANIFEST", batch_options.manifest, "JSON manifest: {\"jobs\": [{\"source\", \"target\", map options}]}")
      ->required();
  batch->add_option("-o,--output", batch_options.output_dir, "Output directory: one folder per job, summary.csv/.md")
      ->required();

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
    if (batch->parsed()) {
      batch_options.progress = isatty(fileno(stderr)) != 0;
      const morphmap::BatchResult result = morphmap::run_batch(batch_options);
      if (result.interrupted) return 130;
      return result.failed > 0 ? 1 : 0;
    }
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
