// Distance-field morph (Payne and Toga 1992; paper §5.1). OpenVDB's meshToVolume computes the
// signed distances; the bands are made wide enough to cover the whole lattice box, because the
// morph's zero set crosses the symmetric difference of the two solids, where a narrow band would
// hold +-background and create false crossings (DESIGN.md, "Distances far from the surface").
#include "mesh/morph.h"

#include <openvdb/openvdb.h>
#include <openvdb/tools/MeshToVolume.h>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <chrono>
#include <cmath>
#include <mutex>

#include "mesh/errors.h"

namespace morphmap {
namespace {

openvdb::FloatGrid::Ptr signed_distance_grid(const Surface& surface, const openvdb::math::Transform& xform,
                                             float band_voxels) {
  std::vector<openvdb::Vec3s> points(surface.V.rows());
  for (Eigen::Index i = 0; i < surface.V.rows(); ++i)
    points[i] = openvdb::Vec3s(float(surface.V(i, 0)), float(surface.V(i, 1)), float(surface.V(i, 2)));
  std::vector<openvdb::Vec3I> triangles(surface.F.rows());
  for (Eigen::Index f = 0; f < surface.F.rows(); ++f)
    triangles[f] = openvdb::Vec3I(surface.F(f, 0), surface.F(f, 1), surface.F(f, 2));
  const std::vector<openvdb::Vec4I> quads;
  return openvdb::tools::meshToSignedDistanceField<openvdb::FloatGrid>(xform, points, triangles, quads, band_voxels,
                                                                        band_voxels);
}

// Copies grid values at lattice points into a dense array (x fastest), one accessor per task.
void sample_lattice(const openvdb::FloatGrid& grid, const MorphField& field, std::vector<float>& out) {
  out.assign(std::size_t(field.dims.prod()), 0.0f);
  tbb::parallel_for(tbb::blocked_range<int>(0, field.dims.z()), [&](const tbb::blocked_range<int>& range) {
    auto accessor = grid.getConstAccessor();
    for (int k = range.begin(); k != range.end(); ++k)
      for (int j = 0; j < field.dims.y(); ++j)
        for (int i = 0; i < field.dims.x(); ++i)
          out[std::size_t(field.index(i, j, k))] = accessor.getValue(openvdb::Coord(i, j, k));
  });
}

}  // namespace

MorphResult build_morph(const Surface& A, const Surface& B, const MorphOptions& options) {
  const auto start = std::chrono::steady_clock::now();
  static std::once_flag vdb_init;
  std::call_once(vdb_init, [] { openvdb::initialize(); });

  if (options.voxel_size <= 0.0 && options.voxels < 4)
    throw InvalidInput("build_morph: voxels must be at least 4 (got " + std::to_string(options.voxels) + ")");
  if (options.padding < 1) throw InvalidInput("build_morph: padding must be at least 1 voxel");
  Eigen::AlignedBox3d box = bounding_box(A.V);
  box.extend(bounding_box(B.V));
  const double extent = box.sizes().maxCoeff();
  if (!(extent > 0.0)) throw InvalidInput("build_morph: the inputs have an empty bounding box");

  MorphResult result;
  MorphField& field = result.field;
  field.voxel_size = options.voxel_size > 0.0 ? options.voxel_size : extent / options.voxels;
  const double h = field.voxel_size;
  field.origin = box.min() - options.padding * h * Eigen::Vector3d::Ones();
  for (int a = 0; a < 3; ++a)
    field.dims(a) = int(std::ceil(box.sizes()(a) / h - 1e-9)) + 1 + 2 * options.padding;

  // Index (0,0,0) of the grid sits at the lattice origin, so lattice points are voxel centres.
  auto xform = openvdb::math::Transform::createLinearTransform(h);
  xform->postTranslate(openvdb::Vec3d(field.origin.x(), field.origin.y(), field.origin.z()));
  // Distances needed reach across the whole box: its diagonal bounds every lattice point's distance.
  const float band = float(std::ceil(field.dims.cast<double>().norm())) + 2.0f;

  auto gridA = signed_distance_grid(A, *xform, band);
  auto gridB = signed_distance_grid(B, *xform, band);
  sample_lattice(*gridA, field, field.dA);
  sample_lattice(*gridB, field, field.dB);
  result.lattice_points = field.dims.prod();
  result.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return result;
}

}  // namespace morphmap
