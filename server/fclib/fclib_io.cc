#include "fclib/fclib_io.h"

#include "fclib/fclib_c.h"
#include <dlfcn.h>
#include <execinfo.h>
#include <hdf5.h>
#include <poll.h>
#include <sys/prctl.h>
#include <sys/socket.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <csignal>
#include <cstdio>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <memory>
#include <new>
#include <optional>
#include <sstream>
#include <string_view>
#include <type_traits>
#include <utility>
#include <vector>

#include "common/error.h"
#include "fclib/fclib_matrix.h"

namespace hapco::fclib {
namespace {

// HDF5 prints its error stack on every failed call unless told not to; our callers get an
// InputError instead. Process-wide, once.
void SilenceHdf5() {
  static const bool silenced = [] {
    H5Eset_auto2(H5E_DEFAULT, nullptr, nullptr);
    return true;
  }();
  (void)silenced;
}

[[noreturn]] void Fail(const std::string& path, const std::string& what) {
  throw InputError("FCLIB file '" + path + "': " + what);
}

// In the reader's worker process (ReaderWorker, end of file): its end of the socket; -1 in
// every other process.
int worker_socket = -1;
constexpr char kCheckedMark = 'C';

// Called by a read once the file's layout has passed every check, before libfclib reads it:
// the reader then stops limiting the worker's memory to what checks need (the read itself is
// bounded by the checked sizes; a valid file of kMaxContacts holds a 1.2 GB W).
void MarkChecked() {
  if (worker_socket >= 0 && send(worker_socket, &kCheckedMark, 1, MSG_NOSIGNAL) != 1) std::_Exit(0);
}

// RAII for an HDF5 identifier.
class H5Id {
 public:
  using Closer = herr_t (*)(hid_t);
  H5Id(hid_t id, Closer closer) : id_(id), closer_(closer) {}
  H5Id(const H5Id&) = delete;
  H5Id& operator=(const H5Id&) = delete;
  ~H5Id() {
    if (id_ >= 0) closer_(id_);
  }
  hid_t get() const { return id_; }
  bool valid() const { return id_ >= 0; }
  // Closes now (libfclib opens the file itself afterwards).
  void Close() {
    if (id_ >= 0) closer_(id_);
    id_ = -1;
  }

