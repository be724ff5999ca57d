// Helpers of the tetrahedral mesh in R^4 (paper §5.2).
#include "mesh/tet_mesh4.h"

#include <Eigen/Dense>

namespace morphmap {

Eigen::Vector4d cross4(const Eigen::Vector4d& a, const Eigen::Vector4d& b, const Eigen::Vector4d& c) {
  // n_i is the cofactor of e_i in det[a b c e_i]; expanding along the last column gives det[a b c n] = |n|^2.
  Eigen::Vector4d n;
  for (int i = 0; i < 4; ++i) {
    Eigen::Matrix3d m;
    int r = 0;
    for (int k = 0; k < 4; ++k) {
      if (k == i) continue;
      m.row(r++) << a(k), b(k), c(k);
    }
    n(i) = ((i + 3) % 2 == 0 ? 1.0 : -1.0) * m.determinant();
  }
  return n;
}

}  // namespace morphmap
