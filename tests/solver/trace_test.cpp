// Tests of characteristic tracing (paper §7) on product meshes built without extraction.
#include "solver/trace.h"

#include <gtest/gtest.h>
#include <tbb/global_control.h>

#include <algorithm>
#include <cmath>

#include "mesh/errors.h"
#include "solver/transport.h"
#include "tests/mesh/product_mesh.h"

namespace morphmap {
namespace {

using test_mesh::gradient_field;
using test_mesh::icosphere;
using test_mesh::octahedron;
using test_mesh::product_mesh;

using test_mesh::time_field;

// One start per side-B vertex, in vertex order.
std::vector<MeshPoint> b_vertices(const TetMesh4& mesh, std::vector<int>& ids) {
  std::vector<MeshPoint> starts;
  for (Eigen::Index v = 0; v < mesh.vertex_count(); ++v) {
    if (mesh.side[std::size_t(v)] != VertexSide::B) continue;
    MeshPoint p;
    p.ids[0] = int(v);
    p.weights[0] = 1.0;
    starts.push_back(p);
    ids.push_back(int(v));
  }
  return starts;
}

TEST(TraceTest, IdentityMorphTracesEveryPointStraightBack) {
  const test_mesh::TriSurface sphere = icosphere(2);
  const TetMesh4 mesh = product_mesh(sphere, 4, 1.3);
  Eigen::MatrixXd field = Eigen::MatrixXd::Zero(mesh.vertex_count(), 4);
  field.col(3).setOnes();
  std::vector<int> ids;
  std::vector<MeshPoint> starts = b_vertices(mesh, ids);
  // Also points inside B's edges and faces: the top layer's vertices are 4 * #S + i.
  const Eigen::Index top = 4 * sphere.V.rows();
  for (Eigen::Index f = 0; f < sphere.F.rows(); ++f) {
    MeshPoint p;
    for (int k = 0; k < 3; ++k) p.ids[std::size_t(k)] = int(top + sphere.F(f, k));
    p.weights = {{0.2, 0.3, 0.5, 0.0}};
    starts.push_back(p);
    p.weights = {{0.5, 0.5, 0.0, 0.0}};
    starts.push_back(p);
  }
  const TraceResult r = trace_to_source(mesh, time_field(mesh), field, starts);
  ASSERT_EQ(r.end.rows(), Eigen::Index(starts.size()));
  EXPECT_EQ(r.reached, std::int64_t(starts.size()));
  for (std::size_t i = 0; i < starts.size(); ++i) {
    Eigen::Vector3d expected = Eigen::Vector3d::Zero();
    for (int k = 0; k < 4; ++k)
      if (starts[i].ids[std::size_t(k)] >= 0)
        expected += starts[i].weights[std::size_t(k)] * mesh.V.row(starts[i].ids[std::size_t(k)]).head<3>().transpose();
    EXPECT_LE((r.end.row(Eigen::Index(i)).transpose() - expected).norm(), 1e-12) << "start " << i;
    for (int k = 0; k < 4; ++k) {
      const int id = r.end_point[i].ids[std::size_t(k)];
      if (id < 0) continue;
      EXPECT_EQ(mesh.side[std::size_t(id)], VertexSide::A);
    }
  }
}

// Worst angle between the traced (or upwind) preimage of each B vertex and its radial preimage.
double worst_radial(const test_mesh::TriSurface& sphere, const std::vector<int>& ids, const Eigen::MatrixXd& labels) {
  double worst = 0.0;
  for (std::size_t i = 0; i < ids.size(); ++i) {
    const Eigen::Vector3d expected = sphere.V.row(ids[i] % sphere.V.rows());
    const Eigen::Vector3d label = labels.row(Eigen::Index(i));
    worst = std::max(worst, std::acos(std::clamp(label.normalized().dot(expected), -1.0, 1.0)));
  }
  return worst;
}

TEST(TraceTest, ConcentricSpheresTraceRadiallyLikeTheUpwindSweep) {
  // r grows from 1 to 2 with s = t: characteristics are radial up to the faceting of the sphere (icosphere(3):
  // edges of about 0.15 rad). Measured worst angles: traced 0.0115, upwind 0.0086 (the prisms are aligned with
  // the radial map, which favours the upwind interpolation).
  const test_mesh::TriSurface sphere = icosphere(3);
  const TetMesh4 mesh = product_mesh(sphere, 6, 1.0, 1.0, 2.0);
  const Eigen::VectorXd s = time_field(mesh);
  const Eigen::MatrixXd field = gradient_field(mesh, s);
  const TransportResult upwind = transport_labels(mesh, s, field, [](const Eigen::Vector3d& x) { return x; });
  std::vector<int> ids;
  const std::vector<MeshPoint> starts = b_vertices(mesh, ids);
  Eigen::MatrixXd upwind_b(Eigen::Index(ids.size()), 3);
  for (std::size_t i = 0; i < ids.size(); ++i) upwind_b.row(Eigen::Index(i)) = upwind.labels.row(ids[i]);
  const double swept = worst_radial(sphere, ids, upwind_b);
  EXPECT_LT(swept, 0.02);
  Eigen::MatrixXd ends[2];
  for (const int order : {2, 4}) {
    TraceOptions options;
    options.order = order;
    const TraceResult r = trace_to_source(mesh, s, field, starts, options);
    EXPECT_EQ(r.reached, std::int64_t(ids.size())) << "order " << order;
    EXPECT_GT(r.tet_pieces, std::int64_t(ids.size()));
    // Every piece costs at least choose()'s rate of the simplex it picks (which starts the step) and the step's
    // further evaluations: one for Heun's, three for the classical step, plus the rate at its end.
    EXPECT_GE(r.rate_evaluations, (order == 2 ? 2 : 5) * (r.tet_pieces + r.face_pieces + r.edge_pieces));
    const double traced = worst_radial(sphere, ids, r.end);
    EXPECT_LT(traced, 0.02) << "order " << order;
    EXPECT_LT(traced, 2.0 * swept) << "order " << order << ": traced " << traced << ", upwind " << swept;
    ends[order / 4] = r.end;
  }
  // The two integrators solve the same ODE: far closer to each other than to the radial map (the faceting).
  EXPECT_LT((ends[0] - ends[1]).rowwise().norm().maxCoeff(), 1e-3);
  TraceOptions bad;
  bad.order = 3;
  EXPECT_THROW(trace_to_source(mesh, s, field, starts, bad), InvalidInput);
}

TEST(TraceTest, ResultDoesNotDependOnThreadCount) {
  const TetMesh4 mesh = product_mesh(icosphere(2), 5, 1.0, 1.0, 1.6);
  const Eigen::VectorXd s = time_field(mesh);
  const Eigen::MatrixXd field = gradient_field(mesh, s);
  std::vector<int> ids;
  const std::vector<MeshPoint> starts = b_vertices(mesh, ids);
  TraceResult one;
  {
    tbb::global_control limit(tbb::global_control::max_allowed_parallelism, 1);
    one = trace_to_source(mesh, time_field(mesh), field, starts);
  }
  const TraceResult many = trace_to_source(mesh, time_field(mesh), field, starts);
  EXPECT_EQ((one.end - many.end).cwiseAbs().maxCoeff(), 0.0);
  EXPECT_EQ(one.tet_pieces, many.tet_pieces);
  EXPECT_EQ(one.face_pieces, many.face_pieces);
  EXPECT_EQ(one.rate_evaluations, many.rate_evaluations);
}

TEST(TraceTest, StallsWhereTheFieldVanishesAndRejectsBadStarts) {
  const TetMesh4 mesh = product_mesh(octahedron(), 2, 1.0);
  const Eigen::MatrixXd zero = Eigen::MatrixXd::Zero(mesh.vertex_count(), 4);
  std::vector<int> ids;
  std::vector<MeshPoint> starts = b_vertices(mesh, ids);
  MeshPoint apart;  // opposite poles of the octahedron share no tet
  apart.ids = {{ids[0], ids[1], -1, -1}};
  apart.weights = {{0.5, 0.5, 0.0, 0.0}};
  starts.push_back(apart);
  MeshPoint outside;
  outside.ids[0] = int(mesh.vertex_count());
  outside.weights[0] = 1.0;
  starts.push_back(outside);
  TraceOptions no_descent;
  no_descent.descend = false;
  const TraceResult r = trace_to_source(mesh, time_field(mesh), zero, starts, no_descent);
  EXPECT_EQ(r.stalled, std::int64_t(ids.size()));
  EXPECT_EQ(r.invalid, 2);
  EXPECT_EQ(r.status[ids.size()], TraceStatus::Invalid);
  for (std::size_t i = 0; i < ids.size(); ++i) {
    EXPECT_EQ(r.status[i], TraceStatus::Stalled);
    EXPECT_EQ(r.end_point[i].ids[0], ids[i]);  // stalled where it started
  }
  EXPECT_THROW(trace_to_source(mesh, time_field(mesh), Eigen::MatrixXd::Zero(3, 4), starts), InvalidInput);
}

TEST(TraceTest, TracesCirclingAStagnantFieldStallAfterOneProgressWindow) {
  // T turns around the z axis within each time layer: s = t never falls along it.
  const TetMesh4 mesh = product_mesh(icosphere(2), 3, 1.0);
  Eigen::MatrixXd field = Eigen::MatrixXd::Zero(mesh.vertex_count(), 4);
  field.col(0) = -mesh.V.col(1);
  field.col(1) = mesh.V.col(0);
  std::vector<int> ids;
  const std::vector<MeshPoint> starts = b_vertices(mesh, ids);
  TraceOptions options;
  options.progress_window = 64;
  options.descend = false;
  const TraceResult r = trace_to_source(mesh, time_field(mesh), field, starts, options);
  EXPECT_EQ(r.reached, 0);
  EXPECT_EQ(r.stalled, std::int64_t(starts.size()));
  EXPECT_LE(r.max_pieces, options.progress_window + 1);

  // With the descent (the default) each stalled trace goes on down s = t, which on the product mesh runs straight
  // down in time: it reaches A under the point where the flow stalled, which the circling kept on the sphere.
  options.descend = true;
  const TraceResult d = trace_to_source(mesh, time_field(mesh), field, starts, options);
  EXPECT_EQ(d.descended, std::int64_t(starts.size()));
  EXPECT_EQ(d.stalled, 0);
  EXPECT_GT(d.descent_pieces, 0);
  for (std::size_t i = 0; i < starts.size(); ++i) {
    ASSERT_EQ(d.status[i], TraceStatus::Descended);
    EXPECT_NEAR(d.end.row(Eigen::Index(i)).norm(), 1.0, 0.05) << i;  // on the unit icosphere's facets
    Eigen::Vector3d stop = Eigen::Vector3d::Zero();
    for (int k = 0; k < 4; ++k)
      if (r.end_point[i].ids[std::size_t(k)] >= 0)
        stop += r.end_point[i].weights[std::size_t(k)] *
                mesh.V.row(r.end_point[i].ids[std::size_t(k)]).head<3>().transpose();
    EXPECT_LT((d.end.row(Eigen::Index(i)).transpose() - stop).norm(), 1e-9) << i;
  }
}

TEST(TraceTest, DescentReachesAWhereTheFieldVanishesButNotWhereSIsFlat) {
  const TetMesh4 mesh = product_mesh(octahedron(), 2, 1.0);
  const Eigen::MatrixXd zero = Eigen::MatrixXd::Zero(mesh.vertex_count(), 4);
  std::vector<int> ids;
  const std::vector<MeshPoint> starts = b_vertices(mesh, ids);
  // No flow at all: the descent of s = t takes every B vertex straight down to its own copy on A.
  const TraceResult r = trace_to_source(mesh, time_field(mesh), zero, starts);
  EXPECT_EQ(r.descended, std::int64_t(ids.size()));
  for (std::size_t i = 0; i < ids.size(); ++i)
    EXPECT_LT((r.end.row(Eigen::Index(i)) - mesh.V.row(ids[i]).head<3>()).norm(), 1e-12) << i;
  // s flat (a born component has s = 1 throughout): nothing descends, every trace stalls where it started.
  const TraceResult flat = trace_to_source(mesh, Eigen::VectorXd::Ones(mesh.vertex_count()), zero, starts);
  EXPECT_EQ(flat.stalled, std::int64_t(ids.size()));
  EXPECT_EQ(flat.descended, 0);
  for (std::size_t i = 0; i < ids.size(); ++i) EXPECT_EQ(flat.end_point[i].ids[0], ids[i]);
}

TEST(TraceTest, EdgePointsSplitSliceVerticesOverTheirEdges) {
  Eigen::MatrixXi edges(2, 2);
  edges << 3, 3, 4, 7;
  const Eigen::VectorXd w = Eigen::Vector2d(0.0, 0.25);
  const std::vector<MeshPoint> p = edge_points(edges, w);
  ASSERT_EQ(p.size(), 2u);
  EXPECT_EQ(p[0].ids[0], 3);
  EXPECT_EQ(p[0].ids[1], -1);
  EXPECT_DOUBLE_EQ(p[0].weights[0], 1.0);
  EXPECT_EQ(p[1].ids[0], 4);
  EXPECT_EQ(p[1].ids[1], 7);
  EXPECT_DOUBLE_EQ(p[1].weights[1], 0.25);
  EXPECT_THROW(edge_points(edges, Eigen::VectorXd::Zero(3)), InvalidInput);
}

}  // namespace
}  // namespace morphmap