 private:
  hid_t id_;
  Closer closer_;
};

// RAII for what libfclib allocates.
struct LocalDeleter {
  void operator()(fclib_local* problem) const {
    fclib_delete_local(problem);  // frees the members, not the struct
    std::free(problem);           // NOLINT: allocated by libfclib with calloc
  }
};
struct SolutionDeleter {
  void operator()(fclib_solution* solution) const { fclib_delete_solutions(solution, 1); }
};
using LocalPtr = std::unique_ptr<fclib_local, LocalDeleter>;
using SolutionPtr = std::unique_ptr<fclib_solution, SolutionDeleter>;

// --- Inspection of the HDF5 layout (so that libfclib, which exits on errors, never fails) ---

// True when every component of the absolute path `name` exists (H5Lexists fails, rather than
// answering false, when an intermediate group is missing, so the components are asked one by
// one). With every parent present, a failing H5Lexists means HDF5 cannot read the link table
// itself: the file (path) is refused. libfclib tests `if (H5Lexists(...))`, which takes that
// failure (-1) for "exists" and then exits on the open that follows (found by fuzzing:
// tests/data/fuzz/fclib_local/corrupt_heap_lexists_fails.h5).
bool Exists(hid_t file, const std::string& path, const std::string& name) {
  std::string prefix;
  std::size_t start = 1;
  while (start <= name.size()) {
    const std::size_t end = name.find('/', start);
    prefix = name.substr(0, end);
    const htri_t exists = H5Lexists(file, prefix.c_str(), H5P_DEFAULT);
    if (exists < 0) Fail(path, "HDF5 cannot look up " + prefix + " (a corrupt link table or heap)");
    if (exists == 0) return false;
    if (end == std::string::npos) break;
    start = end + 1;
  }
  return true;
}

H5I_type_t ObjectType(hid_t file, const std::string& path, const std::string& name) {
  if (!Exists(file, path, name)) return H5I_BADID;
  H5Id object(H5Oopen(file, name.c_str(), H5P_DEFAULT), H5Oclose);
  if (!object.valid()) return H5I_BADID;
  return H5Iget_type(object.get());
}

void RequireGroup(hid_t file, const std::string& path, const std::string& name) {
  const H5I_type_t type = ObjectType(file, path, name);
  if (type == H5I_BADID) Fail(path, "missing group " + name);
  if (type != H5I_GROUP) Fail(path, name + " is not a group");
}

constexpr std::size_t kMaxStringBytes = 1 << 20;  // info text, a sanity bound

// Largest chunk HDF5 may have to hold in memory for one dataset of these files (libfclib
// writes contiguous datasets; a chunked one is accepted up to this).
constexpr std::size_t kMaxChunkBytes = 64u << 20;

struct DatasetShape {
  H5T_class_t type_class = H5T_NO_CLASS;
  long points = 0;
  std::size_t type_size = 0;
  bool variable_string = false;
  std::size_t chunk_bytes = 0;  // 0: not chunked
};

DatasetShape InspectDataset(hid_t file, const std::string& path, const std::string& name) {
  const H5I_type_t type = ObjectType(file, path, name);
  if (type == H5I_BADID) Fail(path, "missing dataset " + name);
  if (type != H5I_DATASET) Fail(path, name + " is not a dataset");
  H5Id dataset(H5Dopen2(file, name.c_str(), H5P_DEFAULT), H5Dclose);
  H5Id datatype(H5Dget_type(dataset.get()), H5Tclose);
  H5Id space(H5Dget_space(dataset.get()), H5Sclose);
  if (!dataset.valid() || !datatype.valid() || !space.valid()) Fail(path, "cannot open " + name);
  DatasetShape shape;
  shape.type_class = H5Tget_class(datatype.get());
  shape.type_size = H5Tget_size(datatype.get());
  shape.points = static_cast<long>(H5Sget_simple_extent_npoints(space.get()));
  shape.variable_string =
      shape.type_class == H5T_STRING && H5Tis_variable_str(datatype.get()) > 0;
  H5Id create_plist(H5Dget_create_plist(dataset.get()), H5Pclose);
  if (create_plist.valid() && H5Pget_layout(create_plist.get()) == H5D_CHUNKED) {
    hsize_t dims[H5S_MAX_RANK] = {};
    const int rank = H5Pget_chunk(create_plist.get(), H5S_MAX_RANK, dims);
    double bytes = static_cast<double>(shape.type_size);
    for (int d = 0; d < rank; ++d) bytes *= static_cast<double>(dims[d]);
    shape.chunk_bytes = rank > 0 ? static_cast<std::size_t>(std::min(bytes, 1e18)) : 0;
  }
  return shape;
}

// Found by fuzzing (tests/data/fuzz/fclib_local/integer_type_of_4gb.h5): a corrupt datatype
// declared 4-byte-looking integers of 4294901764 bytes each, and HDF5 allocated 4 GB per
// element to convert them. Numbers are 1 to 8 bytes wide; chunks are bounded.
void CheckElementStorage(const std::string& path, const std::string& name, const DatasetShape& shape) {
  if (shape.type_size < 1 || shape.type_size > 8) {
    Fail(path, name + " has elements of " + std::to_string(shape.type_size) +
                   " bytes; numbers are 1 to 8 bytes wide (corrupt file?)");
  }
  if (shape.chunk_bytes > kMaxChunkBytes) {
    Fail(path, name + " is stored in chunks of " + std::to_string(shape.chunk_bytes) +
                   " bytes, more than " + std::to_string(kMaxChunkBytes) + " (corrupt file?)");
  }
}

// Reads the whole dataset as libfclib will (same memory type), so that a dataset whose
// metadata is fine but whose data cannot be read (a corrupted file) fails here and not in
// libfclib. `memory_type` < 0 reads with the file's own type (strings, as H5LT does).
void TrialRead(hid_t file, const std::string& path, const std::string& name,
               const DatasetShape& shape, hid_t memory_type, std::size_t bytes_per_point) {
  H5Id dataset(H5Dopen2(file, name.c_str(), H5P_DEFAULT), H5Dclose);
  if (!dataset.valid()) Fail(path, "cannot open " + name);
  H5Id file_type(H5Dget_type(dataset.get()), H5Tclose);
  std::vector<unsigned char> buffer(static_cast<std::size_t>(shape.points) * bytes_per_point +
                                    1);
  const hid_t type = memory_type >= 0 ? memory_type : file_type.get();
  if (H5Dread(dataset.get(), type, H5S_ALL, H5S_ALL, H5P_DEFAULT, buffer.data()) < 0) {
    Fail(path, "cannot read the data of " + name + " (corrupt file?)");
  }
}

void CheckPoints(const std::string& path, const std::string& name, const DatasetShape& shape,
                 long min_points, long max_points) {
  if (shape.points >= min_points && shape.points <= max_points) return;
  std::ostringstream msg;
  msg << name << " has " << shape.points << " entries, expected ";
  if (min_points == max_points) {
    msg << min_points;
  } else {
    msg << "between " << min_points << " and " << max_points;
  }
  Fail(path, msg.str());
}

// Integer dataset with min_points..max_points entries, checked before anything is read.
DatasetShape RequireIntegers(hid_t file, const std::string& path, const std::string& name,
                             long min_points, long max_points) {
  const DatasetShape shape = InspectDataset(file, path, name);
  if (shape.type_class != H5T_INTEGER) Fail(path, name + " must hold integers");
  CheckElementStorage(path, name, shape);
  CheckPoints(path, name, shape, min_points, max_points);
  TrialRead(file, path, name, shape, H5T_NATIVE_INT, sizeof(int));
  return shape;
}

// Numeric dataset (read as double, as libfclib does) with min_points..max_points entries.
DatasetShape RequireNumbers(hid_t file, const std::string& path, const std::string& name,
                            long min_points, long max_points) {
  const DatasetShape shape = InspectDataset(file, path, name);
  if (shape.type_class != H5T_FLOAT && shape.type_class != H5T_INTEGER) {
    Fail(path, name + " must hold numbers");
  }
  CheckElementStorage(path, name, shape);
  CheckPoints(path, name, shape, min_points, max_points);
  TrialRead(file, path, name, shape, H5T_NATIVE_DOUBLE, sizeof(double));
  return shape;
}
DatasetShape RequireNumbers(hid_t file, const std::string& path, const std::string& name,
                            long points) {
  return RequireNumbers(file, path, name, points, points);
}

int ReadInt(hid_t file, const std::string& path, const std::string& name) {
  RequireIntegers(file, path, name, 1, 1);
  H5Id dataset(H5Dopen2(file, name.c_str(), H5P_DEFAULT), H5Dclose);
  int value = 0;
  if (H5Dread(dataset.get(), H5T_NATIVE_INT, H5S_ALL, H5S_ALL, H5P_DEFAULT, &value) < 0) {
    Fail(path, "cannot read " + name);
  }
  return value;
}

// Whether `group` has a link whose name starts with `name`, found by iterating the links as
// libfclib's H5LTfind_dataset does (it compares only strlen(name) characters): in a corrupted
// file a name lookup (H5Lexists) can miss a link, e.g. "title\201", that this search finds,
// and libfclib would then fail to open "title" and exit.
bool ListedInGroup(hid_t file, const std::string& path, const std::string& group,
                   const std::string& name) {
  struct Search {
    const std::string* name;
    bool found;
  } search{&name, false};
  auto visit = [](hid_t, const char* link_name, const H5L_info_t*, void* data) -> herr_t {
    auto* s = static_cast<Search*>(data);
    if (std::strncmp(link_name, s->name->c_str(), s->name->size()) == 0) {
      s->found = true;
      return 1;  // stop
    }
    return 0;
  };
  H5Id group_id(H5Gopen2(file, group.c_str(), H5P_DEFAULT), H5Gclose);
  if (!group_id.valid()) Fail(path, "cannot open group " + group);
  hsize_t index = 0;
  if (H5Literate(group_id.get(), H5_INDEX_NAME, H5_ITER_NATIVE, &index, visit, &search) < 0) {
    Fail(path, "cannot list the links of " + group + " (corrupt file?)");
  }
  return search.found;
}

// Size in bytes of a fixed-length string dataset (libfclib reads it with H5LT into a buffer
// of that size: a variable-length string or an array of strings would be read wrongly).
std::size_t RequireOptionalString(hid_t file, const std::string& path,
                                  const std::string& group, const std::string& leaf) {
  const std::string name = group + "/" + leaf;
  const bool listed = ListedInGroup(file, path, group, leaf);
  const bool exists = Exists(file, path, name);
  if (!listed && !exists) return 0;
  if (!exists) Fail(path, name + " is listed but cannot be opened (corrupt file?)");
  const DatasetShape shape = InspectDataset(file, path, name);
  if (shape.type_class != H5T_STRING || shape.variable_string || shape.points != 1) {
    Fail(path, name + " must be one fixed-length string (as H5LTmake_dataset_string writes)");
  }
  if (shape.type_size > kMaxStringBytes) {
    Fail(path, name + " is longer than " + std::to_string(kMaxStringBytes) + " bytes");
  }
  if (shape.chunk_bytes > kMaxChunkBytes) {
    Fail(path, name + " is stored in chunks of " + std::to_string(shape.chunk_bytes) + " bytes (corrupt file?)");
  }
  TrialRead(file, path, name, shape, -1, shape.type_size);
  return shape.type_size;
}

struct LocalLayout {
  int m = 0, n = 0, nz = 0, nzmax = 0;
  long x_points = 0;
  std::size_t title_size = 0, description_size = 0, math_info_size = 0;
};

struct MatrixLayout {
  int m = 0, n = 0, nz = 0, nzmax = 0;
  long x_points = 0;
};

// The datasets fclib's read_matrix reads from `group` (nzmax, m, n, nz, p, i, x and the
// optional conditioning/determinant/rank/comment), checked with the sizes its buffers get.
// `check_shape(m, n)` (throws) runs once m and n are known, before any array is read.
MatrixLayout CheckMatrixGroup(hid_t file, const std::string& path, const std::string& group,
                              const std::function<void(int, int)>& check_shape) {
  RequireGroup(file, path, group);
  MatrixLayout layout;
  layout.nzmax = ReadInt(file, path, group + "/nzmax");
  layout.m = ReadInt(file, path, group + "/m");
  layout.n = ReadInt(file, path, group + "/n");
  layout.nz = ReadInt(file, path, group + "/nz");
  const int m = layout.m, n = layout.n, nz = layout.nz, nzmax = layout.nzmax;
  check_shape(m, n);
  std::ostringstream msg;
  if (m <= 0 || n <= 0) {
    msg << group << " is " << m << "x" << n << "; both sizes must be positive";
    Fail(path, msg.str());
  }
  if (nz < -2) {
    Fail(path, group + "/nz is " + std::to_string(nz) +
                   "; expected -1 (compressed columns), -2 (compressed rows) or >= 0 (triplet)");
  }
  if (nzmax < 0) Fail(path, group + "/nzmax is negative");
  if (nz > nzmax) {
    Fail(path, group + "/nz = " + std::to_string(nz) + " exceeds nzmax = " + std::to_string(nzmax));
  }
  const long mn = static_cast<long>(m) * n;
  if (nzmax > mn) {
    msg << group << " declares nzmax = " << nzmax << " for a " << m << "x" << n << " matrix (at most " << mn
        << " entries)";
    Fail(path, msg.str());
  }
  const long p_expected = nz >= 0 ? nz : (nz == -1 ? static_cast<long>(n) + 1 : static_cast<long>(m) + 1);
  const long i_expected = nz >= 0 ? nz : nzmax;
  RequireIntegers(file, path, group + "/p", p_expected, p_expected);
  RequireIntegers(file, path, group + "/i", i_expected, i_expected);
  const long used = nz >= 0 ? nz : nzmax;
  if (used == 0) Fail(path, group + " stores no entries");
  layout.x_points = RequireNumbers(file, path, group + "/x", used, nzmax).points;
  if (ListedInGroup(file, path, group, "conditioning")) {
    RequireNumbers(file, path, group + "/conditioning", 1);
    RequireNumbers(file, path, group + "/determinant", 1);
    RequireIntegers(file, path, group + "/rank", 1, 1);
    if (ListedInGroup(file, path, group, "comment")) RequireOptionalString(file, path, group, "comment");
  }
  return layout;
}

// Checks everything fclib_read_local / fclib_read_solution will read, with the sizes their
// buffers get (libfclib sizes each buffer from m, n, nz, nzmax and reads whole datasets).
LocalLayout CheckLocalLayout(hid_t file, const std::string& path) {
  if (!Exists(file, path, "/fclib_local")) {
    if (Exists(file, path, "/fclib_global")) {
      Fail(path, "holds a global problem (/fclib_global: M, H, f, w, mu), not a local one "
                 "(/fclib_local: W, q, mu); read it with ReadFclibGlobalProblem");
    }
    Fail(path, "is an HDF5 file but not an FCLIB local problem (no /fclib_local group)");
  }
  RequireGroup(file, path, "/fclib_local");
  const int spacedim = ReadInt(file, path, "/fclib_local/spacedim");
  if (spacedim != 3) {
    Fail(path, "spacedim is " + std::to_string(spacedim) +
                   "; HapCo solves 3D contact problems (spacedim 3) only");
  }
  if (Exists(file, path, "/fclib_local/V") || Exists(file, path, "/fclib_local/R")) {
    Fail(path, "has V and R (a mixed problem with equality constraints); only plain local "
               "problems (W, q, mu) are supported");
  }
  // W's shape is checked before any of its arrays is read (a corrupt file can declare anything).
  const MatrixLayout w = CheckMatrixGroup(file, path, "/fclib_local/W", [&](int m, int n) {
    std::ostringstream msg;
    if (m != n) {
      msg << "W is " << m << "x" << n << "; it must be square (3m x 3m for m contacts)";
      Fail(path, msg.str());
    }
    if (m <= 0) Fail(path, "W has " + std::to_string(m) + " rows: the problem has no contacts");
    if (m % 3 != 0) Fail(path, "W has " + std::to_string(m) + " rows, not a multiple of 3 (spacedim 3)");
    if (m / 3 > kMaxContacts) {
      msg << "has " << m / 3 << " contacts; at most " << kMaxContacts << " are supported (W is stored dense)";
      Fail(path, msg.str());
    }
  });
  LocalLayout layout;
  layout.m = w.m;
  layout.n = w.n;
  layout.nz = w.nz;
  layout.nzmax = w.nzmax;
  layout.x_points = w.x_points;
  const int m = layout.m;
  RequireGroup(file, path, "/fclib_local/vectors");
  RequireNumbers(file, path, "/fclib_local/vectors/q", m);
  RequireNumbers(file, path, "/fclib_local/vectors/mu", m / 3);
  if (Exists(file, path, "/fclib_local/info")) {
    RequireGroup(file, path, "/fclib_local/info");
    layout.title_size = RequireOptionalString(file, path, "/fclib_local/info", "title");
    layout.description_size =
        RequireOptionalString(file, path, "/fclib_local/info", "description");
    layout.math_info_size = RequireOptionalString(file, path, "/fclib_local/info", "math_info");
  }
  return layout;
}

void CheckIsHdf5File(const std::string& path) {
  std::error_code error;
  if (!std::filesystem::exists(path, error)) Fail(path, "does not exist");
  if (!std::filesystem::is_regular_file(path, error)) Fail(path, "is not a regular file");
  if (H5Fis_hdf5(path.c_str()) <= 0) Fail(path, "is not an HDF5 file");
}

LocalLayout CheckFileInProcess(const std::string& path, bool* has_solution, bool* has_global) {
  SilenceHdf5();
  CheckIsHdf5File(path);
  H5Id file(H5Fopen(path.c_str(), H5F_ACC_RDONLY, H5P_DEFAULT), H5Fclose);
  if (!file.valid()) Fail(path, "cannot be opened by HDF5 (corrupt or locked?)");
  LocalLayout layout;
  try {
    layout = CheckLocalLayout(file.get(), path);
  } catch (const std::bad_alloc&) {
    Fail(path, "declares datasets too large to read (corrupt file?)");
  }
  if (has_solution != nullptr) *has_solution = Exists(file.get(), path, "/solution");
  if (has_global != nullptr) *has_global = Exists(file.get(), path, "/fclib_global");
  return layout;
}

std::string CopyString(const char* text, std::size_t size) {
  if (text == nullptr) return {};
  return std::string(text, strnlen(text, size));  // fixed-length strings may lack the NUL
}

[[noreturn]] void RethrowWithPath(const std::string& path, const InputError& error) {
  throw InputError("FCLIB file '" + path + "': " + error.what());
}

Eigen::VectorXd CopyChecked(const double* values, int size, const std::string& path,
                            const std::string& name) {
  Eigen::VectorXd out(size);
  for (int k = 0; k < size; ++k) {
    if (!std::isfinite(values[k])) {
      Fail(path, name + "[" + std::to_string(k) + "] is " + std::to_string(values[k]) +
                     "; every value must be finite");
    }
    out(k) = values[k];
  }
  return out;
}

// W as compressed columns of its non-zero entries, with fclib_local/fclib_matrix views on
// the owned arrays (libfclib's write and merit functions take non-const pointers).
class LocalView {
 public:
  explicit LocalView(const contact::ContactProblem& problem, const FclibInfo* info = nullptr)
      : q_(problem.free_displacement_m.data(),
           problem.free_displacement_m.data() + problem.free_displacement_m.size()),
        mu_(problem.friction_coefficient.data(),
            problem.friction_coefficient.data() + problem.friction_coefficient.size()) {
    const auto& w = problem.flexibility_m_per_n;
    const int n = static_cast<int>(w.cols());
    p_.push_back(0);
    for (int j = 0; j < n; ++j) {
      for (int i = 0; i < n; ++i) {
        if (w(i, j) != 0.0) {
          i_.push_back(i);
          x_.push_back(w(i, j));
        }
      }
      p_.push_back(static_cast<int>(i_.size()));
    }
    matrix_ = fclib_matrix{};
    matrix_.nzmax = static_cast<int>(x_.size());
    matrix_.m = n;
    matrix_.n = n;
    matrix_.p = p_.data();
    matrix_.i = i_.data();
    matrix_.x = x_.data();
    matrix_.nz = -1;
    matrix_.info = nullptr;
    local_ = fclib_local{};
    local_.W = &matrix_;
    local_.V = nullptr;
    local_.R = nullptr;
    local_.mu = mu_.data();
    local_.q = q_.data();
    local_.s = nullptr;
    local_.spacedim = 3;
    local_.info = nullptr;
    if (info != nullptr &&
        !(info->title.empty() && info->description.empty() && info->math_info.empty())) {
      title_ = info->title;
      description_ = info->description;
      math_info_ = info->math_info;
      info_.title = title_.empty() ? nullptr : title_.data();
      info_.description = description_.empty() ? nullptr : description_.data();
      info_.math_info = math_info_.empty() ? nullptr : math_info_.data();
      local_.info = &info_;
    }
  }
  LocalView(const LocalView&) = delete;
  LocalView& operator=(const LocalView&) = delete;
  fclib_local* get() { return &local_; }

