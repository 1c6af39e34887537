#include "io/trajectory_file.h"

#include <fstream>
#include <sstream>

#include "common/error.h"

namespace hapco::io {

std::vector<Eigen::Vector3d> LoadTrajectoryCsv(const std::string& path) {
  std::ifstream in(path);
  if (!in) throw InputError("cannot read trajectory " + path);
  std::vector<Eigen::Vector3d> points{Eigen::Vector3d::Zero()};
  std::string line;
  int number = 0;
  while (std::getline(in, line)) {
    ++number;
    if (line.empty()) continue;
    for (char& c : line) {
      if (c == ',') c = ' ';
    }
    std::istringstream fields(line);
    Eigen::Vector3d p;
    if (!(fields >> p.x() >> p.y() >> p.z()) || !p.allFinite()) {
      if (number == 1) continue;  // header
      throw InputError(path + ":" + std::to_string(number) + ": expected x_m,y_m,z_m (finite numbers)");
    }
    points.push_back(p);
  }
  if (points.size() < 2) throw InputError(path + ": no trajectory rows");
  return points;
}

}  // namespace hapco::io
