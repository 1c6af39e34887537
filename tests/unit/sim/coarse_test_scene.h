#pragma once
// The coarse two-box scene of the sim unit tests (tests/data/scenes/coarse.txtpb in code): a
// 10 x 2 x 2-cell Tet4 bar clamped at both ends and a 2 x 2 x 1-cell tool driven at its top,
// resting on the bar (zero initial gap). Tests set the solver and trajectory they need.
#include "sim/scene.h"

namespace hapco::sim::testing {

inline SceneSpec CoarseTestScene(double friction_coefficient) {
  SceneSpec scene;
  scene.name = "coarse";
  scene.obstacle.name = "red";
  scene.obstacle.box = {Eigen::Vector3d::Zero(), Eigen::Vector3d(0.10, 0.02, 0.02), Eigen::Vector3i(10, 2, 2),
                        fem::ElementOrder::kTet4};
  scene.obstacle.material = {3.0e6, 0.3};  // E in Pa, Poisson ratio
  scene.obstacle.clamped_faces = {fem::BoxFace::kXMin, fem::BoxFace::kXMax};
  scene.tool.name = "green";
  scene.tool.box = {Eigen::Vector3d(0.04, 0.0, 0.02), Eigen::Vector3d(0.02, 0.02, 0.01), Eigen::Vector3i(2, 2, 1),
                    fem::ElementOrder::kTet4};
  scene.tool.material = {8.0e7, 0.3};
  scene.tool.driven_face = fem::BoxFace::kZMax;
  scene.friction_coefficient = friction_coefficient;
  scene.activation_gap_m = 5e-4;
  return scene;
}

}  // namespace hapco::sim::testing
