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
  // Decimal only: strtod also reads "0x10" as 16 (a helper's file had a hex row, read silently).
  if (text.find_first_not_of("0123456789+-.eE") != std::string::npos) return false;
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

// client_id_if_listed: a file without a client_id column is read whole despite a client id.
TrajectoryFile ReadTrajectoryCsv(std::istream& in, const std::string& path, const std::string& client_id,
                                 bool client_id_if_listed = false) {
  TrajectoryFile file;
  std::vector<Eigen::Vector3d>& points = file.points;
  points.push_back(Eigen::Vector3d::Zero());
  std::array<int, 3> columns{0, 1, 2};
  int client_column = -1, sequence_column = -1, missing_column = -1, server_column = -1, step_column = -1;
  std::size_t header_fields = 0;  // fields of the header (or of the first row without one)
  bool has_header = false;
  file.session_starts.push_back(false);
  std::string last_server;
  std::uint64_t last_sequence = 0, last_step = 0;
  std::set<std::string> clients_seen;
  std::string line;
  int number = 0;
  bool first = true;
  while (std::getline(in, line)) {
    ++number;
    if (number == 1 && line.rfind("\xEF\xBB\xBF", 0) == 0) line.erase(0, 3);  // a UTF-8 byte-order mark
    if (line.empty() || line == "\r" || line[0] == '#') continue;
    const std::vector<std::string> fields = SplitCsv(line);
    if (first) {
      first = false;
      double ignored = 0.0;
      if (fields.empty() || !ParseNumber(fields[0], &ignored)) {
        // A header: positions by name; one set of them (a file with both is ambiguous).
        int found = 0;
        for (const auto& names : {std::array<const char*, 3>{"x_m", "y_m", "z_m"},
                                  std::array<const char*, 3>{"dx_m", "dy_m", "dz_m"}}) {
          const std::array<int, 3> c{Find(fields, names[0]), Find(fields, names[1]), Find(fields, names[2])};
          if (c[0] >= 0 && c[1] >= 0 && c[2] >= 0) {
            columns = c;
            ++found;
          }
        }
        if (found == 0) {
          const bool other_separator = line.find(';') != std::string::npos || line.find('\t') != std::string::npos;
          throw InputError(path + ":" + std::to_string(number) +
                           ": the header names no position columns: expected x_m,y_m,z_m (hapco-server "
                           "--trace) or dx_m,dy_m,dz_m (hapco-sim, hapco-report)" +
                           (other_separator ? ", separated by commas (this line has ';' or tabs)" : ""));
        }
        if (found > 1) {
          throw InputError(path + ":" + std::to_string(number) +
                           ": the header names both x_m,y_m,z_m and dx_m,dy_m,dz_m: keep the one that holds the "
                           "device's translation");
        }
        // A name twice: which column holds it is a guess (the first was taken, silently).
        for (std::size_t i = 0; i < fields.size(); ++i) {
          for (std::size_t j = i + 1; j < fields.size(); ++j) {
            if (!fields[i].empty() && fields[i] == fields[j]) {
              throw InputError(path + ":" + std::to_string(number) + ": the header names '" + fields[i] +
                               "' twice (columns " + std::to_string(i + 1) + " and " + std::to_string(j + 1) +
                               "): keep one");
            }
          }
        }
        header_fields = fields.size();
        has_header = true;
        client_column = Find(fields, "client_id");
        sequence_column = Find(fields, "sequence");
        if (sequence_column < 0) sequence_column = Find(fields, "pose_sequence");
        missing_column = Find(fields, "contacts_missing");
        server_column = Find(fields, "server_id");
        // A report's server step counter (not hapco-sim's own `step`, which has no sequences).
        if (sequence_column >= 0) step_column = Find(fields, "step");
        if (sequence_column >= 0) file.sequences.push_back(0);
        continue;
      }
    }
    // A row longer than the header (or than the first row of a file without one) has a field
    // too many somewhere: which column is which is then a guess (it was read silently).
    if (header_fields == 0) header_fields = fields.size();
    if (fields.size() > header_fields) {
      throw InputError(path + ":" + std::to_string(number) + ": " + std::to_string(fields.size()) + " fields, " +
                       (has_header ? "the header has " : "the first row has ") +
                       std::to_string(header_fields) + ": a field too many (a comma as decimal separator?)");
    }
    const auto field = [&](int column) -> std::string {
      return column >= 0 && column < static_cast<int>(fields.size()) ? fields[static_cast<std::size_t>(column)] : "";
    };
    if (client_column >= 0) {
      const std::string client = field(client_column);
      clients_seen.insert(client);
      if (!client_id.empty() && client != client_id) continue;
    }
    if (missing_column >= 0 && field(missing_column) == "1") {
      ++file.force_only_rows_skipped;
      continue;
    }
    bool starts = false;
    if (server_column >= 0) {
      const std::string server = field(server_column);
      file.servers.insert(server);
      starts = points.size() > 1 && server != last_server;
      last_server = server;
    }
    if (step_column >= 0) {
      const std::uint64_t step = std::strtoull(field(step_column).c_str(), nullptr, 10);
      starts = starts || (points.size() > 1 && step <= last_step);
      last_step = step;
    }
    if (sequence_column >= 0) {
      const std::string text = field(sequence_column);
      char* end = nullptr;
      const unsigned long long sequence = std::strtoull(text.c_str(), &end, 10);
      if (text.empty() || end != text.c_str() + text.size()) {
        throw InputError(path + ":" + std::to_string(number) + ": expected a pose sequence number in column " +
                         std::to_string(sequence_column + 1));
      }
      file.sequences.push_back(sequence);
      starts = starts || (points.size() > 1 && sequence <= last_sequence);
      last_sequence = sequence;
    }
    file.session_starts.push_back(starts);
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
  if (!client_id.empty() && client_column < 0 && !client_id_if_listed) {
    throw InputError(path + ": has no client_id column, so a client id selects nothing: give one only for a file "
                     "that holds several clients (a server's --trace, hapco-report --csv)");
  }
  if (points.size() < 2) {
    throw InputError(path + ": no trajectory rows" + (client_id.empty() ? "" : " for client " + client_id));
  }
  return file;
}

}  // namespace

TrajectoryFile LoadTrajectoryFile(const std::string& path, const std::string& client_id) {
  std::ifstream in(path);
  if (!in) throw InputError("cannot read trajectory " + path);
  return ReadTrajectoryCsv(in, path, client_id);
}

std::vector<Eigen::Vector3d> LoadTrajectoryCsv(const std::string& path, const std::string& client_id,
                                               bool client_id_if_listed) {
  std::ifstream in(path);
  if (!in) throw InputError("cannot read trajectory " + path);
  return ReadTrajectoryCsv(in, path, client_id, client_id_if_listed).points;
}

std::vector<Eigen::Vector3d> ParseTrajectoryCsv(const std::string& text, const std::string& source_name,
                                                const std::string& client_id) {
  std::istringstream in(text);
  return ReadTrajectoryCsv(in, source_name, client_id).points;
}

}  // namespace hapco::io
