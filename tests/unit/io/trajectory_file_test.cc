// Trajectory CSVs are read by header name: the files hapco-server --trace, hapco-sim --csv and
// hapco-report --csv write are accepted as they are; bad files name the line and the fix.
#include "io/trajectory_file.h"

#include <gtest/gtest.h>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>

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
}

}  // namespace
}  // namespace hapco::io
