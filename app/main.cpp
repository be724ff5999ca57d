// The `morphmap` command: map, demo, stretch, batch, render.
#include <unistd.h>

#include <CLI/CLI.hpp>
#include <cstdio>
#include <iostream>
#include <sstream>

#include "app/allocator.h"
#include "app/batch.h"
#include "app/cli_options.h"
#include "app/pipeline.h"
#include "mesh/errors.h"
#include "solver/linear_solver.h"

using morphmap::PipelineOptions;

int main(int argc, char** argv) {
  morphmap::tune_startup(argv);
  CLI::App app{"morphmap: dense correspondence and texture transfer through a 4D implicit morph"};
  app.require_subcommand(1);
  PipelineOptions options;
  options.progress = isatty(fileno(stderr)) != 0;

  CLI::App* map = app.add_subcommand("map", "Map SOURCE onto TARGET and transfer its texture");
  map->add_option("SOURCE", options.source,
                  "Mesh file (.obj/.off/.ply/.stl) or built-in shape (sphere, torus, two-spheres)")
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
  batch
      ->add_option("MANIFEST", batch_options.manifest,
                   "JSON manifest: {\"jobs\": [{\"source\", \"target\", map options}]}")
      ->required();
  batch->add_option("-o,--output", batch_options.output_dir, "Output directory: one folder per job, summary.csv/.md")
      ->required();

  CLI::App* render = app.add_subcommand("render", "Render a mesh to PNG: texture, checkerboard or stretch heat map");
  std::string render_mesh, render_png, render_labels, render_source, render_size = "480x480";
  std::vector<double> render_view;
  int render_checker = 0;
  bool render_shaded = false;
  morphmap::RenderOptions& render_options = options.render_options;
  render->add_option("MESH", render_mesh, "Mesh file (.obj with UVs and MTL texture, .off, .ply, .stl)")->required();
  render->add_option("-o,--output", render_png, "PNG file to write")->required();
  render->add_option("--heat", render_labels, "labels.txt of MESH: colour by per-triangle L2 stretch (needs --source)");
  render->add_option("--source", render_source, "The source surface of the labels (file or built-in shape)");
  render->add_option("--checker", render_checker, "Checkerboard with N squares per side instead of the texture")
      ->check(morphmap::whole_number(1, 1024));
  render->add_flag("--shaded", render_shaded, "Grey shading only");
  for (CLI::App* cmd : {render, map, demo}) {
    cmd->add_option("--view", render_view, "Direction from the shape towards the camera, x,y,z")
        ->delimiter(',')
        ->expected(3);
    cmd->add_option("--size", render_size, "Image (per panel) size WxH")->capture_default_str();
  }
  map->add_flag("--render", options.render, "Also write contact_sheet.png (A, the slices, B)");

  try {
    app.parse(argc, argv);
    int used = 0;
    if (std::sscanf(render_size.c_str(), "%dx%d%n", &render_options.width, &render_options.height, &used) != 2 ||
        used != int(render_size.size()))
      throw morphmap::InvalidInput("--size: '" + render_size + "' is not WxH (e.g. 640x480)");
    if (!render_view.empty()) render_options.view = Eigen::Vector3d(render_view[0], render_view[1], render_view[2]);
    if (render_checker > 0) {
      render_options.mode = morphmap::RenderMode::checker;
      render_options.checker_squares = render_checker;
    }
    if (render_shaded) render_options.mode = morphmap::RenderMode::shaded;
    morphmap::validate_render_options(render_options);
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
    options.render = true;
  }

  try {
    if (batch->parsed()) {
      batch_options.progress = isatty(fileno(stderr)) != 0;
      const morphmap::BatchResult result = morphmap::run_batch(batch_options);
      if (result.interrupted) return 130;
      return result.failed > 0 ? 1 : 0;
    }
    if (render->parsed()) {
      const morphmap::RenderResult r = morphmap::render_file(render_mesh, render_labels, render_source, render_options);
      morphmap::write_png_atomically(render_png, r.image);
      return 0;
    }
    if (stretch->parsed()) {
      const morphmap::StretchInputs in = morphmap::read_stretch_inputs(stretch_target, stretch_labels, stretch_source);
      if (in.source_fitted_to_target)
        std::cerr << "morphmap: note: " << stretch_source << " fitted to " << stretch_target << "'s box, as "
                  << in.source_shape << ": no report.json of the map beside it, whose inputs.source_shape places it "
                  << "as the map did\n";
      std::cout << morphmap::stretch_json(morphmap::measure_stretch(in.A, in.B.V, in.B.F, in.preimages)) << '\n';
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
