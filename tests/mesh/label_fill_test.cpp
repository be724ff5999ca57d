// Labels of stalled vertices from the traced ones around them, on identity maps of a sphere.
#include "mesh/label_fill.h"

#include <gtest/gtest.h>

#include <vector>

#include "mesh/errors.h"
#include "mesh/metrics.h"
#include "mesh/shapes.h"

namespace morphmap {
namespace {

Surface unit_sphere() { return make_shape(parse_shape_spec("sphere:size=1,center=0/0/0,res=24"), std::nullopt); }

// The vertices within `radius` of the sphere's vertex nearest (1, 0, 0).
std::vector<char> cap(const Surface& A, double radius) {
  Eigen::Index centre = 0;
  for (Eigen::Index i = 0; i < A.V.rows(); ++i)
    if (A.V(i, 0) > A.V(centre, 0)) centre = i;
  std::vector<char> in(std::size_t(A.V.rows()), 0);
  for (Eigen::Index i = 0; i < A.V.rows(); ++i) in[std::size_t(i)] = (A.V.row(i) - A.V.row(centre)).norm() < radius;
  return in;
}

TEST(LabelFillTest, StalledCapCollapsedToOnePointIsSpreadBackOverItsPatch) {
  // Every vertex of a cap took one label (the traces of a sink): its triangles collapse. Filled from the identity
  // labels around it, the cap is a Tutte embedding of B's own shape, which on the sphere is close to the identity.
  const Surface A = unit_sphere();
  const SurfaceLocator locator(A);
  const std::vector<char> stalled = cap(A, 0.7);
  Eigen::MatrixXd labels = A.V;
  Eigen::Index inside = 0;
  for (Eigen::Index i = 0; i < A.V.rows(); ++i)
    if (stalled[std::size_t(i)]) labels.row(i) = Eigen::RowVector3d(1.0, 0.0, 0.0), ++inside;
  ASSERT_GT(inside, 10);
  const StretchResult before = measure_stretch(A, A.V, A.F, labels);
  EXPECT_GT(before.collapsed, 10);

  const LabelFillResult r = fill_stalled_labels(A.V, A.F, stalled, locator, labels);
  EXPECT_EQ(r.filled, inside);
  EXPECT_EQ(r.patches, 1);
  EXPECT_EQ(r.unbounded, 0);
  const StretchResult after = measure_stretch(A, A.V, A.F, labels);
  EXPECT_EQ(after.collapsed, 0);
  EXPECT_EQ(after.folded, 0);
  for (Eigen::Index i = 0; i < A.V.rows(); ++i) {
    EXPECT_LT(locator.closest(labels.row(i).transpose()).distance, 1e-9) << i;  // on A
    if (!stalled[std::size_t(i)]) {
      EXPECT_EQ(labels.row(i), A.V.row(i)) << i;  // traced labels stay
    }
    EXPECT_LT((labels.row(i) - A.V.row(i)).norm(), 0.1) << i;
  }

  // Off, nothing moves.
  Eigen::MatrixXd untouched = A.V;
  untouched.row(0) = Eigen::RowVector3d(1.0, 0.0, 0.0);
  LabelFillOptions off;
  off.enabled = false;
  const Eigen::MatrixXd copy = untouched;
  EXPECT_EQ(fill_stalled_labels(A.V, A.F, stalled, locator, untouched, off).filled, 0);
  EXPECT_EQ(untouched, copy);
}

TEST(LabelFillTest, NeighboursWithOneLabelAreFilledUnlessTurnedOff) {
  // Two neighbours whose characteristics merged into one point: their edge collapses, and so do its triangles.
  const Surface A = unit_sphere();
  const SurfaceLocator locator(A);
  Eigen::MatrixXd labels = A.V;
  const int a = A.F(0, 0), b = A.F(0, 1);
  labels.row(b) = labels.row(a);
  EXPECT_GT(measure_stretch(A, A.V, A.F, labels).collapsed, 0);
  const std::vector<char> none(std::size_t(A.V.rows()), 0);
  LabelFillOptions off;
  off.coincident = false;
  Eigen::MatrixXd kept = labels;
  EXPECT_EQ(fill_stalled_labels(A.V, A.F, none, locator, kept, off).filled, 0);
  EXPECT_EQ(kept, labels);

  const LabelFillResult r = fill_stalled_labels(A.V, A.F, none, locator, labels);
  EXPECT_EQ(r.coincident, 2);
  EXPECT_EQ(r.filled, 2);
  const StretchResult after = measure_stretch(A, A.V, A.F, labels);
  EXPECT_EQ(after.collapsed, 0);
  EXPECT_EQ(after.folded, 0);
  EXPECT_LT((labels.row(a) - A.V.row(a)).norm(), 0.05);
  EXPECT_LT((labels.row(b) - A.V.row(b)).norm(), 0.05);
}

TEST(LabelFillTest, PatchWithNoTracedNeighbourKeepsItsLabelsAndBadSizesThrow) {
  const Surface A = unit_sphere();
  const SurfaceLocator locator(A);
  const std::vector<char> all(std::size_t(A.V.rows()), 1);  // a born component: nothing around it was traced
  Eigen::MatrixXd labels = Eigen::MatrixXd::Zero(A.V.rows(), 3);
  labels.col(0).setOnes();
  const Eigen::MatrixXd copy = labels;
  const LabelFillResult r = fill_stalled_labels(A.V, A.F, all, locator, labels);
  EXPECT_EQ(r.filled, 0);
  EXPECT_EQ(r.unbounded, A.V.rows());
  EXPECT_EQ(labels, copy);
  EXPECT_THROW(fill_stalled_labels(A.V, A.F, std::vector<char>(3, 0), locator, labels), InvalidInput);
  Eigen::MatrixXd short_labels = Eigen::MatrixXd::Zero(3, 3);
  EXPECT_THROW(fill_stalled_labels(A.V, A.F, all, locator, short_labels), InvalidInput);
}

}  // namespace
}  // namespace morphmap
