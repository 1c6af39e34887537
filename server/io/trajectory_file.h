#pragma once
// Device trajectories as CSV files: one row x_m,y_m,z_m per step (a header line is skipped),
// the rigid translation of the tool in metres. Shared by hapco-phantom (one row per servo tick)
// and hapco-sim (replaying exactly the poses a server stepped).
#include <Eigen/Dense>

#include <string>
#include <vector>

namespace hapco::io {

// Points 0..N: point 0 is the origin (the reference configuration), point k the row k.
// Throws InputError with FILE:LINE for a malformed or non-finite row, or a file without rows.
std::vector<Eigen::Vector3d> LoadTrajectoryCsv(const std::string& path);

}  // namespace hapco::io
