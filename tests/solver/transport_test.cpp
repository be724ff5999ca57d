// Tests of the upwind label sweep (paper §7.1) on product meshes built without extraction.
#include "solver/transport.h"

#include <gtest/gtest.h>
#include <tbb/global_control.h>

#include <algorithm>
#include <cmath>

#include "mesh/errors.h"
#include "tests/mesh/product_mesh.h"

namespace morphmap {
namespace {

using test_mesh::gradient_field;
using test_mesh::icosphere;
using test_mesh::octahedron;
using test_mesh::product_mesh;

using test_mesh::time_field;

Eigen::Vector3d own_position(const Eigen::Vector3d& x) { return x; }

TEST(TransportTest, IdentityMorphMapsEveryVertexToItself) {
  const TetMesh4 mesh = product_mesh(icosphere(1), 4, 1.3);
  Eigen::MatrixXd field = Eigen::MatrixXd::Zero(mesh.vertex_count(), 4);
  field.col(3).setOnes();
  const TransportResult r = transport_labels(mesh, time_field(mesh), field, own_position);
  ASSERT_EQ(r.labels.rows(), mesh.vertex_count());
  EXPECT_LE((r.labels - mesh.V.leftCols(3)).cwiseAbs().maxCoeff(), 1e-12);
  EXPECT_EQ(r.fallbacks(), 0);
  EXPECT_EQ(r.upwind_exact, mesh.vertex_count() - icosphere(1).V.rows());
}

TEST(TransportTest, ConstantAttributeIsTransportedUnchanged) {
  // A constant on A must arrive unchanged everywhere, whatever the flow: every label is a convex
  // combination (or a mean) of labels already computed.
  const TetMesh4 mesh = product_mesh(icosphere(2), 5, 1.0, 1.0, 1.8);
  const Eigen::VectorXd s = time_field(mesh);
  const Eigen::RowVector2d constant(0.25, -3.5);
  const Eigen::MatrixXd source = constant.replicate(mesh.vertex_count(), 1);
  const TransportResult r = transport_values(mesh, s, gradient_field(mesh, s), source,
                                             [&](const Eigen::Vector3d&) -> Eigen::RowVectorXd { return constant; });
  ASSERT_EQ(r.labels.rows(), mesh.vertex_count());
  ASSERT_EQ(r.labels.cols(), 2);
  EXPECT_LE((r.labels.rowwise() - constant).cwiseAbs().maxCoeff(), 1e-12);
  EXPECT_GT(r.upwind_exact, 0);
}

TEST(TransportTest, EveryVertexGetsAFiniteLabel) {
  const TetMesh4 mesh = product_mesh(icosphere(2), 4, 0.7, 1.0, 0.6);
  const Eigen::VectorXd s = time_field(mesh);
  const TransportResult r = transport_labels(mesh, s, gradient_field(mesh, s), own_position);
  ASSERT_EQ(r.labels.rows(), mesh.vertex_count());
  EXPECT_TRUE(r.labels.allFinite());
  EXPECT_EQ(r.upwind_exact + r.fallbacks() + std::int64_t(icosphere(2).V.rows()), mesh.vertex_count());
}

// Worst angle between the label of a B vertex and the radial preimage of that vertex on A.
double worst_radial_error(const test_mesh::TriSurface& sphere, const TetMesh4& mesh, const Eigen::MatrixXd& labels) {
  double worst = 0.0;
  for (Eigen::Index v = 0; v < mesh.vertex_count(); ++v) {
    if (mesh.side[std::size_t(v)] != VertexSide::B) continue;
    const Eigen::Vector3d expected = sphere.V.row(v % sphere.V.rows());
    const Eigen::Vector3d label = labels.row(v);
    worst = std::max(worst, std::acos(std::clamp(label.normalized().dot(expected), -1.0, 1.0)));
  }
  return worst;
}

TEST(TransportTest, ConcentricSpheresMapRadially) {
  // r grows from 1 to 2 and s = t; the flow is the gradient of s averaged at vertices, so trajectories
  // follow vertex normals of the faceted sphere: radial up to O(h).
  double previous_error = 0.0;
  for (const int subdivisions : {2, 3}) {
    const test_mesh::TriSurface sphere = icosphere(subdivisions);
    const TetMesh4 mesh = product_mesh(sphere, 6, 1.0, 1.0, 2.0);
    const Eigen::VectorXd s = time_field(mesh);
    const Eigen::MatrixXd field = gradient_field(mesh, s);
    const TransportResult r = transport_labels(mesh, s, field, own_position);
    for (Eigen::Index v = 0; v < mesh.vertex_count(); ++v) {
      ASSERT_TRUE(r.labels.row(v).allFinite());
      // Labels are convex combinations of A's vertices, hence inside A's unit ball.
      EXPECT_LE(r.labels.row(v).norm(), 1.0 + 1e-12);
    }
    const double error = worst_radial_error(sphere, mesh, r.labels);
    EXPECT_LT(error, 0.025);  // the edge length of the coarser sphere is about 0.3 rad
    if (subdivisions == 3) {
      EXPECT_LT(error, 0.7 * previous_error);
    }
    previous_error = error;
    // On the common tangent space of each star every ray finds its upwind tet.
    EXPECT_EQ(r.fallbacks(), 0);
    EXPECT_EQ(r.upwind_exact, mesh.vertex_count() - sphere.V.rows());

    // Projecting into each tet's own hull leaves gaps in a bent star: most vertices fall back, still accurately.
    TransportOptions per_tet;
    per_tet.star_tangent_space = false;
    const TransportResult h = transport_labels(mesh, s, field, own_position, per_tet);
    EXPECT_GT(h.fallback_projected, 0);
    EXPECT_LT(worst_radial_error(sphere, mesh, h.labels), 0.025);
  }
}

TEST(TransportTest, LabelsMoveWithTranslatedInput) {
  // Weights sum to one, so translating the whole morph translates every label.
  TetMesh4 mesh = product_mesh(icosphere(1), 4, 1.0, 1.0, 1.6);
  const Eigen::VectorXd s = time_field(mesh);
  const Eigen::MatrixXd field = gradient_field(mesh, s);
  const TransportResult base = transport_labels(mesh, s, field, own_position);
  const Eigen::RowVector3d offset(3.0, -2.0, 0.5);
  mesh.V.leftCols(3).rowwise() += offset;
  const TransportResult moved = transport_labels(mesh, s, field, own_position);
  EXPECT_LE(((moved.labels.rowwise() - offset) - base.labels).cwiseAbs().maxCoeff(), 1e-12);
  EXPECT_EQ(moved.upwind_exact, base.upwind_exact);
}

TEST(TransportTest, SweepIsCausalForPerturbedField) {
  const TetMesh4 mesh = product_mesh(icosphere(1), 5, 1.0, 1.0, 1.5);
  Eigen::VectorXd s = time_field(mesh);
  // Perturb interior values so the processing order differs from the layer order.
  for (Eigen::Index v = 0; v < s.size(); ++v)
    if (mesh.side[std::size_t(v)] == VertexSide::Interior) s(v) += 0.08 * std::sin(7.0 * double(v));
  TransportOptions options;
  options.record_upwind = true;
  const TransportResult r = transport_labels(mesh, s, gradient_field(mesh, s), own_position, options);
  ASSERT_EQ(r.upwind.rows(), mesh.vertex_count());
  std::int64_t checked = 0;
  for (Eigen::Index v = 0; v < mesh.vertex_count(); ++v) {
    for (int k = 0; k < 3; ++k) {
      const int u = r.upwind(v, k);
      if (u < 0) continue;
      ++checked;
      // Causal: every label read was final before (an earlier wavefront).
      EXPECT_LT(r.wave(u), r.wave(v)) << "vertex " << v << " used " << u;
    }
    if (mesh.side[std::size_t(v)] == VertexSide::A) {
      EXPECT_EQ(r.upwind(v, 0), -1);
    }
  }
  EXPECT_GT(checked, mesh.vertex_count());
  EXPECT_GT(r.upwind_exact, 0);
  EXPECT_GT(r.wavefronts, 5);
}

TEST(TransportTest, BornComponentTakesUnreachedLabelAndKeepsItConstant) {
  const TetMesh4 main_mesh = product_mesh(icosphere(1), 4, 1.0);
  // A small octahedron that exists only for t in [0.5, 1]: no vertex of it touches A.
  const TetMesh4 mesh =
      test_mesh::with_component(main_mesh, product_mesh(octahedron(), 2, 0.5, 0.3, 0.3), 0.5, VertexSide::B);
  const Eigen::Index nm = main_mesh.vertex_count();

  const Eigen::Vector3d constant(7.0, 7.0, 7.0);
  int calls = 0;
  auto unreached = [&](const Eigen::Vector3d&) {
    ++calls;
    return constant;
  };
  const Eigen::VectorXd s = time_field(mesh);
  const Eigen::MatrixXd field = gradient_field(mesh, s);
  const TransportResult r = transport_labels(mesh, s, field, unreached);
  EXPECT_GE(r.fallback_unreached, 1);
  EXPECT_EQ(r.fallback_unreached, calls);
  for (Eigen::Index v = nm; v < mesh.vertex_count(); ++v)
    EXPECT_LE((r.labels.row(v).transpose() - constant).cwiseAbs().maxCoeff(), 1e-12) << "vertex " << v;

  // The main component must not notice the other one.
  const Eigen::VectorXd s_main = time_field(main_mesh);
  const TransportResult alone = transport_labels(main_mesh, s_main, gradient_field(main_mesh, s_main), own_position);
  EXPECT_LE((r.labels.topRows(nm) - alone.labels).cwiseAbs().maxCoeff(), 0.0);
}

TEST(TransportTest, ResultDoesNotDependOnThreadCount) {
  const TetMesh4 mesh = product_mesh(icosphere(1), 4, 1.0, 1.0, 1.4);
  const Eigen::VectorXd s = time_field(mesh);
  const Eigen::MatrixXd field = gradient_field(mesh, s);
  Eigen::MatrixXd one_thread;
  {
    tbb::global_control limit(tbb::global_control::max_allowed_parallelism, 1);
    one_thread = transport_labels(mesh, s, field, own_position).labels;
  }
  const Eigen::MatrixXd many = transport_labels(mesh, s, field, own_position).labels;
  EXPECT_EQ((one_thread - many).cwiseAbs().maxCoeff(), 0.0);
}

TEST(TransportTest, RejectsMismatchedInputs) {
  const TetMesh4 mesh = product_mesh(octahedron(), 2, 1.0);
  const Eigen::VectorXd s = time_field(mesh);
  const Eigen::MatrixXd field = Eigen::MatrixXd::Zero(mesh.vertex_count(), 4);
  EXPECT_THROW(transport_labels(mesh, s.head(3), field, own_position), InvalidInput);
  EXPECT_THROW(transport_labels(mesh, s, field.leftCols(3), own_position), InvalidInput);
  Eigen::VectorXd bad = s;
  bad(4) = std::nan("");
  EXPECT_THROW(transport_labels(mesh, bad, field, own_position), InvalidInput);
}

}  // namespace
}  // namespace morphmap
