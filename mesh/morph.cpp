// Distance-field morph (Payne and Toga 1992; paper §5.1). A mesh's distances within a narrow band of its surface
// are exact (closest-point queries), its signs the winding number's along the lattice lines, right everywhere;
// OpenVDB's meshToVolume (flood-filled signs, band values a few percent off) on request. The morph's zero set crosses
// the symmetric difference of the two solids, far from either surface, where the narrow band holds
// +-background and would create false crossings (DESIGN.md, "Distances far from the surface"); so
// every lattice point of a cube where d can change sign gets its exact distance from a closest-point
// query. A wide meshToVolume band does the same but costs seconds at 37^3 (measured: 5.3 s). Built-in shapes
// (Surface::signed_distance) are sampled from their exact distance function at every lattice point instead.
#include "mesh/morph.h"

#include <openvdb/openvdb.h>
#include <openvdb/tools/MeshToVolume.h>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_invoke.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <memory>
#include <mutex>
#include <sstream>
#include <utility>

#include "mesh/errors.h"
#include "mesh/thin_features.h"
#include "mesh/transfer.h"

namespace morphmap {
namespace {

// The grid is built in index space (voxel size 1, lattice point (i, j, k) at index (i, j, k)), its values scaled back
// by h when sampled: OpenVDB refuses a transform whose voxel size cubed is below 3e-15 ("Non-zero scale values
// required", so a mesh in units where the voxel is under 1.4e-5 could not be mapped), and single-precision world
// coordinates far from the origin lose what a voxel resolves (a bunny 0.15 across moved to x = 1e5 has a float step
// of half a voxel at 20 voxels). Points relative to the lattice origin, in voxels, keep float's precision for both.
openvdb::FloatGrid::Ptr signed_distance_grid(const Surface& surface, const MorphField& field, float band_voxels) {
  const double h = field.voxel_size;
  std::vector<openvdb::Vec3s> points(surface.V.rows());
  for (Eigen::Index i = 0; i < surface.V.rows(); ++i) {
    const Eigen::Vector3d p = (surface.V.row(i).transpose() - field.origin) / h;
    points[i] = openvdb::Vec3s(float(p.x()), float(p.y()), float(p.z()));
  }
  std::vector<openvdb::Vec3I> triangles(surface.F.rows());
  for (Eigen::Index f = 0; f < surface.F.rows(); ++f)
    triangles[f] = openvdb::Vec3I(surface.F(f, 0), surface.F(f, 1), surface.F(f, 2));
  const std::vector<openvdb::Vec4I> quads;
  static std::once_flag vdb_init;
  std::call_once(vdb_init, [] { openvdb::initialize(); });
  const auto xform = openvdb::math::Transform::createLinearTransform(1.0);
  return openvdb::tools::meshToSignedDistanceField<openvdb::FloatGrid>(*xform, points, triangles, quads, band_voxels,
                                                                       band_voxels);
}

// Copies grid values at lattice points into a dense array (x fastest), one accessor per task; the grid is in voxel
// units (signed_distance_grid), the array in the surfaces' own.
void sample_lattice(const openvdb::FloatGrid& grid, const MorphField& field, std::vector<float>& out) {
  out.assign(std::size_t(field.point_count()), 0.0f);
  const float h = float(field.voxel_size);
  tbb::parallel_for(tbb::blocked_range<int>(0, field.dims.z()), [&](const tbb::blocked_range<int>& range) {
    auto accessor = grid.getConstAccessor();
    for (int k = range.begin(); k != range.end(); ++k)
      for (int j = 0; j < field.dims.y(); ++j)
        for (int i = 0; i < field.dims.x(); ++i)
          out[std::size_t(field.index(i, j, k))] = h * accessor.getValue(openvdb::Coord(i, j, k));
  });
}

// The positions of lattice points given by index (MorphField::index), #list by 3: the queries of a list of points.
Eigen::MatrixXd lattice_points(const MorphField& field, const std::vector<std::int64_t>& list) {
  const std::int64_t nx = field.dims.x(), ny = field.dims.y();
  Eigen::MatrixXd points(Eigen::Index(list.size()), 3);
  for (std::size_t r = 0; r < list.size(); ++r) {
    const std::int64_t q = list[r];
    points.row(Eigen::Index(r)) = field.point(int(q % nx), int((q / nx) % ny), int(q / (nx * ny))).transpose();
  }
  return points;
}

// Signed distances of a mesh at every lattice point: exact within `band` voxels of the surface (Embree's closest-point
// queries), +-band voxels beyond, negative where the winding votes of the lattice lines say inside (a tie: the side
// of the closest face). Written by hand around the locator because OpenVDB's meshToVolume works per triangle, each
// flooding the voxels around it: the horse's 97 k triangles took 0.20-0.30 s where the 26 k points of its 3-voxel
// band took 0.04 s of queries.
std::int64_t mesh_distances(const Surface& surface, const SurfaceLocator& locator, const WindingVotes& winding,
                            const MorphField& field, float band, std::vector<float>& out) {
  const Eigen::Vector3i& n = field.dims;
  const double h = field.voxel_size;
  const std::int64_t sy = n.x(), sz = std::int64_t(n.x()) * n.y();
  // Cells (by their lowest corner's index) holding a sample of a triangle, samples on a barycentric grid no more than
  // a quarter voxel apart, so every point of the surface lies within `slack` voxels of a marked cell.
  constexpr double kSlack = 0.25;
  std::vector<std::uint8_t> cell(std::size_t(field.point_count()), 0);
  for (Eigen::Index f = 0; f < surface.F.rows(); ++f) {
    Eigen::Vector3d c[3];
    for (int m = 0; m < 3; ++m) c[m] = (surface.V.row(surface.F(f, m)).transpose() - field.origin) / h;
    const double longest = std::max({(c[1] - c[0]).norm(), (c[2] - c[1]).norm(), (c[0] - c[2]).norm()});
    const int parts = std::max(1, int(std::ceil(longest / kSlack)));
    for (int a = 0; a <= parts; ++a)
      for (int b = 0; a + b <= parts; ++b) {
        const Eigen::Vector3d p = c[0] + (double(a) / parts) * (c[1] - c[0]) + (double(b) / parts) * (c[2] - c[0]);
        std::int64_t q = 0, stride = 1;
        for (int axis = 0; axis < 3; ++axis) {
          q += stride * std::clamp(std::int64_t(std::floor(p(axis))), std::int64_t(0), std::int64_t(n(axis) - 2));
          stride *= n(axis);
        }
        cell[std::size_t(q)] = 1;
      }
  }
  // A point within band of the surface is within band + slack of a marked cell's box [0, 1]^3: the stencil of such
  // offsets, applied plane by plane of the output so that no two tasks write one byte.
  const double reach = double(band) + kSlack;
  const int wide = int(std::floor(reach));
  struct Offset {
    int dx, dy;
  };
  std::vector<std::vector<Offset>> stencil(std::size_t(2 * wide + 2));  // by dz + wide
  for (int dz = -wide; dz <= wide + 1; ++dz)
    for (int dy = -wide; dy <= wide + 1; ++dy)
      for (int dx = -wide; dx <= wide + 1; ++dx) {
        const auto gap = [](int o) { return o < 0 ? double(-o) : o > 1 ? double(o - 1) : 0.0; };
        if (gap(dx) * gap(dx) + gap(dy) * gap(dy) + gap(dz) * gap(dz) <= reach * reach)
          stencil[std::size_t(dz + wide)].push_back({dx, dy});
      }
  std::vector<std::vector<std::int64_t>> cells_at(std::size_t(n.z()));
  for (std::size_t q = 0; q < cell.size(); ++q)
    if (cell[q]) cells_at[std::size_t(std::int64_t(q) / sz)].push_back(std::int64_t(q));
  std::vector<std::uint8_t> near(cell.size(), 0);
  tbb::parallel_for(tbb::blocked_range<int>(0, n.z()), [&](const tbb::blocked_range<int>& range) {
    for (int k = range.begin(); k != range.end(); ++k)
      for (int dz = -wide; dz <= wide + 1; ++dz) {
        const int ck = k - dz;
        if (ck < 0 || ck >= n.z()) continue;
        for (const std::int64_t c : cells_at[std::size_t(ck)]) {
          const int ci = int(c % sy), cj = int((c / sy) % n.y());
          for (const Offset& o : stencil[std::size_t(dz + wide)]) {
            const int i = ci + o.dx, j = cj + o.dy;
            if (i >= 0 && j >= 0 && i < n.x() && j < n.y()) near[std::size_t(field.index(i, j, k))] = 1;
          }
        }
      }
  });
  cell = std::vector<std::uint8_t>();
  // Queries: every near point, bounded by the band (beyond it the value is the band's width whatever the distance),
  // and every point the votes leave tied, unbounded (its side comes from the closest face).
  const float clamp = band * float(h);
  std::vector<std::int64_t> bounded, tied;
  for (std::size_t q = 0; q < near.size(); ++q) {
    if (2 * winding.inside[q] == winding.votes[q])
      tied.push_back(std::int64_t(q));
    else if (near[q])
      bounded.push_back(std::int64_t(q));
  }
  const std::vector<SurfaceHit> near_hits = locator.closest_all(lattice_points(field, bounded), double(clamp));
  const Eigen::MatrixXd tied_points = lattice_points(field, tied);
  const std::vector<SurfaceHit> tied_hits = locator.closest_all(tied_points);
  out.assign(near.size(), clamp);
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, near.size()), [&](const tbb::blocked_range<std::size_t>& r) {
    for (std::size_t q = r.begin(); q != r.end(); ++q)
      if (2 * winding.inside[q] > winding.votes[q]) out[q] = -clamp;
  });
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, bounded.size()), [&](const tbb::blocked_range<std::size_t>& r) {
    for (std::size_t m = r.begin(); m != r.end(); ++m) {
      float& v = out[std::size_t(bounded[m])];
      v = std::copysign(std::min(float(near_hits[m].distance), clamp), v);
    }
  });
  for (std::size_t m = 0; m < tied.size(); ++m) {
    const SurfaceHit& hit = tied_hits[m];
    const Eigen::Vector3d a = surface.V.row(surface.F(hit.face, 0)), b = surface.V.row(surface.F(hit.face, 1)),
                          c = surface.V.row(surface.F(hit.face, 2));
    const bool inside = (tied_points.row(Eigen::Index(m)).transpose() - hit.point).dot((b - a).cross(c - a)) < 0.0;
    const float d = std::min(float(hit.distance), clamp);
    out[std::size_t(tied[m])] = inside ? -d : d;
  }
  return std::int64_t(bounded.size() + tied.size());
}