 private:
  std::vector<double> q_, mu_, x_;
  std::vector<int> p_, i_;
  std::string title_, description_, math_info_;
  fclib_matrix matrix_{};
  fclib_info info_{};
  fclib_local local_{};
};

// --- Global problems: the same checks, for /fclib_global ---

struct GlobalLayout {
  MatrixLayout m, h;
  std::size_t title_size = 0, description_size = 0, math_info_size = 0;
  int dofs() const { return m.n; }
  int local_size() const { return h.n; }
};

GlobalLayout CheckGlobalLayout(hid_t file, const std::string& path) {
  if (!Exists(file, path, "/fclib_global")) {
    if (Exists(file, path, "/fclib_local")) {
      Fail(path, "holds a local problem (/fclib_local: W, q, mu), not a global one; read it with "
                 "ReadFclibLocalProblem");
    }
    Fail(path, "is an HDF5 file but not an FCLIB global problem (no /fclib_global group)");
  }
  RequireGroup(file, path, "/fclib_global");
  const int spacedim = ReadInt(file, path, "/fclib_global/spacedim");
  if (spacedim != 3) {
    Fail(path, "spacedim is " + std::to_string(spacedim) + "; HapCo solves 3D contact problems (spacedim 3) only");
  }
  if (Exists(file, path, "/fclib_global/G") || Exists(file, path, "/fclib_global/vectors/b")) {
    Fail(path, "has equality constraints (/fclib_global/G and b: G^T v + b = 0 with multipliers lambda); "
               "HapCo solves global problems without them (M v = H r + f, u = H^T v + w)");
  }
  GlobalLayout layout;
  layout.m = CheckMatrixGroup(file, path, "/fclib_global/M", [&](int m, int n) {
    if (m != n) Fail(path, "M is " + std::to_string(m) + "x" + std::to_string(n) + "; it must be square");
  });
  layout.h = CheckMatrixGroup(file, path, "/fclib_global/H", [&](int m, int n) {
    std::ostringstream msg;
    if (m != layout.m.n) {
      msg << "H has " << m << " rows but M has " << layout.m.n << " (H is dofs x 3 contacts)";
      Fail(path, msg.str());
    }
    if (n % 3 != 0) Fail(path, "H has " + std::to_string(n) + " columns, not a multiple of 3 (spacedim 3)");
    if (n / 3 > kMaxContacts) {
      msg << "has " << n / 3 << " contacts; at most " << kMaxContacts
          << " are supported (the Delassus operator W is formed dense)";
      Fail(path, msg.str());
    }
  });
  RequireGroup(file, path, "/fclib_global/vectors");
  RequireNumbers(file, path, "/fclib_global/vectors/f", layout.m.m);
  RequireNumbers(file, path, "/fclib_global/vectors/w", layout.h.n);
  RequireNumbers(file, path, "/fclib_global/vectors/mu", layout.h.n / 3);
  if (Exists(file, path, "/fclib_global/info")) {
    RequireGroup(file, path, "/fclib_global/info");
    layout.title_size = RequireOptionalString(file, path, "/fclib_global/info", "title");
    layout.description_size = RequireOptionalString(file, path, "/fclib_global/info", "description");
    layout.math_info_size = RequireOptionalString(file, path, "/fclib_global/info", "math_info");
  }
  return layout;
}

GlobalLayout CheckGlobalFileInProcess(const std::string& path, bool* has_solution) {
  SilenceHdf5();
  CheckIsHdf5File(path);
  H5Id file(H5Fopen(path.c_str(), H5F_ACC_RDONLY, H5P_DEFAULT), H5Fclose);
  if (!file.valid()) Fail(path, "cannot be opened by HDF5 (corrupt or locked?)");
  GlobalLayout layout;
  try {
    layout = CheckGlobalLayout(file.get(), path);
  } catch (const std::bad_alloc&) {
    Fail(path, "declares datasets too large to read (corrupt file?)");
  }
  if (has_solution != nullptr) *has_solution = Exists(file.get(), path, "/solution");
  return layout;
}

// The datasets fclib_read_solution reads: v (n_v entries, 0 = none), r and u (n_r each).
void CheckSolutionInProcess(const std::string& path, int n_r, int n_v) {
  SilenceHdf5();
  H5Id file(H5Fopen(path.c_str(), H5F_ACC_RDONLY, H5P_DEFAULT), H5Fclose);
  RequireGroup(file.get(), path, "/solution");
  if (n_v > 0) RequireNumbers(file.get(), path, "/solution/v", n_v);
  RequireNumbers(file.get(), path, "/solution/r", n_r);
  RequireNumbers(file.get(), path, "/solution/u", n_r);
}

FclibKind KindInProcess(const std::string& path) {
  SilenceHdf5();
  CheckIsHdf5File(path);
  H5Id file(H5Fopen(path.c_str(), H5F_ACC_RDONLY, H5P_DEFAULT), H5Fclose);
  if (!file.valid()) Fail(path, "cannot be opened by HDF5 (corrupt or locked?)");
  if (Exists(file.get(), path, "/fclib_local")) return FclibKind::kLocal;
  if (Exists(file.get(), path, "/fclib_global")) return FclibKind::kGlobal;
  Fail(path, "is an HDF5 file but not an FCLIB problem (neither /fclib_local nor /fclib_global)");
}

struct GlobalDeleter {
  void operator()(fclib_global* problem) const {
    fclib_delete_global(problem);  // frees the members, not the struct
    std::free(problem);            // NOLINT: allocated by libfclib with calloc
  }
};
using GlobalPtr = std::unique_ptr<fclib_global, GlobalDeleter>;

MatrixStorage StorageOf(const fclib_matrix& matrix) {
  return matrix.nz >= 0 ? MatrixStorage::kTriplet
         : matrix.nz == -1 ? MatrixStorage::kCompressedColumns
                           : MatrixStorage::kCompressedRows;
}

int StoredEntries(const fclib_matrix& matrix) {
  return matrix.nz >= 0 ? matrix.nz : matrix.p[matrix.nz == -1 ? matrix.n : matrix.m];
}

// Compressed columns of a sparse matrix, as int arrays for an fclib_matrix view.
struct CompressedColumns {
  std::vector<int> p, i;
  std::vector<double> x;
  fclib_matrix view{};
  explicit CompressedColumns(const Eigen::SparseMatrix<double>& a) {
    p.push_back(0);
    for (int j = 0; j < a.outerSize(); ++j) {
      for (Eigen::SparseMatrix<double>::InnerIterator it(a, j); it; ++it) {
        i.push_back(static_cast<int>(it.row()));
        x.push_back(it.value());
      }
      p.push_back(static_cast<int>(i.size()));
    }
    view.nzmax = static_cast<int>(x.size());
    view.m = static_cast<int>(a.rows());
    view.n = static_cast<int>(a.cols());
    view.p = p.data();
    view.i = i.data();
    view.x = x.data();
    view.nz = -1;
    view.info = nullptr;
  }
};

// contact::ValidateProblem, except that W may be asymmetric within kMaxRelativeAsymmetry (a
// problem as a file stored it): then its symmetric part is validated.
void ValidateStoredProblem(const contact::ContactProblem& problem) {
  const Eigen::MatrixXd& w = problem.flexibility_m_per_n;
  const bool square = w.rows() == w.cols() && w.size() > 0;
  const double asymmetry = square && w.allFinite() ? RelativeAsymmetry(w) : 0.0;
  if (asymmetry > 0.0 && asymmetry <= kMaxRelativeAsymmetry) {
    contact::ContactProblem symmetric = problem;
    symmetric.flexibility_m_per_n = 0.5 * (w + w.transpose());
    contact::ValidateProblem(symmetric);
  } else {
    contact::ValidateProblem(problem);
  }
}

void ValidateForWrite(const std::string& path, const contact::ContactProblem& problem) {
  try {
    ValidateStoredProblem(problem);
  } catch (const InputError& error) {
    Fail(path, std::string("cannot write: ") + error.what());
  }
  if (problem.num_contacts() == 0) Fail(path, "cannot write a problem with no contacts");
  if (problem.num_contacts() > kMaxContacts) {
    Fail(path, "cannot write more than " + std::to_string(kMaxContacts) + " contacts");
  }
}

}  // namespace

const char* StorageName(MatrixStorage storage) {
  switch (storage) {
    case MatrixStorage::kCompressedColumns:
      return "compressed columns";
    case MatrixStorage::kCompressedRows:
      return "compressed rows";
    case MatrixStorage::kTriplet:
      return "triplet";
  }
  return "?";
}

namespace detail {

namespace {

// Calls add(row, column, value) for every stored entry of `matrix` (duplicates included),
// after checking pointers, index ranges and values (ToDense's contract, fclib_matrix.h).
template <typename Add>
void VisitEntries(const fclib_matrix& matrix, TripletRows triplet_rows, long available_values,
                  const std::string& where, const Add& add_entry) {
  const int rows = matrix.m, cols = matrix.n;
  if (rows < 0 || cols < 0) throw InputError(where + ": negative size");
  auto add = [&](long k, long r, long c) {
    std::ostringstream msg;
    if (r < 0 || r >= rows || c < 0 || c >= cols) {
      msg << where << ": entry " << k << " has (row, column) = (" << r << ", " << c
          << ") outside the " << rows << "x" << cols << " matrix";
      throw InputError(msg.str());
    }
    if (!std::isfinite(matrix.x[k])) {
      msg << where << ": entry " << k << " at (" << r << ", " << c << ") is " << matrix.x[k]
          << "; every value must be finite";
      throw InputError(msg.str());
    }
    add_entry(static_cast<int>(r), static_cast<int>(c), matrix.x[k]);
  };
  if (matrix.nz >= 0) {  // triplet
    if (matrix.nz > available_values) {
      throw InputError(where + ": triplet nz exceeds the stored values");
    }
    const int* row_index = triplet_rows == TripletRows::kInI ? matrix.i : matrix.p;
    const int* col_index = triplet_rows == TripletRows::kInI ? matrix.p : matrix.i;
    for (long k = 0; k < matrix.nz; ++k) add(k, row_index[k], col_index[k]);
    return;
  }
  if (matrix.nz != -1 && matrix.nz != -2) {
    throw InputError(where + ": unknown storage nz = " + std::to_string(matrix.nz));
  }
  const bool by_columns = matrix.nz == -1;
  const int outer = by_columns ? cols : rows;
  if (matrix.p[0] != 0) throw InputError(where + ": compressed pointers must start at 0");
  for (int j = 0; j < outer; ++j) {
    if (matrix.p[j + 1] < matrix.p[j]) {
      throw InputError(where + ": compressed pointers decrease at " + std::to_string(j + 1));
    }
  }
  if (matrix.p[outer] > available_values) {
    std::ostringstream msg;
    msg << where << ": compressed pointers address " << matrix.p[outer] << " entries but only "
        << available_values << " are stored";
    throw InputError(msg.str());
  }
  for (int j = 0; j < outer; ++j) {
    for (long k = matrix.p[j]; k < matrix.p[j + 1]; ++k) {
      if (by_columns) {
        add(k, matrix.i[k], j);
      } else {
        add(k, j, matrix.i[k]);
      }
    }
  }
}

}  // namespace

Eigen::MatrixXd ToDense(const fclib_matrix& matrix, TripletRows triplet_rows, long available_values,
                        const std::string& where) {
  Eigen::MatrixXd dense = Eigen::MatrixXd::Zero(std::max(matrix.m, 0), std::max(matrix.n, 0));
  VisitEntries(matrix, triplet_rows, available_values, where,
               [&](int r, int c, double x) { dense(r, c) += x; });
  return dense;
}

Eigen::SparseMatrix<double> ToSparse(const fclib_matrix& matrix, TripletRows triplet_rows,
                                     long available_values, const std::string& where) {
  std::vector<Eigen::Triplet<double>> entries;
  VisitEntries(matrix, triplet_rows, available_values, where,
               [&](int r, int c, double x) { entries.emplace_back(r, c, x); });
  Eigen::SparseMatrix<double> sparse(matrix.m, matrix.n);
  sparse.setFromTriplets(entries.begin(), entries.end());  // duplicates summed (CSparse)
  return sparse;
}

}  // namespace detail

namespace {
// The readers' bodies: they run in the worker process (ReaderWorker below).
contact::ContactProblem ReadLocalProblemInProcess(const std::string& path, FclibFileDetails* details) {
  const LocalLayout layout = CheckFileInProcess(path, nullptr, nullptr);
  MarkChecked();
  LocalPtr local(fclib_read_local(path.c_str()));
  if (!local) Fail(path, "libfclib could not read the local problem");
  HAPCO_ASSERT(local->W != nullptr && local->W->m == layout.m && local->W->n == layout.n &&
                   local->W->nz == layout.nz && local->spacedim == 3,
               "libfclib read a different layout than the one checked");
  const fclib_matrix& w = *local->W;
  const int n = layout.n;

  contact::ContactProblem problem;
  // Triplets: rows from `i` (CSparse, as Siconos writes). The documented convention gives
  // the transpose, identical for the symmetric W checked below.
  try {
    problem.flexibility_m_per_n =
        detail::ToDense(w, detail::TripletRows::kInI, layout.x_points, "W");
  } catch (const InputError& error) {
    RethrowWithPath(path, error);
  }
  problem.free_displacement_m = CopyChecked(local->q, n, path, "/fclib_local/vectors/q");
  problem.friction_coefficient = CopyChecked(local->mu, n / 3, path, "/fclib_local/vectors/mu");

  // Asymmetry gets its own message: it is the symptom a triplet-convention mix-up would be
  // suspected of, and it is not one (see fclib_io.h). Round-off asymmetry is accepted.
  const Eigen::MatrixXd& dense = problem.flexibility_m_per_n;
  const double asymmetry = RelativeAsymmetry(dense);
  if (asymmetry > kMaxRelativeAsymmetry) {
    Eigen::Index worst_i = 0, worst_j = 0;
    (dense - dense.transpose()).cwiseAbs().maxCoeff(&worst_i, &worst_j);
    if (worst_i < worst_j) std::swap(worst_i, worst_j);
    std::ostringstream msg;
    msg << "W is not symmetric: W(" << worst_i << "," << worst_j << ") = " << dense(worst_i, worst_j)
        << " but W(" << worst_j << "," << worst_i << ") = " << dense(worst_j, worst_i)
        << " (stored as "
        << StorageName(w.nz >= 0   ? MatrixStorage::kTriplet
                       : w.nz == -1 ? MatrixStorage::kCompressedColumns
                                    : MatrixStorage::kCompressedRows)
        << "; max|W - W^T| / max|W| = " << asymmetry << ", round-off is accepted up to "
        << kMaxRelativeAsymmetry
        << "). FCLIB stores the full symmetric W; a file holding one triangle only is not "
           "supported";
    if (w.nz >= 0) {
      msg << " (reading the triplet's p/i the other way round only transposes W, so the "
             "index convention is not the cause)";
    }
    Fail(path, msg.str());
  }
  contact::ContactProblem stored;
  if (asymmetry > 0.0) {
    stored = problem;
    problem.flexibility_m_per_n = 0.5 * (stored.flexibility_m_per_n + stored.flexibility_m_per_n.transpose());
  }
  try {
    contact::ValidateProblem(problem);
  } catch (const InputError& error) {
    RethrowWithPath(path, error);
  }
  if (details != nullptr) {
    details->w_storage = w.nz >= 0    ? MatrixStorage::kTriplet
                         : w.nz == -1 ? MatrixStorage::kCompressedColumns
                                      : MatrixStorage::kCompressedRows;
    details->w_stored_entries = w.nz >= 0 ? w.nz : w.p[w.nz == -1 ? w.n : w.m];
    details->w_relative_asymmetry = asymmetry;
    details->stored_problem = std::move(stored);
    details->info = FclibInfo{};
    if (local->info != nullptr) {
      details->info.title = CopyString(local->info->title, layout.title_size);
      details->info.description =
          CopyString(local->info->description, layout.description_size);
      details->info.math_info = CopyString(local->info->math_info, layout.math_info_size);
    }
  }
  return problem;
}
}  // namespace

void WriteFclibLocalProblem(const std::string& path, const contact::ContactProblem& problem,
                            const FclibInfo& info) {
  SilenceHdf5();
  ValidateForWrite(path, problem);
  // Create (or truncate) the file ourselves: fclib_write_local appends to an existing file
  // and refuses one that already holds a local problem.
  {
    H5Id file(H5Fcreate(path.c_str(), H5F_ACC_TRUNC, H5P_DEFAULT, H5P_DEFAULT), H5Fclose);
    if (!file.valid()) {
      Fail(path, "cannot be created (does the directory exist and is it writable?)");
    }
  }
  LocalView view(problem, &info);
  if (fclib_write_local(view.get(), path.c_str()) != 1) {
    Fail(path, "libfclib failed to write the local problem");
  }
}

namespace {
void WriteLocalSolutionInProcess(const std::string& path, const Eigen::VectorXd& force_n,
                                 const Eigen::VectorXd& displacement_m) {
  bool has_solution = false, has_global = false;
  const LocalLayout layout = CheckFileInProcess(path, &has_solution, &has_global);
  MarkChecked();
  if (has_global) {
    Fail(path, "also holds a global problem; libfclib would size the solution from it");
  }
  if (force_n.size() != layout.n || displacement_m.size() != layout.n) {
    std::ostringstream msg;
    msg << "cannot write a solution with r of size " << force_n.size() << " and u of size "
        << displacement_m.size() << " for a problem with 3m = " << layout.n;
    Fail(path, msg.str());
  }
  if (!force_n.allFinite() || !displacement_m.allFinite()) {
    Fail(path, "cannot write a solution with non-finite values");
  }
  if (has_solution) {
    H5Id file(H5Fopen(path.c_str(), H5F_ACC_RDWR, H5P_DEFAULT), H5Fclose);
    if (!file.valid() || H5Ldelete(file.get(), "/solution", H5P_DEFAULT) < 0) {
      Fail(path, "cannot replace the existing /solution (is the file writable?)");
    }
  }
  std::vector<double> r(force_n.data(), force_n.data() + force_n.size());
  std::vector<double> u(displacement_m.data(), displacement_m.data() + displacement_m.size());
  fclib_solution solution{};
  solution.v = nullptr;
  solution.u = u.data();
  solution.r = r.data();
  solution.l = nullptr;
  if (fclib_write_solution(&solution, path.c_str()) != 1) {
    Fail(path, "libfclib failed to write the solution (is the file writable?)");
  }
}
}  // namespace

namespace {
std::optional<FclibSolution> ReadLocalSolutionInProcess(const std::string& path) {
  bool has_solution = false, has_global = false;
  const LocalLayout layout = CheckFileInProcess(path, &has_solution, &has_global);
  if (!has_solution) return std::nullopt;
  if (has_global) {
    Fail(path, "also holds a global problem; its solution would be sized from it");
  }
  CheckSolutionInProcess(path, layout.n, 0);
  MarkChecked();
  SolutionPtr solution(fclib_read_solution(path.c_str()));
  if (!solution) Fail(path, "libfclib could not read the solution");
  FclibSolution out;
  out.force_n = CopyChecked(solution->r, layout.n, path, "/solution/r");
  out.displacement_m = CopyChecked(solution->u, layout.n, path, "/solution/u");
  return out;
}
}  // namespace

double FclibMeritLocal(const contact::ContactProblem& problem, const Eigen::VectorXd& force_n) {
  ValidateStoredProblem(problem);
  if (force_n.size() != problem.free_displacement_m.size()) {
    throw InputError("FclibMeritLocal: r has size " + std::to_string(force_n.size()) +
                     ", the problem needs 3m = " +
                     std::to_string(problem.free_displacement_m.size()));
  }
  LocalView view(problem);
  std::vector<double> r(force_n.data(), force_n.data() + force_n.size());
  const Eigen::VectorXd u_eigen = problem.flexibility_m_per_n * force_n +
                                  problem.free_displacement_m;
  std::vector<double> u(u_eigen.data(), u_eigen.data() + u_eigen.size());
  fclib_solution solution{};
  solution.v = nullptr;
  solution.u = u.data();
  solution.r = r.data();
  solution.l = nullptr;
  return fclib_merit_local(view.get(), MERIT_1, &solution);
}

double RelativeAsymmetry(const Eigen::MatrixXd& w) {
  HAPCO_ASSERT(w.rows() == w.cols(), "RelativeAsymmetry needs a square matrix");
  const double scale = w.cwiseAbs().maxCoeff();
  if (!(scale > 0.0)) return 0.0;
  return (w - w.transpose()).cwiseAbs().maxCoeff() / scale;
}

namespace {
contact::GlobalContactProblem ReadGlobalProblemInProcess(const std::string& path, FclibGlobalDetails* details) {
  const GlobalLayout layout = CheckGlobalFileInProcess(path, nullptr);
  MarkChecked();
  GlobalPtr global(fclib_read_global(path.c_str()));
  if (!global) Fail(path, "libfclib could not read the global problem");
  HAPCO_ASSERT(global->M != nullptr && global->H != nullptr && global->G == nullptr &&
                   global->M->n == layout.m.n && global->H->n == layout.h.n && global->H->nz == layout.h.nz &&
                   global->spacedim == 3,
               "libfclib read a different layout than the one checked");
  contact::GlobalContactProblem problem;
  TripletReading h_reading = TripletReading::kNotTriplet;
  Eigen::SparseMatrix<double> h_other_reading;
  try {
    // M is symmetric: the two triplet readings give the same matrix (see fclib_io.h).
    problem.m = detail::ToSparse(*global->M, detail::TripletRows::kInI, layout.m.x_points, "M");
    if (global->H->nz < 0) {
      problem.h = detail::ToSparse(*global->H, detail::TripletRows::kInI, layout.h.x_points, "H");
    } else {
      // H is n x 3n_c: read rows from `i` (CSparse, Siconos); if those indices do not fit but
      // the documented reading (rows in `p`) does, the file follows fclib.h.
      try {
        problem.h = detail::ToSparse(*global->H, detail::TripletRows::kInI, layout.h.x_points, "H");
        h_reading = TripletReading::kRowsInI;
        try {
          Eigen::SparseMatrix<double> documented =
              detail::ToSparse(*global->H, detail::TripletRows::kInP, layout.h.x_points, "H");
          if ((documented - problem.h).norm() > 0.0) h_other_reading = std::move(documented);
        } catch (const InputError&) {
          // The documented reading does not fit: the file is unambiguous.
        }
      } catch (const InputError& csparse_error) {
        try {
          problem.h = detail::ToSparse(*global->H, detail::TripletRows::kInP, layout.h.x_points, "H");
          h_reading = TripletReading::kRowsInP;
        } catch (const InputError&) {
          throw csparse_error;
        }
      }
    }
  } catch (const InputError& error) {
    RethrowWithPath(path, error);
  }
  problem.f = CopyChecked(global->f, layout.m.m, path, "/fclib_global/vectors/f");
  problem.w = CopyChecked(global->w, layout.h.n, path, "/fclib_global/vectors/w");
  problem.mu = CopyChecked(global->mu, layout.h.n / 3, path, "/fclib_global/vectors/mu");
  try {
    contact::ValidateGlobalProblem(problem);
  } catch (const InputError& error) {
    RethrowWithPath(path, error);
  }
  if (details != nullptr) {
    details->m_storage = StorageOf(*global->M);
    details->h_storage = StorageOf(*global->H);
    details->h_triplet_reading = h_reading;
    details->h_other_reading = std::move(h_other_reading);
    details->m_stored_entries = StoredEntries(*global->M);
    details->h_stored_entries = StoredEntries(*global->H);
    details->m_relative_asymmetry = contact::SparseRelativeAsymmetry(problem.m);
    details->info = FclibInfo{};
    if (global->info != nullptr) {
      details->info.title = CopyString(global->info->title, layout.title_size);
      details->info.description = CopyString(global->info->description, layout.description_size);
      details->info.math_info = CopyString(global->info->math_info, layout.math_info_size);
    }
  }
  return problem;
}
}  // namespace

void WriteFclibGlobalProblem(const std::string& path, const contact::GlobalContactProblem& problem,
                             const FclibInfo& info) {
  SilenceHdf5();
  try {
    contact::ValidateGlobalProblem(problem);
  } catch (const InputError& error) {
    Fail(path, std::string("cannot write: ") + error.what());
  }
  if (problem.num_contacts() > kMaxContacts) {
    Fail(path, "cannot write more than " + std::to_string(kMaxContacts) + " contacts");
  }
  {
    H5Id file(H5Fcreate(path.c_str(), H5F_ACC_TRUNC, H5P_DEFAULT, H5P_DEFAULT), H5Fclose);
    if (!file.valid()) Fail(path, "cannot be created (does the directory exist and is it writable?)");
  }
  CompressedColumns m(problem.m), h(problem.h);
  std::vector<double> f(problem.f.data(), problem.f.data() + problem.f.size());
  std::vector<double> w(problem.w.data(), problem.w.data() + problem.w.size());
  std::vector<double> mu(problem.mu.data(), problem.mu.data() + problem.mu.size());
  std::string title = info.title, description = info.description, math_info = info.math_info;
  fclib_info fclib_info_view{};
  fclib_info_view.title = title.empty() ? nullptr : title.data();
  fclib_info_view.description = description.empty() ? nullptr : description.data();
  fclib_info_view.math_info = math_info.empty() ? nullptr : math_info.data();
  fclib_global global{};
  global.M = &m.view;
  global.H = &h.view;
  global.G = nullptr;
  global.mu = mu.data();
  global.f = f.data();
  global.b = nullptr;
  global.w = w.data();
  global.spacedim = 3;
  global.info = (title.empty() && description.empty() && math_info.empty()) ? nullptr : &fclib_info_view;
  if (fclib_write_global(&global, path.c_str()) != 1) Fail(path, "libfclib failed to write the global problem");
}

namespace {
void WriteGlobalSolutionInProcess(const std::string& path, const FclibGlobalSolution& solution) {
  bool has_solution = false;
  const GlobalLayout layout = CheckGlobalFileInProcess(path, &has_solution);
  MarkChecked();
  if (solution.velocity.size() != layout.dofs() || solution.force.size() != layout.local_size() ||
      solution.local_velocity.size() != layout.local_size()) {
    std::ostringstream msg;
    msg << "cannot write a solution with v, r, u of sizes " << solution.velocity.size() << ", "
        << solution.force.size() << ", " << solution.local_velocity.size() << " for a problem with n = "
        << layout.dofs() << " and 3n_c = " << layout.local_size();
    Fail(path, msg.str());
  }
  if (!solution.velocity.allFinite() || !solution.force.allFinite() || !solution.local_velocity.allFinite()) {
    Fail(path, "cannot write a solution with non-finite values");
  }
  if (has_solution) {
    H5Id file(H5Fopen(path.c_str(), H5F_ACC_RDWR, H5P_DEFAULT), H5Fclose);
    if (!file.valid() || H5Ldelete(file.get(), "/solution", H5P_DEFAULT) < 0) {
      Fail(path, "cannot replace the existing /solution (is the file writable?)");
    }
  }
  std::vector<double> v(solution.velocity.data(), solution.velocity.data() + solution.velocity.size());
  std::vector<double> r(solution.force.data(), solution.force.data() + solution.force.size());
  std::vector<double> u(solution.local_velocity.data(),
                        solution.local_velocity.data() + solution.local_velocity.size());
  fclib_solution out{};
  out.v = v.data();
  out.u = u.data();
  out.r = r.data();
  out.l = nullptr;
  if (fclib_write_solution(&out, path.c_str()) != 1) {
    Fail(path, "libfclib failed to write the solution (is the file writable?)");
  }
}
}  // namespace

namespace {
std::optional<FclibGlobalSolution> ReadGlobalSolutionInProcess(const std::string& path) {
  bool has_solution = false;
  const GlobalLayout layout = CheckGlobalFileInProcess(path, &has_solution);
  if (!has_solution) return std::nullopt;
  CheckSolutionInProcess(path, layout.local_size(), layout.dofs());
  MarkChecked();
  SolutionPtr solution(fclib_read_solution(path.c_str()));
  if (!solution) Fail(path, "libfclib could not read the solution");
  FclibGlobalSolution out;
  out.velocity = CopyChecked(solution->v, layout.dofs(), path, "/solution/v");
  out.force = CopyChecked(solution->r, layout.local_size(), path, "/solution/r");
  out.local_velocity = CopyChecked(solution->u, layout.local_size(), path, "/solution/u");
  return out;
}

// --- The worker process that does every read of an existing file ---
//
// HDF5 1.10.8 crashes (finding 5: SIGSEGV under H5Lexists), copies -1 bytes (finding 9), loops
// (finding 13) or builds gigabytes from a few bytes (finding 14) on some corrupt files, and no
// check of ours can run before HDF5 parses its own metadata (docs/fuzzing.md). So every access
// to an existing file (the layout checks, libfclib's read, a solution written into the file)
// runs in a worker process, a fork of this one, and only the parsed result comes back over a
// socket: this process's HDF5 never opens a file it did not create. Whatever a corrupt file
// does to HDF5's state in the worker (its free lists: finding 15) then cannot reach the reader,
// so one worker serves many files (kRequestsPerWorker), and a batch of reads or a fuzzer pays
// one fork, not one per file (a fork of the ASan fuzzer costs ~10 ms).
//
// How the worker ends tells what happened: killed by a signal = a library crashed on the file
// (refused, InputError); a HapCo assertion, or in a sanitizer build a report whose stack does
// not pass through HDF5, ends it with kWorkerBugExitCode = a bug (HAPCO_ASSERT here; the
// worker printed the details). The reader waits at most kChecksTimeoutMs for the checks and
// stops the worker when they need more than kChecksMemoryBytes + 16 x the file over what it
// held before; once the checks passed (MarkChecked) only a generous time limit remains.
// Not for multi-threaded use (neither is the serial HDF5 library).

enum class Request : std::uint8_t {
  kKind = 1,
  kLocalProblem,
  kLocalSolution,
  kGlobalProblem,
  kGlobalSolution,
  kWriteLocalSolution,
  kWriteGlobalSolution,
};
enum class Answer : std::uint8_t { kResult = 'R', kInputError = 'E', kOutOfMemory = 'M' };

constexpr int kWorkerBugExitCode = 86;
// A worker serves this many requests, then the next one forks afresh (HDF5 leaks a little on
// corrupt files, finding 7) ...
constexpr int kRequestsPerWorker = 2000;
// ... or earlier once it holds this much more memory than when it was forked, bytes.
constexpr long long kWorkerGrowthBytes = 256LL << 20;
// A file whose checks take longer is refused (HDF5 may loop on corrupt metadata). Generous: the
// checks read every array once.
constexpr int kChecksTimeoutMs = 20'000;
// After the checks: libfclib's read and our conversion of a checked layout (up to a dense W of
// kMaxContacts, 1.2 GB) and the transfer.
constexpr int kReadTimeoutMs = 600'000;
// The checks read every array once, so a valid file needs about its own size in memory; HDF5's
// caches and our copies stay far below 64 MiB + 16 x the file (bytes over the worker's
// resident set before the request).
constexpr long long kChecksMemoryBytes = 64LL << 20;
constexpr long long kChecksMemoryPerFileByte = 16;
constexpr int kMemoryCheckMs = 10;

WorkerCoverageHooks coverage_hooks;

// Thrown by WireReader when the worker ends or misses the deadline mid-answer.
struct WorkerLost {};

// Writes to the socket: small values buffered, arrays straight from their storage.
class WireWriter {
 public:
  explicit WireWriter(int socket) : socket_(socket) {}
  template <class T>
  void Value(const T& value) {
    static_assert(std::is_trivially_copyable_v<T>);
    Bytes(&value, sizeof(T));
  }
  void Bytes(const void* data, std::size_t size) {
    if (size >= kDirectBytes) {
      Flush();
      Send(data, size);
      return;
    }
    buffer_.append(static_cast<const char*>(data), size);
    if (buffer_.size() >= kDirectBytes) Flush();
  }
  // False when the other end is gone.
  bool Flush() {
    Send(buffer_.data(), buffer_.size());
    buffer_.clear();
    return ok_;
  }
  bool ok() const { return ok_; }

