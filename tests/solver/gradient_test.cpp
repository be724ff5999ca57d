// Tests of the per-tet gradient and the vertex tangent field T (paper §6.2).
#include "solver/gradient.h"

#include <gtest/gtest.h>
#include <tbb/global_control.h>

#include <Eigen/Dense>
#include <cstring>
#include <vector>

#include "mesh/errors.h"
#include "tests/solver/test_meshes.h"

namespace morphmap {
namespace {

TetMesh4 curved_slab(int n, int nz, unsigned seed) {
  TetMesh4 mesh = test::make_slab_mesh(n, nz);
  test::perturb_interior(mesh, 0.3 / n, seed);
  test::transform_embedding(mesh, test::random_rotation(seed + 1), Eigen::Vector4d(-1.0, 0.5, 2.0, 0.25));
  return mesh;
}

Eigen::Matrix<double, 4, 3> edge_matrix(const TetMesh4& mesh, Eigen::Index t) {
  Eigen::Matrix<double, 4, 3> E;
  for (int k = 0; k < 3; ++k) E.col(k) = (mesh.V.row(mesh.T(t, k + 1)) - mesh.V.row(mesh.T(t, 0))).transpose();
  return E;
}

TEST(Gradient, AffineFunctionIsExactOnEveryTet) {
  const TetMesh4 mesh = curved_slab(4, 4, 21);
  const Eigen::Vector4d a(0.7, -1.3, 2.1, 0.4);
  const double b = -0.8;
  const Eigen::VectorXd s = (mesh.V * a).array() + b;
  const GradientResult result = compute_gradient(mesh, s);
  ASSERT_EQ(result.tet_gradient.rows(), mesh.T.rows());
  ASSERT_EQ(result.tet_gradient.cols(), 4);
  for (Eigen::Index t = 0; t < mesh.T.rows(); ++t) {
    // Projection of a onto the tet's hull through an orthonormal basis (not the Gram matrix).
    const Eigen::Matrix<double, 4, 3> Q =
        Eigen::HouseholderQR<Eigen::Matrix<double, 4, 3>>(edge_matrix(mesh, t)).householderQ() *
        Eigen::Matrix<double, 4, 3>::Identity();
    const Eigen::Vector4d expected = Q * (Q.transpose() * a);
    EXPECT_LT((result.tet_gradient.row(t).transpose() - expected).norm(), 1e-10) << "tet " << t;
  }
}

TEST(Gradient, TetVolumesAreCrossProductNorms) {
  const TetMesh4 mesh = curved_slab(3, 2, 8);
  const GradientResult result = compute_gradient(mesh, Eigen::VectorXd::Zero(mesh.V.rows()));
  for (Eigen::Index t = 0; t < mesh.T.rows(); ++t) {
    const Eigen::Matrix<double, 4, 3> E = edge_matrix(mesh, t);
    EXPECT_NEAR(result.tet_volume(t), cross4(E.col(0), E.col(1), E.col(2)).norm() / 6.0, 1e-14);
  }
  // The unperturbed slab is cut exactly: 6 tets of volume h^2 * (H / nz) / 6 per cube.
  const TetMesh4 flat = test::make_slab_mesh(3, 2, 2.0);
  EXPECT_NEAR(compute_gradient(flat, Eigen::VectorXd::Zero(flat.V.rows())).tet_volume.sum(), 2.0, 1e-13);
}

TEST(Gradient, VertexFieldOfTimeIsTheTimeDirection) {
  TetMesh4 mesh = test::make_slab_mesh(3, 4, 2.0);
  const Eigen::VectorXd s = mesh.V.col(3) / mesh.time_scale;
  const Eigen::Matrix4d R = test::random_rotation(17);
  test::transform_embedding(mesh, R);
  const GradientResult result = compute_gradient(mesh, s);
  const Eigen::RowVector4d direction = R.col(3).transpose();  // the rotated tau axis
  for (Eigen::Index i = 0; i < mesh.V.rows(); ++i) {
    EXPECT_LT((result.vertex_field.row(i) - direction).norm(), 1e-12) << "vertex " << i;
  }
  for (Eigen::Index t = 0; t < mesh.T.rows(); ++t) {
    EXPECT_LT((result.tet_gradient.row(t) - 0.5 * direction).norm(), 1e-12);
  }
}

TEST(Gradient, VertexFieldIsVolumeWeightedMean) {
  const TetMesh4 mesh = curved_slab(3, 3, 31);
  Eigen::VectorXd s(mesh.V.rows());
  for (Eigen::Index i = 0; i < s.size(); ++i) s(i) = std::sin(mesh.V(i, 0)) + mesh.V(i, 1) * mesh.V(i, 3);
  const GradientResult result = compute_gradient(mesh, s);
  Eigen::MatrixXd sum = Eigen::MatrixXd::Zero(mesh.V.rows(), 4);
  for (Eigen::Index t = 0; t < mesh.T.rows(); ++t) {
    for (int k = 0; k < 4; ++k) sum.row(mesh.T(t, k)) += result.tet_volume(t) * result.tet_gradient.row(t);
  }
  for (Eigen::Index i = 0; i < mesh.V.rows(); ++i) {
    EXPECT_LT((result.vertex_field.row(i) - sum.row(i).normalized()).norm(), 1e-12);
    EXPECT_NEAR(result.vertex_field.row(i).norm(), 1.0, 1e-14);
  }
}

TEST(Gradient, ConstantFieldAndDegenerateTetGiveZero) {
  TetMesh4 mesh = test::make_slab_mesh(2, 2);
  // An extra vertex held only by a flat tet: no hull, so no gradient and no direction.
  mesh.V.conservativeResize(mesh.V.rows() + 1, 4);
  mesh.V.bottomRows(1) << 0.5, 0.5, 0.0, 0.0;
  mesh.side.push_back(VertexSide::A);
  mesh.T.conservativeResize(mesh.T.rows() + 1, 4);
  mesh.T.bottomRows(1) << 0, 1, 3, static_cast<int>(mesh.V.rows() - 1);
  mesh.source_cell.push_back(0);
  const GradientResult constant = compute_gradient(mesh, Eigen::VectorXd::Constant(mesh.V.rows(), 0.25));
  EXPECT_EQ(constant.vertex_field.cwiseAbs().maxCoeff(), 0.0);
  EXPECT_EQ(constant.tet_gradient.cwiseAbs().maxCoeff(), 0.0);

  const Eigen::VectorXd s = mesh.V.col(3) + mesh.V.col(0);
  const GradientResult result = compute_gradient(mesh, s);
  EXPECT_TRUE(result.tet_gradient.allFinite());
  EXPECT_TRUE(result.vertex_field.allFinite());
  EXPECT_EQ(result.tet_volume(mesh.T.rows() - 1), 0.0);
  EXPECT_EQ(result.tet_gradient.bottomRows(1).cwiseAbs().maxCoeff(), 0.0);
  EXPECT_EQ(result.vertex_field.bottomRows(1).cwiseAbs().maxCoeff(), 0.0);
  EXPECT_NEAR(result.vertex_field.row(0).norm(), 1.0, 1e-14);
}

TEST(Gradient, IndependentOfThreadCount) {
  const TetMesh4 mesh = curved_slab(12, 12, 2);
  Eigen::VectorXd s(mesh.V.rows());
  for (Eigen::Index i = 0; i < s.size(); ++i) s(i) = std::cos(3.0 * mesh.V(i, 0)) * mesh.V(i, 2);
  std::vector<GradientResult> results;
  for (int threads : {1, 2}) {
    tbb::global_control limit(tbb::global_control::max_allowed_parallelism, static_cast<std::size_t>(threads));
    results.push_back(compute_gradient(mesh, s));
  }
  EXPECT_EQ(results[0].vertex_field, results[1].vertex_field);
  EXPECT_EQ(results[0].tet_gradient, results[1].tet_gradient);
}

TEST(Gradient, RejectsBadInput) {
  const TetMesh4 mesh = test::make_slab_mesh(2, 2);
  EXPECT_THROW(compute_gradient(mesh, Eigen::VectorXd::Zero(mesh.V.rows() - 1)), InvalidInput);
  TetMesh4 broken = mesh;
  broken.T(0, 0) = static_cast<int>(mesh.V.rows());
  EXPECT_THROW(compute_gradient(broken, Eigen::VectorXd::Zero(mesh.V.rows())), InvalidInput);
}

}  // namespace
}  // namespace morphmap
