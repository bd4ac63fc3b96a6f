// A Ceres cost function of one parameter block x (n variables) whose Jacobian is computed only
// for the free variables: forward-mode Jets seeded on the free ones (kWidth directions per pass),
// the frozen ones constants, their columns zero.
//
// With a ceres::SubsetManifold holding the frozen variables, LM uses only the free columns of
// J = dr/dx, so the frozen ones need not be computed. Ceres' DynamicAutoDiffCostFunction seeds a
// Jet direction per variable of the block; this one seeds m = (free count) directions, so each
// Jacobian pass carries m instead of n derivatives (the optimizer's glasses are held by default:
// 12 of the Cooke's 18 variables are free, 15 of the Tessar's 23, and 1 in the focus round).
// Derivative direction j of a Jet is computed by the same arithmetic whatever the Jet's width, so
// every free column, and the residuals (the Jets' values), equal those of the dynamic autodiff
// cost function bit for bit.
//
// Functor: template <typename T> bool operator()(T const* const* parameters, T* residuals) const,
// as for ceres::DynamicAutoDiffCostFunction (one parameter block).
#pragma once

#include <ceres/cost_function.h>
#include <ceres/jet.h>

#include <algorithm>
#include <cstddef>
#include <memory>
#include <vector>

#include "lensopt/core/jet_width.h"

namespace lensopt {

template <typename Functor, int kWidth>
class FreeJacobianCost final : public ceres::CostFunction {
 public:
  // Takes ownership of `functor`. `free`: the indices of the free variables (any order).
  FreeJacobianCost(Functor* functor, int n, int residuals, std::vector<int> free)
      : functor_(functor), free_(std::move(free)) {
    for (int i = 0; i < n; ++i)
      if (std::find(free_.begin(), free_.end(), i) == free_.end()) frozen_.push_back(i);
    mutable_parameter_block_sizes()->push_back(n);
    set_num_residuals(residuals);
  }

  bool Evaluate(double const* const* parameters, double* residuals,
                double** jacobians) const override {
    const int count = num_residuals();
    const int n = parameter_block_sizes()[0];
    const bool want_jacobian = jacobians != nullptr && jacobians[0] != nullptr;
    // The frozen columns are zero; every free column is written below, row by row.
    if (want_jacobian)
      for (int row = 0; row < count; ++row)
        for (int i : frozen_) jacobians[0][std::size_t(row) * n + i] = 0.0;
    if (!want_jacobian || free_.empty()) return (*functor_)(parameters, residuals);
    using J = ceres::Jet<double, kWidth>;
    const int m = static_cast<int>(free_.size());
    // Scratch reused across evaluations (a Cooke's residual Jets are about 1 MB: allocated per
    // evaluation, they were fresh pages to fault in and zero, and malloc trimming them again).
    thread_local std::vector<J> x, r;
    x.assign(n, J(0.0));
    r.assign(count, J(0.0));
    for (int first = 0; first < m; first += kWidth) {
      const int width = std::min(kWidth, m - first);
      for (int i = 0; i < n; ++i) x[i] = J(parameters[0][i]);
      for (int j = 0; j < width; ++j) x[free_[first + j]].v[j] = 1.0;
      const J* block = x.data();
      if (!(*functor_)(&block, r.data())) return false;
      for (int row = 0; row < count; ++row) {
        if (first == 0) residuals[row] = r[row].a;
        double* out = jacobians[0] + std::size_t(row) * n;
        for (int j = 0; j < width; ++j) out[free_[first + j]] = r[row].v[j];
      }
    }
    return true;
  }

 private:
  std::unique_ptr<Functor> functor_;
  std::vector<int> free_;
  std::vector<int> frozen_;  // the other variables, in increasing order
};

// The cost function for n variables of which `frozen` are held, at the narrowest Jet width of
// core/jet_width.h that takes every free variable in one pass (more passes above kJetWidthCap).
// Takes ownership of `functor`.
template <typename Functor>
ceres::CostFunction* make_free_jacobian_cost(Functor* functor, int n, int residuals,
                                             const std::vector<int>& frozen) {
  std::vector<int> free;
  for (int i = 0; i < n; ++i)
    if (std::find(frozen.begin(), frozen.end(), i) == frozen.end()) free.push_back(i);
  const int m = static_cast<int>(free.size());
  return with_jet_width(m, [&](auto width) -> ceres::CostFunction* {
    return new FreeJacobianCost<Functor, decltype(width)::value>(functor, n, residuals, free);
  });
}

}  // namespace lensopt
