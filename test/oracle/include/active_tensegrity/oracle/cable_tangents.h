/// A cable's exact tangents in the body coordinates (the test oracle's System): K and C into a block-sparse matrix.
#pragma once

#include <Eigen/Core>

#include "active_tensegrity/core/elements/cable.h"
#include "active_tensegrity/oracle/block_sparse.h"

namespace active_tensegrity::core
{
/// evaluateCable with k_weight * K + c_weight * C added into jac (when not null): K = -dF/dq and C = -dF/dqd, exact
/// (material, geometric and damping parts).
CableState evaluateCableTangents(const Model& model, const Cable& cable, const Eigen::VectorXd& q,
                                 const Eigen::VectorXd& qd, const ActuationValues& u, bool damping, Eigen::VectorXd* F,
                                 BlockSparseMatrix* jac, double k_weight, double c_weight);
}  // namespace active_tensegrity::core