 private:
  static constexpr std::size_t kDirectBytes = 1 << 16;
  void Send(const void* data, std::size_t size) {
    const auto* bytes = static_cast<const char*>(data);
    while (ok_ && size > 0) {
      const ssize_t sent = send(socket_, bytes, size, MSG_NOSIGNAL);  // no SIGPIPE if it died
      if (sent < 0 && errno == EINTR) continue;
      if (sent <= 0) ok_ = false;
      if (sent > 0) {
        bytes += sent;
        size -= static_cast<std::size_t>(sent);
      }
    }
  }
  int socket_;
  std::string buffer_;
  bool ok_ = true;
};

// Reads from the socket until a deadline (none: -1 ms); throws WorkerLost when the other end
// closes or the deadline passes.
class WireReader {
 public:
  WireReader(int socket, int timeout_ms)
      : socket_(socket),
        deadline_(std::chrono::steady_clock::now() + std::chrono::milliseconds(timeout_ms)),
        timed_(timeout_ms >= 0) {}
  template <class T>
  T Value() {
    static_assert(std::is_trivially_copyable_v<T>);
    T value{};
    Bytes(&value, sizeof(T));
    return value;
  }
  void Bytes(void* data, std::size_t size) {
    auto* bytes = static_cast<char*>(data);
    while (size > 0) {
      if (timed_) {
        const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(deadline_ - std::chrono::steady_clock::now());
        if (left.count() <= 0) throw WorkerLost{};
        pollfd ready{socket_, POLLIN, 0};
        const int n = poll(&ready, 1, static_cast<int>(left.count()));
        if (n < 0 && errno == EINTR) continue;
        if (n <= 0) throw WorkerLost{};
      }
      const ssize_t got = recv(socket_, bytes, size, 0);
      if (got < 0 && errno == EINTR) continue;
      if (got <= 0) throw WorkerLost{};
      bytes += got;
      size -= static_cast<std::size_t>(got);
    }
  }
  // A count the other side sent, checked against what any answer can hold.
  std::size_t Count(std::size_t limit) {
    const std::uint64_t count = Value<std::uint64_t>();
    HAPCO_ASSERT(count <= limit, "the FCLIB reader's worker sent an implausible size");
    return static_cast<std::size_t>(count);
  }

