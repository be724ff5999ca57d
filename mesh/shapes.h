// Built-in analytic input shapes (sphere, torus, two spheres), triangulated, for the demo and tests.
#pragma once

#include <Eigen/Geometry>
#include <optional>
#include <string>

#include "mesh/surface.h"

namespace morphmap {

/// Parsed form of "sphere", "torus:R=1,r=0.3", "two-spheres:radius=0.4,separation=1.2", ...
/// Keys: center=x/y/z (slash-separated), size (radius of the bounding sphere of the shape), res
/// (subdivisions along a great circle), torus r_ratio (minor / major radius), two-spheres
/// gap_ratio (gap between spheres / sphere radius). Unknown shapes or keys throw InvalidInput.
struct ShapeSpec {
  std::string kind;                       ///< "sphere", "torus" or "two-spheres"
  std::optional<Eigen::Vector3d> center;  ///< default: centre of the box to fit, else origin
  std::optional<double> size;             ///< half of the largest extent; default: fits the box, else 1
  int resolution = 96;                    ///< segments around a full circle
  double r_ratio = 0.4;                   ///< torus: minor radius / major radius
  double gap_ratio = 0.5;                 ///< two-spheres: gap between the spheres / sphere radius
  bool texture = true;                    ///< sphere: lat-long UVs and a generated checkerboard texture
};

/// True when `arg` names a built-in shape (its text before ':' is a known kind).
bool is_builtin_shape(const std::string& arg);

/// Parses a spec string; throws InvalidInput naming the spec and the problem.
ShapeSpec parse_shape_spec(const std::string& arg);

/// The spec with the centre and size make_shape(spec, fit) places the shape at, both explicit.
ShapeSpec resolve_shape_spec(const ShapeSpec& spec, const std::optional<Eigen::AlignedBox3d>& fit);

/// The spec as text that parse_shape_spec reads back to the same spec (numbers in shortest round-trip form), e.g.
/// "sphere:size=1.5,center=0/0/0". Of a resolved spec it names the shape without reference to another's box.
std::string shape_spec_string(const ShapeSpec& spec);

/// Builds the shape. Without an explicit centre/size it is placed to fit `fit` when given
/// (centred in it, its largest half-extent equal to the box's largest half-extent), else at the
/// origin with size 1. Spheres carry per-corner lat-long UVs (seam at longitude 0) and a checkerboard.
Surface make_shape(const ShapeSpec& spec, const std::optional<Eigen::AlignedBox3d>& fit);

}  // namespace morphmap
