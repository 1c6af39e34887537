#pragma once
// Device paths for free-interaction studies and benchmarks: straight segments between
// waypoints sampled at a fixed spacing (the haptic increment per step).
#include <vector>

#include <Eigen/Core>

namespace hapco::sim {

// Points every step_m (m) along the polyline through `waypoints` (device translations, m),
// starting with waypoints[0] and ending exactly on every waypoint (a segment is split into
// ceil(length / step_m) equal increments). Throws InputError for fewer than two waypoints, a
// non-finite waypoint or step_m <= 0.
std::vector<Eigen::Vector3d> PolylinePath(const std::vector<Eigen::Vector3d>& waypoints, double step_m);

}  // namespace hapco::sim