 private:
  int socket_;
  std::chrono::steady_clock::time_point deadline_;
  bool timed_;
};

// Sizes on the wire are bounded by the largest answer: a dense W of kMaxContacts.
constexpr std::size_t kMaxWireEntries = std::size_t{9} * kMaxContacts * kMaxContacts;

void Put(WireWriter& out, const std::string& text) {
  out.Value<std::uint64_t>(text.size());
  out.Bytes(text.data(), text.size());
}
void Get(WireReader& in, std::string* text) {
  text->resize(in.Count(kMaxWireEntries));
  in.Bytes(text->data(), text->size());
}
void Put(WireWriter& out, const Eigen::VectorXd& vector) {
  out.Value<std::uint64_t>(static_cast<std::uint64_t>(vector.size()));
  out.Bytes(vector.data(), sizeof(double) * static_cast<std::size_t>(vector.size()));
}
void Get(WireReader& in, Eigen::VectorXd* vector) {
  vector->resize(static_cast<Eigen::Index>(in.Count(kMaxWireEntries)));
  in.Bytes(vector->data(), sizeof(double) * static_cast<std::size_t>(vector->size()));
}
void Put(WireWriter& out, const Eigen::MatrixXd& matrix) {
  out.Value<std::uint64_t>(static_cast<std::uint64_t>(matrix.rows()));
  out.Value<std::uint64_t>(static_cast<std::uint64_t>(matrix.cols()));
  out.Bytes(matrix.data(), sizeof(double) * static_cast<std::size_t>(matrix.size()));
}
void Get(WireReader& in, Eigen::MatrixXd* matrix) {
  const std::size_t rows = in.Count(kMaxWireEntries), cols = in.Count(kMaxWireEntries);
  HAPCO_ASSERT(rows == 0 || cols <= kMaxWireEntries / rows, "the FCLIB reader's worker sent an implausible size");
  matrix->resize(static_cast<Eigen::Index>(rows), static_cast<Eigen::Index>(cols));
  in.Bytes(matrix->data(), sizeof(double) * rows * cols);
}
void Put(WireWriter& out, const Eigen::SparseMatrix<double>& matrix) {
  Eigen::SparseMatrix<double> compressed = matrix;
  compressed.makeCompressed();
  const auto cols = static_cast<std::size_t>(compressed.cols());
  const auto entries = static_cast<std::size_t>(compressed.nonZeros());
  out.Value<std::uint64_t>(static_cast<std::uint64_t>(compressed.rows()));
  out.Value<std::uint64_t>(cols);
  out.Value<std::uint64_t>(entries);
  out.Bytes(compressed.outerIndexPtr(), sizeof(int) * (cols + 1));
  out.Bytes(compressed.innerIndexPtr(), sizeof(int) * entries);
  out.Bytes(compressed.valuePtr(), sizeof(double) * entries);
}
void Get(WireReader& in, Eigen::SparseMatrix<double>* matrix) {
  const std::size_t rows = in.Count(kMaxWireEntries), cols = in.Count(kMaxWireEntries);
  const std::size_t entries = in.Count(kMaxWireEntries);
  std::vector<int> outer(cols + 1), inner(entries);
  std::vector<double> values(entries);
  in.Bytes(outer.data(), sizeof(int) * outer.size());
  in.Bytes(inner.data(), sizeof(int) * inner.size());
  in.Bytes(values.data(), sizeof(double) * values.size());
  HAPCO_ASSERT(outer.front() == 0 && static_cast<std::size_t>(outer.back()) == entries,
               "the FCLIB reader's worker sent an inconsistent sparse matrix");
  *matrix = Eigen::Map<const Eigen::SparseMatrix<double>>(static_cast<Eigen::Index>(rows), static_cast<Eigen::Index>(cols),
                                                          static_cast<Eigen::Index>(entries), outer.data(), inner.data(),
                                                          values.data());
}
void Put(WireWriter& out, const FclibInfo& info) {
  Put(out, info.title);
  Put(out, info.description);
  Put(out, info.math_info);
}
void Get(WireReader& in, FclibInfo* info) {
  Get(in, &info->title);
  Get(in, &info->description);
  Get(in, &info->math_info);
}
void Put(WireWriter& out, const contact::ContactProblem& problem) {
  Put(out, problem.flexibility_m_per_n);
  Put(out, problem.free_displacement_m);
  Put(out, problem.friction_coefficient);
}
void Get(WireReader& in, contact::ContactProblem* problem) {
  Get(in, &problem->flexibility_m_per_n);
  Get(in, &problem->free_displacement_m);
  Get(in, &problem->friction_coefficient);
}
void Put(WireWriter& out, const FclibFileDetails& details) {
  Put(out, details.info);
  out.Value(details.w_storage);
  out.Value(details.w_stored_entries);
  out.Value(details.w_relative_asymmetry);
  Put(out, details.stored_problem);
}
void Get(WireReader& in, FclibFileDetails* details) {
  Get(in, &details->info);
  details->w_storage = in.Value<MatrixStorage>();
  details->w_stored_entries = in.Value<int>();
  details->w_relative_asymmetry = in.Value<double>();
  Get(in, &details->stored_problem);
}
void Put(WireWriter& out, const contact::GlobalContactProblem& problem) {
  Put(out, problem.m);
  Put(out, problem.h);
  Put(out, problem.f);
  Put(out, problem.w);
  Put(out, problem.mu);
}
void Get(WireReader& in, contact::GlobalContactProblem* problem) {
  Get(in, &problem->m);
  Get(in, &problem->h);
  Get(in, &problem->f);
  Get(in, &problem->w);
  Get(in, &problem->mu);
}
void Put(WireWriter& out, const FclibGlobalDetails& details) {
  Put(out, details.info);
  out.Value(details.m_storage);
  out.Value(details.h_storage);
  out.Value(details.h_triplet_reading);
  Put(out, details.h_other_reading);
  out.Value(details.m_stored_entries);
  out.Value(details.h_stored_entries);
  out.Value(details.m_relative_asymmetry);
}
void Get(WireReader& in, FclibGlobalDetails* details) {
  Get(in, &details->info);
  details->m_storage = in.Value<MatrixStorage>();
  details->h_storage = in.Value<MatrixStorage>();
  details->h_triplet_reading = in.Value<TripletReading>();
  Get(in, &details->h_other_reading);
  details->m_stored_entries = in.Value<int>();
  details->h_stored_entries = in.Value<int>();
  details->m_relative_asymmetry = in.Value<double>();
}
void Put(WireWriter& out, const FclibSolution& solution) {
  Put(out, solution.force_n);
  Put(out, solution.displacement_m);
}
void Get(WireReader& in, FclibSolution* solution) {
  Get(in, &solution->force_n);
  Get(in, &solution->displacement_m);
}
void Put(WireWriter& out, const FclibGlobalSolution& solution) {
  Put(out, solution.velocity);
  Put(out, solution.force);
  Put(out, solution.local_velocity);
}
void Get(WireReader& in, FclibGlobalSolution* solution) {
  Get(in, &solution->velocity);
  Get(in, &solution->force);
  Get(in, &solution->local_velocity);
}
template <class T>
void Put(WireWriter& out, const std::optional<T>& value) {
  out.Value<std::uint8_t>(value.has_value() ? 1 : 0);
  if (value) Put(out, *value);
}
template <class T>
void Get(WireReader& in, std::optional<T>* value) {
  value->reset();
  if (in.Value<std::uint8_t>() != 0) Get(in, &value->emplace());
}

// The sanitizer runtimes' hook (sanitizer/common_interface_defs.h), declared weak so that a
// build without sanitizers links without it.
extern "C" void __sanitizer_set_death_callback(void (*callback)(void)) __attribute__((weak));

// In a sanitizer build's worker, for a report (ASan or UBSan): true when a frame of the
// reporting stack is in HDF5 (its memory errors on corrupt heaps, finding 9) and none of the
// frames between the report and HDF5 is outside this program and the C library. A SIGSEGV never
// gets here: the worker's default action ends it first. Known gap: a report in a callback HDF5
// calls (H5Literate's, in this program) counts as HDF5's.
bool ReportIsInHdf5() {
  void* frames[128];
  const int count = backtrace(frames, 128);
  Dl_info self{};
  if (dladdr(reinterpret_cast<void*>(&ReportIsInHdf5), &self) == 0) return false;
  for (int k = 0; k < count; ++k) {
    Dl_info frame{};
    if (dladdr(frames[k], &frame) == 0 || frame.dli_fname == nullptr) continue;
    if (frame.dli_fbase == self.dli_fbase) continue;  // this program, with the sanitizer runtime
    const std::string_view module(frame.dli_fname);
    if (module.find("/libc.so") != std::string_view::npos) continue;  // memcpy, signal frames
    return module.find("libhdf5") != std::string_view::npos;
  }
  return false;
}

void OnSanitizerDeathInWorker() {
  if (ReportIsInHdf5()) {
    std::signal(SIGSEGV, SIG_DFL);
    std::raise(SIGSEGV);  // as the release build's HDF5 crash: the file is refused
  }
  std::fflush(stderr);
  std::_Exit(kWorkerBugExitCode);  // a HapCo bug: a finding for a fuzzer
}

class ReaderWorker {
 public:
  ~ReaderWorker() { Stop(); }