// Marks the corners of every lattice cube where d(x, t) can change sign for some t: signs of dA and
// dB are right everywhere, and d keeps its sign over a cube whose corners all have dA and dB of one
// sign. Cubes are flagged first and points gathered from their (up to 8) cubes, so no two tasks write
// the same byte.
std::vector<std::uint8_t> crossing_corners(const MorphField& field) {
  const Eigen::Vector3i& n = field.dims;
  const std::int64_t cx = n.x() - 1, cy = n.y() - 1, cz = n.z() - 1;
  const std::int64_t sy = n.x(), sz = std::int64_t(n.x()) * n.y();
  std::vector<std::uint8_t> cube(std::size_t(cx * cy * cz), 0);
  tbb::parallel_for(tbb::blocked_range<std::int64_t>(0, cz), [&](const tbb::blocked_range<std::int64_t>& range) {
    for (std::int64_t k = range.begin(); k != range.end(); ++k)
      for (std::int64_t j = 0; j < cy; ++j)
        for (std::int64_t i = 0; i < cx; ++i) {
          const std::int64_t base = i + sy * j + sz * k;
          bool nonneg = false, neg = false;
          for (int b = 0; b < 8; ++b) {
            const std::size_t q = std::size_t(base + ((b & 1) ? 1 : 0) + ((b & 2) ? sy : 0) + ((b & 4) ? sz : 0));
            nonneg |= field.dA[q] >= 0.0f || field.dB[q] >= 0.0f;
            neg |= field.dA[q] < 0.0f || field.dB[q] < 0.0f;
          }
          cube[std::size_t(i + cx * (j + cy * k))] = nonneg && neg;
        }
  });
  std::vector<std::uint8_t> mark(field.dA.size(), 0);
  tbb::parallel_for(tbb::blocked_range<std::int64_t>(0, n.z()), [&](const tbb::blocked_range<std::int64_t>& range) {
    for (std::int64_t k = range.begin(); k != range.end(); ++k)
      for (std::int64_t j = 0; j < n.y(); ++j)
        for (std::int64_t i = 0; i < n.x(); ++i) {
          std::uint8_t m = 0;
          for (int b = 0; b < 8 && !m; ++b) {
            const std::int64_t ci = i - (b & 1), cj = j - ((b >> 1) & 1), ck = k - ((b >> 2) & 1);
            if (ci < 0 || cj < 0 || ck < 0 || ci >= cx || cj >= cy || ck >= cz) continue;
            m = cube[std::size_t(ci + cx * (cj + cy * ck))];
          }
          mark[std::size_t(i + sy * j + sz * k)] = m;
        }
  });
  return mark;
}

