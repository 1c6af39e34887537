#include "io/trajectory_file.h"

#include <array>
#include <cmath>
#include <cstdlib>
#include <fstream>
#include <set>
#include <sstream>

#include "common/error.h"

namespace hapco::io {
namespace {

std::vector<std::string> SplitCsv(const std::string& line) {
  std::vector<std::string> fields;
  std::string field;
  std::istringstream in(line);
  while (std::getline(in, field, ',')) {
    while (!field.empty() && (field.back() == '\r' || field.back() == ' ')) field.pop_back();
    while (!field.empty() && field.front() == ' ') field.erase(field.begin());
    fields.push_back(field);
  }
  if (!line.empty() && line.back() == ',') fields.emplace_back();
  return fields;
}

bool ParseNumber(const std::string& text, double* value) {
  if (text.empty()) return false;
  char* end = nullptr;
  *value = std::strtod(text.c_str(), &end);
  return end == text.c_str() + text.size();
}

int Find(const std::vector<std::string>& header, const std::string& name) {
  for (std::size_t i = 0; i < header.size(); ++i) {
    if (header[i] == name) return static_cast<int>(i);
  }
  return -1;
}

std::vector<Eigen::Vector3d> ReadTrajectoryCsv(std::istream& in, const std::string& path,
                                               const std::string& client_id) {
  std::vector<Eigen::Vector3d> points{Eigen::Vector3d::Zero()};
  std::array<int, 3> columns{0, 1, 2};
  int client_column = -1;
  std::set<std::string> clients_seen;
  std::string line;
  int number = 0;
  bool first = true;
  while (std::getline(in, line)) {
    ++number;
    if (line.empty() || line == "\r") continue;
    const std::vector<std::string> fields = SplitCsv(line);
    if (first) {
      first = false;
      double ignored = 0.0;
      if (fields.empty() || !ParseNumber(fields[0], &ignored)) {
        // A header: positions by name.
        bool found = false;
        for (const auto& names : {std::array<const char*, 3>{"x_m", "y_m", "z_m"},
                                  std::array<const char*, 3>{"dx_m", "dy_m", "dz_m"}}) {
          const std::array<int, 3> c{Find(fields, names[0]), Find(fields, names[1]), Find(fields, names[2])};
          if (c[0] >= 0 && c[1] >= 0 && c[2] >= 0) {
            columns = c;
            found = true;
            break;
          }
        }
        if (!found) {
          throw InputError(path + ":" + std::to_string(number) +
                           ": the header names no position columns: expected x_m,y_m,z_m (hapco-server "
                           "--trace) or dx_m,dy_m,dz_m (hapco-sim, hapco-report)");
        }
        client_column = Find(fields, "client_id");
        continue;
      }
    }
    if (client_column >= 0) {
      const std::string client = client_column < static_cast<int>(fields.size()) ? fields[static_cast<std::size_t>(client_column)] : "";
      clients_seen.insert(client);
      if (!client_id.empty() && client != client_id) continue;
    }
    Eigen::Vector3d p;
    for (int a = 0; a < 3; ++a) {
      const auto column = static_cast<std::size_t>(columns[static_cast<std::size_t>(a)]);
      if (column >= fields.size() || !ParseNumber(fields[column], &p[a]) || !std::isfinite(p[a])) {
        throw InputError(path + ":" + std::to_string(number) + ": expected a finite number in column " +
                         std::to_string(column + 1) + " (" + (a == 0 ? "x" : a == 1 ? "y" : "z") + ", m)");
      }
    }
    points.push_back(p);
  }
  if (client_id.empty() && clients_seen.size() > 1) {
    std::string names;
    for (const auto& c : clients_seen) names += (names.empty() ? "" : ", ") + c;
    throw InputError(path + ": holds the poses of several clients (" + names + "): choose one client_id");
  }
  if (points.size() < 2) {
    throw InputError(path + ": no trajectory rows" + (client_id.empty() ? "" : " for client " + client_id));
  }
  return points;
}

}  // namespace

std::vector<Eigen::Vector3d> LoadTrajectoryCsv(const std::string& path, const std::string& client_id) {
  std::ifstream in(path);
  if (!in) throw InputError("cannot read trajectory " + path);
  return ReadTrajectoryCsv(in, path, client_id);
}

std::vector<Eigen::Vector3d> ParseTrajectoryCsv(const std::string& text, const std::string& source_name,
                                                const std::string& client_id) {
  std::istringstream in(text);
  return ReadTrajectoryCsv(in, source_name, client_id);
}

}  // namespace hapco::io
