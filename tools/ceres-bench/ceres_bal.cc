// Ceres side of tools/ceres-vs-ours.sh: bundle adjustment on a BAL file with the model of
// docs/optimisation.md ("Model") and fixtures/optim/ANCHORS.md, timed the way `slam-app optim-bench`
// times ours (the solve only; parsing and building the problem excluded).
//
// Usage: ceres_bal FILE HUBER(0|1) REPS [LINEAR(sparse|dense)] [MAX_ITERATIONS]
// Prints one line per repetition:
//   RESULT file=... loss=L2|Huber rep=N iterations=N accepted=N initial=... final=... seconds=WALL cpu=CPU ...
// (CPU: process time of the solve, std::clock; the same as wall on a quiet machine with 1 thread).
//
// BAL camera (9 numbers): angle-axis r, translation t, focal f, radial k1, k2.
//   P = R(r) X + t;  p = -(P.x, P.y) / P.z;  u = f (1 + k1 |p|^2 + k2 |p|^4) p;  residual = u - observed.
// Cost 0.5 sum |r|^2, or with Huber (delta 1 px on the residual norm) 0.5 sum rho(|r|^2), which is
// Ceres' HuberLoss. One thread, Levenberg-Marquardt, Schur elimination of the points (ordering: points
// first), Ceres' default tolerances; the angle-axis is a plain R^3 parameter (no manifold).

#include <ceres/ceres.h>
#include <ceres/rotation.h>

#include <chrono>
#include <ctime>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>
#include <vector>

namespace {

struct Bal {
  int n_cameras = 0, n_points = 0;
  std::vector<int> cam, pt;           // per observation
  std::vector<double> obs;            // 2 per observation
  std::vector<double> params;         // 9 per camera, then 3 per point
};

bool read_bal(const char* path, Bal* b) {
  FILE* f = std::fopen(path, "r");
  if (!f) { std::fprintf(stderr, "%s: cannot open\n", path); return false; }
  int n_obs = 0;
  bool ok = std::fscanf(f, "%d %d %d", &b->n_cameras, &b->n_points, &n_obs) == 3 && b->n_cameras > 0 &&
            b->n_points > 0 && n_obs > 0;
  if (ok) {
    b->cam.resize(n_obs); b->pt.resize(n_obs); b->obs.resize(2 * n_obs);
    for (int i = 0; ok && i < n_obs; ++i) {
      ok = std::fscanf(f, "%d %d %lf %lf", &b->cam[i], &b->pt[i], &b->obs[2 * i], &b->obs[2 * i + 1]) == 4 &&
           b->cam[i] >= 0 && b->cam[i] < b->n_cameras && b->pt[i] >= 0 && b->pt[i] < b->n_points;
      if (!ok) std::fprintf(stderr, "%s: bad observation %d\n", path, i);
    }
    b->params.resize(9 * b->n_cameras + 3 * b->n_points);
    for (size_t i = 0; ok && i < b->params.size(); ++i) {
      ok = std::fscanf(f, "%lf", &b->params[i]) == 1;
      if (!ok) std::fprintf(stderr, "%s: bad parameter %zu\n", path, i);
    }
  } else {
    std::fprintf(stderr, "%s: bad header\n", path);
  }
  std::fclose(f);
  return ok;
}

// Residual of one observation, templated for automatic differentiation.
struct Reprojection {
  Reprojection(double u, double v) : u(u), v(v) {}
  template <typename T>
  bool operator()(const T* camera, const T* point, T* residual) const {
    T p[3];
    ceres::AngleAxisRotatePoint(camera, point, p);
    for (int i = 0; i < 3; ++i) p[i] += camera[3 + i];
    const T x = -p[0] / p[2];
    const T y = -p[1] / p[2];
    const T n = x * x + y * y;
    const T scale = camera[6] * (T(1.0) + camera[7] * n + camera[8] * n * n);
    residual[0] = scale * x - T(u);
    residual[1] = scale * y - T(v);
    return true;
  }
  double u, v;
};

}  // namespace

int main(int argc, char** argv) {
  if (argc < 4) {
    std::fprintf(stderr, "usage: %s FILE HUBER(0|1) REPS [sparse|dense] [MAX_ITERATIONS]\n", argv[0]);
    return 2;
  }
  const char* file = argv[1];
  const bool huber = std::atoi(argv[2]) != 0;
  const int reps = std::atoi(argv[3]);
  const std::string linear = argc > 4 ? argv[4] : "sparse";
  const int max_iterations = argc > 5 ? std::atoi(argv[5]) : 100;
  if (reps < 1 || (linear != "sparse" && linear != "dense") || max_iterations < 1) {
    std::fprintf(stderr, "bad arguments\n");
    return 2;
  }
  Bal bal;
  if (!read_bal(file, &bal)) return 1;
  const char* base = std::strrchr(file, '/');
  base = base ? base + 1 : file;

  for (int rep = 0; rep < reps; ++rep) {
    std::vector<double> x = bal.params;  // a fresh start every repetition
    double* cameras = x.data();
    double* points = x.data() + 9 * bal.n_cameras;
    ceres::Problem problem;
    for (size_t i = 0; i < bal.cam.size(); ++i) {
      auto* cost = new ceres::AutoDiffCostFunction<Reprojection, 2, 9, 3>(
          new Reprojection(bal.obs[2 * i], bal.obs[2 * i + 1]));
      problem.AddResidualBlock(cost, huber ? new ceres::HuberLoss(1.0) : nullptr, cameras + 9 * bal.cam[i],
                               points + 3 * bal.pt[i]);
    }
    auto* ordering = new ceres::ParameterBlockOrdering;
    for (int j = 0; j < bal.n_points; ++j) ordering->AddElementToGroup(points + 3 * j, 0);
    for (int c = 0; c < bal.n_cameras; ++c) ordering->AddElementToGroup(cameras + 9 * c, 1);

    ceres::Solver::Options options;
    options.minimizer_type = ceres::TRUST_REGION;
    options.trust_region_strategy_type = ceres::LEVENBERG_MARQUARDT;
    options.linear_solver_type = linear == "sparse" ? ceres::SPARSE_SCHUR : ceres::DENSE_SCHUR;
    options.linear_solver_ordering.reset(ordering);
    options.num_threads = 1;
    options.max_num_iterations = max_iterations;
    options.minimizer_progress_to_stdout = false;
    options.logging_type = ceres::SILENT;

    ceres::Solver::Summary summary;
    const auto t0 = std::chrono::steady_clock::now();
    const std::clock_t c0 = std::clock();
    ceres::Solve(options, &problem, &summary);
    const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    const double cpu = double(std::clock() - c0) / CLOCKS_PER_SEC;
    std::printf("RESULT file=%s loss=%s rep=%d iterations=%d accepted=%d initial=%.9e final=%.9e seconds=%.4f "
                "cpu=%.4f termination=%s\n",
                base, huber ? "Huber" : "L2", rep, summary.num_successful_steps + summary.num_unsuccessful_steps,
                summary.num_successful_steps, summary.initial_cost, summary.final_cost, seconds, cpu,
                ceres::TerminationTypeToString(summary.termination_type));
    std::fflush(stdout);
  }
  return 0;
}