// A signed distance function at every lattice point (analytic shapes, test fields).
void sample_distance(const SignedDistance& distance, const MorphField& field, std::vector<float>& out) {
  out.assign(std::size_t(field.point_count()), 0.0f);
  tbb::parallel_for(tbb::blocked_range<int>(0, field.dims.z()), [&](const tbb::blocked_range<int>& range) {
    for (int k = range.begin(); k != range.end(); ++k)
      for (int j = 0; j < field.dims.y(); ++j)
        for (int i = 0; i < field.dims.x(); ++i)
          out[std::size_t(field.index(i, j, k))] = float(distance(field.point(i, j, k)));
  });
}

// Replaces band-clamped values at marked lattice points with exact signed distances (surfaces sampled analytically
// are exact everywhere already). OpenVDB's band values ("openvdb" distances) are left as they are: replacing them
// too was measured in 2026-12 (cow -> horse's L2 p99 20.6 -> 33.7) when that was the only method; the "exact"
// method (whose signs differ too) maps some models better and more of them worse (docs/performance_log.md,
// 2026-12-07 from 21:12 UTC), at half the morph stage's time.
// `filled` holds the points already filled (empty: none), and is set to the points marked now.
std::int64_t fill_exact_distances(const Surface& A, const Surface& B, const SurfaceLocator* locators[2], float clamp,
                                  MorphField& field, std::vector<std::uint8_t>& filled) {
  std::vector<std::uint8_t> mark = crossing_corners(field);
  std::int64_t queries = 0;
  for (int which = 0; which < 2; ++which) {
    if ((which == 0 ? A : B).signed_distance) continue;
    std::vector<float>& values = which == 0 ? field.dA : field.dB;
    std::vector<std::int64_t> todo;
    for (std::size_t q = 0; q < values.size(); ++q)
      if (mark[q] && (filled.empty() || !filled[q]) && std::abs(values[q]) >= 0.999f * clamp)
        todo.push_back(std::int64_t(q));
    if (todo.empty()) continue;
    const std::vector<SurfaceHit> hits = locators[which]->closest_all(lattice_points(field, todo));
    for (std::size_t r = 0; r < todo.size(); ++r) {
      float& v = values[std::size_t(todo[r])];
      v = std::copysign(float(hits[r].distance), v);
    }
    queries += std::int64_t(todo.size());
  }
  filled = std::move(mark);
  return queries;
}

}  // namespace