  // Runs `request` on `path` in the worker: `send` adds the request's data, `receive` reads the
  // result. False when no worker process can be started (the caller then reads in-process).
  // Throws what the read threw (InputError, std::bad_alloc), or InputError when HDF5 crashed,
  // looped or grew on the file.
  bool Run(Request request, const std::string& path, const std::function<void(WireWriter&)>& send,
           const std::function<void(WireReader&)>& receive) {
    if (socket_ < 0 && !Start()) return false;
    std::error_code size_error;
    const std::uintmax_t file_size = std::filesystem::file_size(path, size_error);
    const long long file_bytes = size_error ? 0 : static_cast<long long>(file_size);
    const long long before_bytes = ResidentBytes(pid_);  // HDF5's free lists keep memory between files
    const long long memory_limit = before_bytes + kChecksMemoryBytes + kChecksMemoryPerFileByte * file_bytes;
    {
      WireWriter out(socket_);
      out.Value(request);
      Put(out, path);
      if (send) send(out);
      if (!out.Flush()) WorkerEnded(path, Stop());
    }
    const Wait wait = AwaitAnswer(memory_limit);
    if (wait == Wait::kTooMuchMemory || wait == Wait::kTimeout) {
      kill(pid_, SIGKILL);
      Stop();
      if (wait == Wait::kTooMuchMemory) {
        Fail(path, "HDF5 needed more than " + std::to_string((memory_limit - before_bytes) >> 20) + " MiB to read this " +
                       std::to_string(file_bytes) + "-byte file: refused as corrupt");
      }
      Fail(path, "HDF5 did not finish reading the file within " + std::to_string(kChecksTimeoutMs / 1000) +
                     " s: refused as corrupt");
    }
    std::optional<InputError> refusal;
    bool out_of_memory = false;
    try {
      WireReader in(socket_, kReadTimeoutMs);
      const auto answer = in.Value<Answer>();
      if (answer == Answer::kResult) {
        if (receive) receive(in);
      } else if (answer == Answer::kInputError) {
        std::string message;
        Get(in, &message);
        refusal.emplace(message);
      } else {
        HAPCO_ASSERT(answer == Answer::kOutOfMemory, "the FCLIB reader's worker sent an unknown answer");
        out_of_memory = true;
      }
      std::string coverage;
      Get(in, &coverage);
      if (!coverage.empty() && coverage_hooks.merge != nullptr) coverage_hooks.merge(coverage);
    } catch (const WorkerLost&) {
      kill(pid_, SIGKILL);  // (a no-op when it ended by itself; its status says how)
      WorkerEnded(path, Stop());
    }
    if (++requests_ >= kRequestsPerWorker || ResidentBytes(pid_) > started_bytes_ + kWorkerGrowthBytes) Stop();
    if (refusal) throw *refusal;
    if (out_of_memory) throw std::bad_alloc();
    return true;
  }

