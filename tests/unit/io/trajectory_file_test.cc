// Trajectory CSVs are read by header name: the files hapco-server --trace, hapco-sim --csv and
// hapco-report --csv write are accepted as they are; bad files name the line and the fix.
#include "io/trajectory_file.h"

#include <gtest/gtest.h>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <set>
#include <string>
#include <vector>

#include "common/error.h"

namespace hapco::io {
namespace {

std::string Write(const std::string& name, const std::string& text) {
  const std::string path = (std::filesystem::temp_directory_path() / ("hapco_traj_" + name + ".csv")).string();
  std::ofstream(path) << text;
  return path;
}

std::string ErrorOf(const std::string& path, const std::string& client = "") {
  try {
    LoadTrajectoryCsv(path, client);
  } catch (const InputError& error) {
    return error.what();
  }
  return "";
}

TEST(TrajectoryFileTest, ServerTraceColumnsAreFoundByName) {
  const std::string path = Write("trace",
                                 "client_id,sequence,x_m,y_m,z_m,fx_n,fy_n,fz_n,step_us\n"
                                 "a,1,0.001,0.002,-0.003,1,2,3,40\n"
                                 "b,1,0.5,0.5,0.5,0,0,0,40\n"
                                 "a,2,0.002,0.002,-0.003,1,2,3,41\n");
  const auto points = LoadTrajectoryCsv(path, "a");
  ASSERT_EQ(points.size(), 3u);
  EXPECT_TRUE(points[0].isZero());
  EXPECT_TRUE(points[1].isApprox(Eigen::Vector3d(0.001, 0.002, -0.003)));
  EXPECT_TRUE(points[2].isApprox(Eigen::Vector3d(0.002, 0.002, -0.003)));
  EXPECT_NE(ErrorOf(path).find("several clients (a, b)"), std::string::npos) << ErrorOf(path);
  EXPECT_NE(ErrorOf(path, "c").find("no trajectory rows for client c"), std::string::npos);
}

TEST(TrajectoryFileTest, SimAndReportColumnsAreFoundByName) {
  const std::string path = Write("sim", "step,phase,dx_m,dy_m,dz_m,fx_n\n1,press,0,0,-0.0001,0.5\n2,press,0,0,-0.0002,1\n");
  const auto points = LoadTrajectoryCsv(path);
  ASSERT_EQ(points.size(), 3u);
  EXPECT_DOUBLE_EQ(points[2].z(), -0.0002);
}

TEST(TrajectoryFileTest, HeaderlessFilesHoldXyzFirst) {
  const auto points = LoadTrajectoryCsv(Write("plain", "0.001,0,0\n0.002,0,0\n"));
  ASSERT_EQ(points.size(), 3u);
  EXPECT_DOUBLE_EQ(points[2].x(), 0.002);
}

TEST(TrajectoryFileTest, BadFilesNameTheLineAndTheFix) {
  EXPECT_NE(ErrorOf(Write("nocols", "a,b,c\n1,2,3\n")).find(":1: the header names no position columns"),
            std::string::npos);
  EXPECT_NE(ErrorOf(Write("nan", "x_m,y_m,z_m\n0,0,0\n0,nan,0\n")).find(":3: expected a finite number in column 2"),
            std::string::npos);
  EXPECT_NE(ErrorOf(Write("short", "x_m,y_m,z_m\n0,0\n")).find(":2:"), std::string::npos);
  EXPECT_NE(ErrorOf(Write("empty", "x_m,y_m,z_m\n")).find("no trajectory rows"), std::string::npos);
  // Read silently before (a helper session): a hex number, a field too many, a column named twice.
  EXPECT_NE(ErrorOf(Write("hex", "x_m,y_m,z_m\n0,0,0\n0x10,0,0\n")).find(":3: expected a finite number in column 1"),
            std::string::npos);
  EXPECT_NE(ErrorOf(Write("ragged", "x_m,y_m,z_m\n0,0,0\n0,0,0,5\n")).find(":3: 4 fields, the header has 3"),
            std::string::npos);
  EXPECT_NE(ErrorOf(Write("ragged_bare", "0,0,0\n0,0,-1e-4,1\n")).find(":2: 4 fields, the first row has 3"),
            std::string::npos);
  EXPECT_NE(ErrorOf(Write("dup", "dx_m,dx_m,dy_m,dz_m\n0,1,0,0\n")).find(":1: the header names 'dx_m' twice (columns 1 and 2)"),
            std::string::npos);
  EXPECT_EQ(ErrorOf(Write("decimal", "x_m,y_m,z_m\n0,-1.5e-4,+2E-4\n")), "") << "decimal forms are fine";
}

TEST(TrajectoryFileTest, SteppedPoseFilesGiveTheirSequencesAndSkipForceOnlyRows) {
  // A report CSV: pose sequences with gaps (poses the server ignored) and a restart (a second
  // server), and a row written from a force alone (no pose recorded: dx written as 0).
  const std::string path = Write("report",
                                 "step,client_id,time_ns,dx_m,dy_m,dz_m,pose_sequence,contacts_missing,server_id\n"
                                 "1,a,10,0,0,-0.0001,1,0,s1\n"
                                 "2,a,20,0,0,-0.0005,4,0,s1\n"
                                 "3,a,30,0,0,0,5,1,s1\n"
                                 "1,a,40,0,0,-0.0004,2,0,s2\n");
  const TrajectoryFile file = LoadTrajectoryFile(path, "a");
  ASSERT_EQ(file.points.size(), 4u);
  EXPECT_EQ(file.sequences, (std::vector<std::uint64_t>{0, 1, 4, 2}));
  EXPECT_EQ(file.force_only_rows_skipped, 1);
  EXPECT_EQ(file.servers, (std::set<std::string>{"s1", "s2"}));
  EXPECT_EQ(file.session_starts, (std::vector<bool>{false, false, false, true}));
  EXPECT_DOUBLE_EQ(file.points[3].z(), -0.0004);
  // A trace names it `sequence`; files without one give none.
  EXPECT_EQ(LoadTrajectoryFile(Write("trace_seq", "client_id,sequence,x_m,y_m,z_m\na,7,0,0,0\n"), "a").sequences,
            (std::vector<std::uint64_t>{0, 7}));
  EXPECT_TRUE(LoadTrajectoryFile(Write("noseq", "dx_m,dy_m,dz_m\n0,0,0\n")).sequences.empty());
  EXPECT_NE(ErrorOf(Write("badseq", "sequence,x_m,y_m,z_m\nx,0,0,0\n")).find(":2: expected a pose sequence"),
            std::string::npos);
}

TEST(TrajectoryFileTest, SpreadsheetFilesAndAmbiguousHeaders) {
  // "CSV UTF-8" starts with a byte-order mark; '#' lines are comments.
  const auto points = LoadTrajectoryCsv(Write("bom", "\xEF\xBB\xBF# from a spreadsheet\ndx_m,dy_m,dz_m\n0,0,-0.001\n"));
  ASSERT_EQ(points.size(), 2u);
  EXPECT_DOUBLE_EQ(points[1].z(), -0.001);
  EXPECT_NE(ErrorOf(Write("semicolon", "dx_m;dy_m;dz_m\n0;0;0\n")).find("separated by commas"), std::string::npos);
  EXPECT_NE(ErrorOf(Write("both", "x_m,y_m,z_m,dx_m,dy_m,dz_m\n0,0,0,0,0,0\n")).find("both x_m,y_m,z_m and dx_m"),
            std::string::npos);
  EXPECT_NE(ErrorOf(Write("noclient", "dx_m,dy_m,dz_m\n0,0,0\n"), "zed").find("has no client_id column"),
            std::string::npos);
  // hapco-phantom's own client id picks its rows where the file lists clients, else all rows.
  EXPECT_EQ(LoadTrajectoryCsv(Write("noclient2", "dx_m,dy_m,dz_m\n0,0,0\n"), "zed", true).size(), 2u);
  EXPECT_EQ(LoadTrajectoryCsv(Write("two", "client_id,x_m,y_m,z_m\na,0,0,0\nb,1e-3,0,0\nb,2e-3,0,0\n"), "b", true).size(),
            3u);
}

}  // namespace
}  // namespace hapco::io
