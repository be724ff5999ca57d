// Inputs shared by the benchmarks: the Table II morphs' surfaces built as the pipeline builds them. Models folder:
// $MORPHMAP_MODELS, default ../shared/data/models.
#pragma once

#include <cstdlib>
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include "io/mesh_io.h"
#include "mesh/shapes.h"
#include "mesh/surface.h"

namespace bench {

inline std::string models_dir() {
  const char* env = std::getenv("MORPHMAP_MODELS");
  return env ? env : "../shared/data/models";
}

/// Each surface scaled into its own bounding box centred at the origin, half its largest side = 1 (the
/// pipeline's --align bbox, app/pipeline.cpp normalise()).
inline void normalise(morphmap::Surface& surface) {
  const Eigen::AlignedBox3d box = morphmap::bounding_box(surface.V);
  const Eigen::Vector3d center = box.center();
  surface.V = (surface.V.rowwise() - center.transpose()) / (0.5 * box.sizes().maxCoeff());
}

/// A and B of `morph` (sphere-torus: built-in shapes; sphere-bunny: the sphere fitted to bunny_closed.obj's box;
/// cow-horse: cow.off and horse.obj, each normalised). Returns an error message when a model file is missing.
inline std::string case_surfaces(const std::string& morph, morphmap::Surface& A, morphmap::Surface& B) {
  if (morph == "sphere-torus") {
    B = morphmap::make_shape(morphmap::parse_shape_spec("torus"), std::nullopt);
    A = morphmap::make_shape(morphmap::parse_shape_spec("sphere"), morphmap::bounding_box(B.V));
    return "";
  }
  const std::string dir = models_dir();
  const std::string a_path = dir + "/cow.off";
  const std::string b_path = dir + (morph == "sphere-bunny" ? "/bunny_closed.obj" : "/horse.obj");
  for (const std::string& path :
       morph == "sphere-bunny" ? std::vector<std::string>{b_path} : std::vector<std::string>{a_path, b_path})
    if (!std::filesystem::exists(path)) return path + " not found: set MORPHMAP_MODELS to the models folder";
  B = morphmap::read_surface(b_path);
  if (morph == "sphere-bunny") {
    A = morphmap::make_shape(morphmap::parse_shape_spec("sphere"), morphmap::bounding_box(B.V));
  } else {
    A = morphmap::read_surface(a_path);
    normalise(A);
    normalise(B);
  }
  return "";
}

}  // namespace bench