 private:
  bool Start() {
    int ends[2] = {-1, -1};
    if (socketpair(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC, 0, ends) != 0) return false;
    std::fflush(nullptr);
    const pid_t child = fork();
    if (child < 0) {
      close(ends[0]);
      close(ends[1]);
      return false;
    }
    if (child == 0) {
      close(ends[0]);
      Serve(ends[1]);
    }
    close(ends[1]);
    pid_ = child;
    socket_ = ends[0];
    requests_ = 0;
    started_bytes_ = ResidentBytes(pid_);
    return true;
  }

  // Resident set of a process (/proc/PID/statm), bytes; 0 when it cannot be read.
  static long long ResidentBytes(pid_t pid) {
    std::ifstream statm("/proc/" + std::to_string(pid) + "/statm");
    long long pages = 0, resident = 0;
    if (!(statm >> pages >> resident)) return 0;
    return resident * sysconf(_SC_PAGESIZE);
  }

  // The worker: requests in, answers out, until the reader closes its end.
  [[noreturn]] static void Serve(int socket) {
    prctl(PR_SET_PDEATHSIG, SIGKILL);
    // A crash must end the worker by its signal, not in a sanitizer's or fuzzer's handler
    // (libFuzzer's, inherited over fork, wrote bogus crash files and could deadlock in the
    // child on a lock of a thread the child does not have: finding 12).
    for (const int signal_number : {SIGSEGV, SIGBUS, SIGFPE, SIGILL, SIGABRT, SIGTRAP}) {
      std::signal(signal_number, SIG_DFL);
    }
    // A sanitizer's report (libFuzzer's callback would write the unit it holds as a crash file:
    // from the worker, a bogus one); weak, absent outside sanitizer builds.
    if (__sanitizer_set_death_callback != nullptr) {
      void* warm_up[1];
      backtrace(warm_up, 1);  // loads the unwinder now, not inside a report
      __sanitizer_set_death_callback(&OnSanitizerDeathInWorker);
    }
    SetAssertionExitCode(kWorkerBugExitCode);
    worker_socket = socket;
    for (;;) {
      Request request{};
      std::string path;
      Eigen::VectorXd force_n, displacement_m;
      FclibGlobalSolution global_solution_to_write;
      try {
        WireReader in(socket, -1);
        request = in.Value<Request>();
        Get(in, &path);
        if (request == Request::kWriteLocalSolution) {
          Get(in, &force_n);
          Get(in, &displacement_m);
        } else if (request == Request::kWriteGlobalSolution) {
          Get(in, &global_solution_to_write);
        }
      } catch (const WorkerLost&) {
        std::_Exit(0);  // the reader closed its end
      }
      if (coverage_hooks.reset != nullptr) coverage_hooks.reset();
      // The read first, the answer after: an InputError may come from anywhere in it.
      FclibKind kind = FclibKind::kLocal;
      contact::ContactProblem local;
      FclibFileDetails local_details;
      std::optional<FclibSolution> local_solution;
      contact::GlobalContactProblem global;
      FclibGlobalDetails global_details;
      std::optional<FclibGlobalSolution> global_solution;
      Answer answer = Answer::kResult;
      std::string refusal;
      try {
        switch (request) {
          case Request::kKind: kind = KindInProcess(path); break;
          case Request::kLocalProblem: local = ReadLocalProblemInProcess(path, &local_details); break;
          case Request::kLocalSolution: local_solution = ReadLocalSolutionInProcess(path); break;
          case Request::kGlobalProblem: global = ReadGlobalProblemInProcess(path, &global_details); break;
          case Request::kGlobalSolution: global_solution = ReadGlobalSolutionInProcess(path); break;
          case Request::kWriteLocalSolution: WriteLocalSolutionInProcess(path, force_n, displacement_m); break;
          case Request::kWriteGlobalSolution: WriteGlobalSolutionInProcess(path, global_solution_to_write); break;
          default: HAPCO_ASSERT(false, "the FCLIB reader's worker got an unknown request");
        }
      } catch (const InputError& error) {
        answer = Answer::kInputError;
        refusal = error.what();
      } catch (const std::bad_alloc&) {
        answer = Answer::kOutOfMemory;
      }
      // Every identifier a read opened is closed again, on every path (HDF5 keeps open ones
      // reachable, so a leak checker cannot see a forgotten one).
      HAPCO_ASSERT(H5Fget_obj_count(H5F_OBJ_ALL, H5F_OBJ_ALL) == 0, "an FCLIB read left an HDF5 identifier open");
      WireWriter out(socket);
      out.Value(answer);
      if (answer == Answer::kInputError) Put(out, refusal);
      if (answer == Answer::kResult) {
        switch (request) {
          case Request::kKind: out.Value(kind); break;
          case Request::kLocalProblem: Put(out, local), Put(out, local_details); break;
          case Request::kLocalSolution: Put(out, local_solution); break;
          case Request::kGlobalProblem: Put(out, global), Put(out, global_details); break;
          case Request::kGlobalSolution: Put(out, global_solution); break;
          default: break;  // writes: nothing to return
        }
      }
      Put(out, coverage_hooks.collect != nullptr ? coverage_hooks.collect() : std::string());
      if (!out.Flush()) std::_Exit(0);
    }
  }

