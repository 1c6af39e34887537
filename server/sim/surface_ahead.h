#pragma once
// The obstacle surface ahead of a tool that touches nothing (issue 12, docs/network-haptics.md):
// the nearest node-to-face pair between the bodies within a reach, as a plane the device can
// meet. A remote client renders the first contact from it at once, instead of one network
// round trip late (at 200 ms the device sank 3.9 mm into the obstacle before the first force).
//
// Without contact the configuration is known exactly (quasi-static, no load): the obstacle
// rests in its reference configuration and the tool is translated rigidly by d with its free
// displacement (TwoBodyModel::tool_unit_fields). The same two passes as the step
// (step_pipeline.h) are searched on it: tool surface nodes against obstacle faces, and the
// obstacle's sharp-edge nodes against tool faces. Moving the device by Δx changes every pair's
// gap by n·Δx to first order (n the face normal, towards the slave), so the nearest pair's
//   gap(x) = gap₀ + n_device·(x − d)
// is what a client extrapolates; n_device is the direction a contact there pushes the device.
#include <Eigen/Core>

#include <vector>

#include "sim/collision.h"
#include "sim/two_body_model.h"

namespace hapco::sim {

struct SurfaceAhead {
  bool found = false;                                       // a pair within reach
  double gap_m = 0.0;                                       // gap₀ >= 0 at the pose, m
  Eigen::Vector3d normal_device = Eigen::Vector3d::Zero();  // unit: a contact there pushes the device along it
  Eigen::Vector3d point_m = Eigen::Vector3d::Zero();        // the obstacle's point of the pair, m
};

class SurfaceAheadProbe {
 public:
  // reach_m > 0: pairs farther apart than this are not looked for.
  SurfaceAheadProbe(const TwoBodyModel& model, double reach_m);

  // The nearest pair for the tool translated by device_translation_m (m) with no contact load.
  // Allocation-free after the first call. Cost: one tree query per tool surface node and per
  // obstacle edge node (tens of µs on the benchmarks).
  const SurfaceAhead& Probe(const Eigen::Vector3d& device_translation_m);

  double reach_m() const { return reach_m_; }

 private:
  const TwoBodyModel& model_;
  double reach_m_;
  CollisionParameters parameters_;
  ContactDetector tool_pass_, edge_pass_;
  Eigen::Matrix<double, Eigen::Dynamic, 3> tool_positions_m_;
  std::vector<ContactPoint> points_;
  SurfaceAhead result_;
};

}  // namespace hapco::sim
