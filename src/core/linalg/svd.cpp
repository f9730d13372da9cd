#include "active_tensegrity/core/linalg/svd.h"

#include <Eigen/SVD>

namespace active_tensegrity::core
{
namespace
{
template <typename Decomposition>
Svd collect(const Decomposition& d, unsigned int options)
{
  Svd out;
  out.singular = d.singularValues();
  if (options & (Eigen::ComputeThinU | Eigen::ComputeFullU))
    out.u = d.matrixU();
  if (options & (Eigen::ComputeThinV | Eigen::ComputeFullV))
    out.v = d.matrixV();
  return out;
}
}  // namespace

Svd svd(const Eigen::MatrixXd& a, unsigned int options)
{
  return collect(Eigen::BDCSVD<Eigen::MatrixXd>(a, options), options);
}

Svd jacobiSvd(const Eigen::MatrixXd& a, unsigned int options)
{
  return collect(Eigen::JacobiSVD<Eigen::MatrixXd>(a, options), options);
}
}  // namespace active_tensegrity::core
