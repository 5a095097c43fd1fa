// Private to libmr: the one Ceres solver set-up of photo/'s fits (sun direction, lamp
// intensities, BRDF). Every fit is small (at most a handful of parameter blocks), so the solver
// runs silent, on one thread, with dense linear algebra; what differs between fits is the
// iteration budget, the tolerances and the linear solver.
#pragma once

#include <ceres/ceres.h>

namespace mr::photo {

struct SolverSettings {
  int max_iterations = 100;
  double function_tolerance = 1e-12;
  double gradient_tolerance = 1e-14;
  double parameter_tolerance = 1e-12;
  ceres::LinearSolverType linear_solver = ceres::DENSE_QR;
};

inline ceres::Solver::Options solver_options(const SolverSettings& settings) {
  ceres::Solver::Options options;
  options.linear_solver_type = settings.linear_solver;
  options.max_num_iterations = settings.max_iterations;
  options.function_tolerance = settings.function_tolerance;
  options.gradient_tolerance = settings.gradient_tolerance;
  options.parameter_tolerance = settings.parameter_tolerance;
  options.num_threads = 1;
  options.logging_type = ceres::SILENT;
  options.minimizer_progress_to_stdout = false;
  return options;
}

}  // namespace mr::photo