MorphField sample_morph(const SignedDistance& dA, const SignedDistance& dB, double extent, int n) {
  if (n < 2 || !(extent > 0.0)) throw InvalidInput("sample_morph: need n >= 2 points and a positive extent");
  MorphField field;
  field.voxel_size = 2.0 * extent / (n - 1);
  field.dims = Eigen::Vector3i(n, n, n);
  field.origin = Eigen::Vector3d::Constant(-extent);
  sample_distance(dA, field, field.dA);
  sample_distance(dB, field, field.dB);
  return field;
}

MorphField morph_lattice(const Surface& A, const Surface& B, const MorphOptions& options) {
  if (options.voxel_size <= 0.0 && options.voxels < 4)
    throw InvalidInput("morph_lattice: voxels must be at least 4 (got " + std::to_string(options.voxels) + ")");
  if (options.padding < 1) throw InvalidInput("morph_lattice: padding must be at least 1 voxel");
  Eigen::AlignedBox3d box = bounding_box(A.V);
  box.extend(bounding_box(B.V));
  const double extent = box.sizes().maxCoeff();
  if (!(extent > 0.0)) throw InvalidInput("morph_lattice: the inputs have an empty bounding box");
  MorphField field;
  field.voxel_size = options.voxel_size > 0.0 ? options.voxel_size : extent / options.voxels;
  // An explicit voxel size is held to what --voxels allows: a lattice of 31 k voxels a side overflowed the point
  // count (a crash, whatever --max-memory said), and one under 4 voxels extracts nothing of the shapes.
  const double across = extent / field.voxel_size;
  if (!(across >= 4.0 - 1e-9 && across <= 4096.0 + 1e-9)) {
    std::ostringstream message;
    message << "morph_lattice: voxel size " << field.voxel_size << " puts " << across
            << " voxels across the shapes' box (" << extent << "); it must put 4 to 4096";
    throw InvalidInput(message.str());
  }
  field.extent = extent;
  const double h = field.voxel_size;
  field.origin = box.min() - options.padding * h * Eigen::Vector3d::Ones();
  for (int a = 0; a < 3; ++a) field.dims(a) = int(std::ceil(box.sizes()(a) / h - 1e-9)) + 1 + 2 * options.padding;
  return field;
}

