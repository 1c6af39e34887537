#pragma once
// Device trajectories as CSV files, one row per step: the rigid translation of the tool in
// metres. Shared by hapco-phantom (one row per servo tick) and hapco-sim (replaying exactly
// the poses a server stepped). Columns are found by header name, so the files other HapCo
// tools write are read as they are:
//   x_m,y_m,z_m      hapco-server --trace, hand-written files
//   dx_m,dy_m,dz_m   hapco-sim --csv, hapco-report --csv
// A file without a header holds x,y,z in its first three columns.
#include <Eigen/Dense>

#include <string>
#include <vector>

namespace hapco::io {

// Points 0..N: point 0 is the origin (the reference configuration), point k the row k. When
// the file has a client_id column, `client_id` selects that client's rows (required when the
// file holds several clients). Throws InputError with FILE:LINE for a malformed or non-finite
// row, a header without position columns (naming the accepted ones), or a file without rows.
std::vector<Eigen::Vector3d> LoadTrajectoryCsv(const std::string& path, const std::string& client_id = "");

// Same, from text already in memory; `source_name` is used in messages (the fuzz harness).
std::vector<Eigen::Vector3d> ParseTrajectoryCsv(const std::string& text, const std::string& source_name,
                                                const std::string& client_id = "");

}  // namespace hapco::io