  enum class Wait { kAnswer, kTimeout, kTooMuchMemory };
  // Waits for the start of the answer (or the worker's end): for the checks at most
  // kChecksTimeoutMs, looking at the worker's resident memory every kMemoryCheckMs; after the
  // worker's MarkChecked at most kReadTimeoutMs, memory unwatched. A signal (EINTR) resumes the
  // wait for the time left, not a fresh limit: libFuzzer's timer interrupts every 16 s, and
  // restarting let a file HDF5 reads for minutes outlive the limit (finding 13).
  Wait AwaitAnswer(long long memory_limit_bytes) const {
    bool checked = false;
    auto deadline = std::chrono::steady_clock::now() + std::chrono::milliseconds(kChecksTimeoutMs);
    for (;;) {
      const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(deadline - std::chrono::steady_clock::now());
      if (left.count() <= 0) return Wait::kTimeout;
      pollfd ready{socket_, POLLIN, 0};
      const int n = poll(&ready, 1, static_cast<int>(checked ? left.count() : std::min<long long>(left.count(), kMemoryCheckMs)));
      if (n < 0 && errno == EINTR) continue;
      if (n > 0) {
        char mark = 0;
        if (checked || recv(socket_, &mark, 1, MSG_PEEK) != 1 || mark != kCheckedMark) return Wait::kAnswer;
        recv(socket_, &mark, 1, 0);  // the mark itself
        checked = true;
        deadline = std::chrono::steady_clock::now() + std::chrono::milliseconds(kReadTimeoutMs);
        continue;
      }
      if (!checked && ResidentBytes(pid_) > memory_limit_bytes) return Wait::kTooMuchMemory;
    }
  }

  // The worker ended during a request: by a signal if a library crashed on the file.
  [[noreturn]] static void WorkerEnded(const std::string& path, int status) {
    if (WIFSIGNALED(status)) {
      Fail(path, std::string("HDF5 crashed reading the file (") + strsignal(WTERMSIG(status)) + "): it is corrupt");
    }
    const std::string what =
        WIFEXITED(status) && WEXITSTATUS(status) == kWorkerBugExitCode
            ? "the FCLIB reader's worker failed a check of its own (a HapCo bug: its message is above)"
            : "the FCLIB reader's worker ended for another reason than the file (exit status " +
                  std::to_string(WIFEXITED(status) ? WEXITSTATUS(status) : -1) + ")";
    HAPCO_ASSERT(false, what.c_str());
  }

  // Closes the worker's socket (it exits) and reaps it; returns its wait status.
  int Stop() {
    if (socket_ >= 0) close(socket_);
    socket_ = -1;
    int status = 0;
    if (pid_ > 0) {
      while (waitpid(pid_, &status, 0) < 0 && errno == EINTR) {
      }
    }
    pid_ = -1;
    return status;
  }

  pid_t pid_ = -1;
  int socket_ = -1;
  int requests_ = 0;
  long long started_bytes_ = 0;
};

ReaderWorker& Worker() {
  static ReaderWorker worker;
  return worker;
}

}  // namespace

void SetWorkerCoverageHooks(const WorkerCoverageHooks& hooks) { coverage_hooks = hooks; }

FclibKind ReadFclibKind(const std::string& path) {
  FclibKind kind = FclibKind::kLocal;
  if (!Worker().Run(Request::kKind, path, nullptr, [&](WireReader& in) { kind = in.Value<FclibKind>(); })) {
    kind = KindInProcess(path);
  }
  return kind;
}

contact::ContactProblem ReadFclibLocalProblem(const std::string& path, FclibFileDetails* details) {
  contact::ContactProblem problem;
  FclibFileDetails read_details;
  if (!Worker().Run(Request::kLocalProblem, path, nullptr, [&](WireReader& in) {
        Get(in, &problem);
        Get(in, &read_details);
      })) {
    problem = ReadLocalProblemInProcess(path, &read_details);
  }
  if (details != nullptr) *details = std::move(read_details);
  return problem;
}

std::optional<FclibSolution> ReadFclibSolution(const std::string& path) {
  std::optional<FclibSolution> solution;
  if (!Worker().Run(Request::kLocalSolution, path, nullptr, [&](WireReader& in) { Get(in, &solution); })) {
    solution = ReadLocalSolutionInProcess(path);
  }
  return solution;
}

void WriteFclibSolution(const std::string& path, const Eigen::VectorXd& force_n, const Eigen::VectorXd& displacement_m) {
  if (!Worker().Run(
          Request::kWriteLocalSolution, path,
          [&](WireWriter& out) {
            Put(out, force_n);
            Put(out, displacement_m);
          },
          nullptr)) {
    WriteLocalSolutionInProcess(path, force_n, displacement_m);
  }
}

contact::GlobalContactProblem ReadFclibGlobalProblem(const std::string& path, FclibGlobalDetails* details) {
  contact::GlobalContactProblem problem;
  FclibGlobalDetails read_details;
  if (!Worker().Run(Request::kGlobalProblem, path, nullptr, [&](WireReader& in) {
        Get(in, &problem);
        Get(in, &read_details);
      })) {
    problem = ReadGlobalProblemInProcess(path, &read_details);
  }
  if (details != nullptr) *details = std::move(read_details);
  return problem;
}

std::optional<FclibGlobalSolution> ReadFclibGlobalSolution(const std::string& path) {
  std::optional<FclibGlobalSolution> solution;
  if (!Worker().Run(Request::kGlobalSolution, path, nullptr, [&](WireReader& in) { Get(in, &solution); })) {
    solution = ReadGlobalSolutionInProcess(path);
  }
  return solution;
}

void WriteFclibGlobalSolution(const std::string& path, const FclibGlobalSolution& solution) {
  if (!Worker().Run(Request::kWriteGlobalSolution, path, [&](WireWriter& out) { Put(out, solution); }, nullptr)) {
    WriteGlobalSolutionInProcess(path, solution);
  }
}

}  // namespace hapco::fclib
