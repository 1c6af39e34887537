#pragma once
// Shared helpers for the FCLIB tests: the hand-written 3-contact problem that
// scripts/make_siconos_style_fclib.py stores in tests/data/fclib/, and scratch paths.
#include <gtest/gtest.h>
#include <unistd.h>

#include <Eigen/Dense>
#include <filesystem>
#include <fstream>
#include <string>

#include "contact/problem.h"

namespace hapco::fclib::testing {

inline std::string DataFile(const std::string& name) {
  return std::string(HAPCO_SOURCE_DIR) + "/tests/data/fclib/" + name;
}

// A fresh path in a per-process scratch directory, named after the running test.
inline std::string ScratchFile(const std::string& suffix) {
  const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
  const std::filesystem::path dir = std::filesystem::path(::testing::TempDir()) /
                                    ("hapco_fclib_" + std::to_string(::getpid()));
  std::filesystem::create_directories(dir);
  const std::filesystem::path path =
      dir / (std::string(info->test_suite_name()) + "." + info->name() + suffix);
  std::filesystem::remove(path);
  return path.string();
}

inline void WriteText(const std::string& path, const std::string& text) {
  std::ofstream out(path, std::ios::binary);
  out << text;
}

// The known problem, typed in by hand from the script (not read from any file).
inline contact::ContactProblem KnownProblem() {
  contact::ContactProblem p;
  Eigen::MatrixXd w(9, 9);
  // clang-format off
  w << 2.0,  0.1,  0.0,  0.5,  0.0,  0.0,  0.0,  0.0,  0.0,
       0.1,  1.0,  0.0,  0.0,  0.25, 0.0,  0.0,  0.0,  0.0,
       0.0,  0.0,  1.0,  0.0,  0.0,  0.0,  0.0,  0.0,  0.0,
       0.5,  0.0,  0.0,  3.0,  0.0,  0.2,  0.25, 0.0,  0.0,
       0.0,  0.25, 0.0,  0.0,  1.5,  0.0,  0.0,  0.0,  0.0,
       0.0,  0.0,  0.0,  0.2,  0.0,  1.5,  0.0,  0.0,  0.1,
       0.0,  0.0,  0.0,  0.25, 0.0,  0.0,  1.0,  0.0,  0.0,
       0.0,  0.0,  0.0,  0.0,  0.0,  0.0,  0.0,  0.5,  0.0,
       0.0,  0.0,  0.0,  0.0,  0.0,  0.1,  0.0,  0.0,  0.5;
  // clang-format on
  p.flexibility_m_per_n = w;
  p.free_displacement_m.resize(9);
  p.free_displacement_m << -1.0, 0.5, -0.25, -0.5, 0.1, 0.0, 0.75, 0.0, 0.0;
  p.friction_coefficient.resize(3);
  p.friction_coefficient << 0.3, 0.5, 0.8;
  return p;
}

}  // namespace hapco::fclib::testing
