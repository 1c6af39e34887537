#include "sim/device_path.h"

#include <cmath>
#include <string>

#include "common/error.h"

namespace hapco::sim {

std::vector<Eigen::Vector3d> PolylinePath(const std::vector<Eigen::Vector3d>& waypoints, double step_m) {
  if (waypoints.size() < 2) throw InputError("a device path needs at least two waypoints");
  if (!(std::isfinite(step_m) && step_m > 0.0)) {
    throw InputError("device path step must be a finite distance > 0 m, got " + std::to_string(step_m));
  }
  for (const auto& w : waypoints) {
    if (!w.allFinite()) throw InputError("device path waypoint is not finite");
  }
  std::vector<Eigen::Vector3d> path{waypoints.front()};
  for (std::size_t i = 1; i < waypoints.size(); ++i) {
    const Eigen::Vector3d from = waypoints[i - 1], to = waypoints[i];
    const int increments = std::max(1, static_cast<int>(std::ceil((to - from).norm() / step_m - 1e-9)));
    for (int k = 1; k <= increments; ++k) {
      path.push_back(k == increments ? to : Eigen::Vector3d(from + (to - from) * (static_cast<double>(k) / increments)));
    }
  }
  return path;
}

}  // namespace hapco::sim
