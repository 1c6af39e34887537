#pragma once
// Device trajectories as CSV files, one row per step: the rigid translation of the tool in
// metres. Shared by hapco-phantom (one row per servo tick) and hapco-sim (replaying exactly
// the poses a server stepped). Columns are found by header name, so the files other HapCo
// tools write are read as they are:
//   x_m,y_m,z_m      hapco-server --trace, hand-written files
//   dx_m,dy_m,dz_m   hapco-sim --csv, hapco-report --csv
// A file without a header holds x,y,z in its first three columns. A UTF-8 byte-order mark
// (spreadsheets' "CSV UTF-8") and lines starting with '#' are skipped.
#include <Eigen/Dense>

#include <cstdint>
#include <set>
#include <string>
#include <vector>

namespace hapco::io {

// A trajectory file with what the stepped-pose files (a server's --trace, hapco-report --csv)
// say beyond the positions.
struct TrajectoryFile {
  std::vector<Eigen::Vector3d> points;  // as LoadTrajectoryCsv
  // The client's pose sequence of each point (column `sequence` of a trace, `pose_sequence` of
  // a report CSV; [0] = 0), empty when the file has none: the server's jump check scales with
  // the sequence gap, so a replay of stepped poses needs the real gaps, not the row numbers.
  std::vector<std::uint64_t> sequences;
  // Per point ([0] false): the row starts a new session of its client (the server_id changes,
  // or the pose sequence or a report's step counter starts again): a restarted client, or a
  // client moved to another server, whose session started from the reference configuration.
  std::vector<bool> session_starts;
  // hapco-report rows written from a force alone (contacts_missing 1: the frame was lost, the
  // pose is not in the recording): skipped, counted.
  int force_only_rows_skipped = 0;
  std::set<std::string> servers;  // server_id column values (several: a failover or restart)
};

// Same rules as LoadTrajectoryCsv.
TrajectoryFile LoadTrajectoryFile(const std::string& path, const std::string& client_id = "");

// Points 0..N: point 0 is the origin (the reference configuration), point k the row k. When
// the file has a client_id column, `client_id` selects that client's rows (required when the
// file holds several clients). Throws InputError with FILE:LINE for a malformed or non-finite
// row, a header without position columns (naming the accepted ones), or a file without rows.
// client_id_if_listed: a file without a client_id column is read whole (hapco-phantom passes
// its own --client-id, which then picks its rows from a multi-client trace); otherwise a
// client id given for such a file is an error.
std::vector<Eigen::Vector3d> LoadTrajectoryCsv(const std::string& path, const std::string& client_id = "",
                                               bool client_id_if_listed = false);

// Same, from text already in memory; `source_name` is used in messages (the fuzz harness).
std::vector<Eigen::Vector3d> ParseTrajectoryCsv(const std::string& text, const std::string& source_name,
                                                const std::string& client_id = "");

}  // namespace hapco::io