MorphResult build_morph(const Surface& A, const Surface& B, const MorphOptions& options, const SurfaceCheck* checks) {
  if (options.distances != "exact" && options.distances != "openvdb")
    throw InvalidInput("build_morph: unknown distances '" + options.distances + "' (choose exact, openvdb)");
  const auto start = std::chrono::steady_clock::now();

  MorphResult result;
  result.field = morph_lattice(A, B, options);
  MorphField& field = result.field;
  const double h = field.voxel_size;

  const float band = float(options.band_voxels());
  std::unique_ptr<SurfaceLocator> owned[2];
  const SurfaceLocator* locators[2] = {nullptr, nullptr};
  for (int which = 0; which < 2; ++which)
    if (!(which == 0 ? A : B).signed_distance) {
      owned[which] = std::make_unique<SurfaceLocator>(which == 0 ? A : B);
      locators[which] = owned[which].get();
    }
  WindingVotes winding[2];
  // Built-in shapes carry their exact distance: the voxelisation and the closest-point queries are needed only for
  // meshes (and the analytic field is the shape itself, not its triangulation).
  for (int which = 0; which < 2; ++which) {
    const Surface* surface = which == 0 ? &A : &B;
    std::vector<float>& values = which == 0 ? field.dA : field.dB;
    if (surface->signed_distance) {
      sample_distance(surface->signed_distance, field, values);
    } else if (options.distances == "openvdb") {
      auto grid = signed_distance_grid(*surface, field, band);
      sample_lattice(*grid, field, values);
    } else {
      winding[which] = winding_votes(*locators[which], field);
      result.band_queries += mesh_distances(*surface, *locators[which], winding[which], field, band, values);
    }
  }
  result.lattice_points = field.point_count();
  std::vector<std::uint8_t> filled;
  result.exact_queries = fill_exact_distances(A, B, locators, band * float(h), field, filled);
  // After the exact distances: thin parts lie within a voxel of the surface, inside the band either way.
  // A and B side by side: much of the work (the topology counts) is sequential, and the two are independent.
  const auto keep = [&](int which) {
    if (locators[which] == nullptr) return;
    const Surface& surface = which == 0 ? A : B;
    const SurfaceCheck check = checks != nullptr ? checks[which] : check_surface(surface.F, surface.V.rows());
    const LatticeTopology target{check.euler(), check.components};
    (which == 0 ? result.thin_a : result.thin_b) =
        keep_thin_features(*locators[which], field, which == 0 ? field.dA : field.dB, target, options.thin,
                           winding[which].votes.empty() ? nullptr : &winding[which]);
  };
  tbb::parallel_invoke([&] { keep(0); }, [&] { keep(1); });
  // A point the thin parts moved to the other side makes cubes crossed that were not, and their corners up to
  // 2 sqrt(3) voxels from the surface may still hold the band's width: exact distances there too (so that the values
  // the extraction reads do not depend on the band's width beyond sqrt(3) voxels).
  const auto moved = [](const ThinFeatureResult& r) { return r.sign_flips + r.moved_inside + r.moved_outside; };
  if (moved(result.thin_a) + moved(result.thin_b) > 0)
    result.exact_queries += fill_exact_distances(A, B, locators, band * float(h), field, filled);
  result.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return result;
}

}  // namespace morphmap
