// FCLIB files, local and global problems (the harness keeps its historical name). libfclib
// reads by file name and calls exit(1) on what it cannot
// read, and HDF5 trusts the file's metadata, so fclib_io's own HDF5 pre-checks must refuse
// every malformed layout before libfclib sees it. Two modes, by the first byte:
//   'L' + bytes: a layout written with the HDF5 API from fuzzed fields (types, sizes, index
//                arrays, values, strings): reaches the pre-checks with a well-formed file;
//   otherwise:   the bytes are the file itself (mutated seed files: damaged HDF5).
// Either way the file goes to a per-process path on /dev/shm (tmpfs) when it exists.
#include <hdf5.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <csignal>
#include <cstdio>
#include <cstring>
#include <limits>
#include <string>
#include <string_view>
#include <vector>

#include "common/error.h"
#include "fclib/fclib_io.h"
#include "fuzz_targets.h"

namespace hapco::fuzz {
namespace {

// fclib_io reads every file in a worker process (a fork of this fuzzer, fclib_io.cc), so the
// reader's code runs there, out of libFuzzer's sight: the worker sends its coverage counters
// back with every answer and they are added to this process's (the inline 8-bit counters that
// -fsanitize=fuzzer-no-link places between these linker-made symbols; absent, i.e. null, in
// the release replay build). libFuzzer's comparison tracing of the worker is not carried over.
// A memory error the worker hits in HDF5 refuses the file (as the release build's crash does);
// any other sanitizer report there ends the worker as a HapCo bug, which aborts this process:
// a finding (fclib_io.cc, OnSanitizerDeathInWorker).
extern "C" {
extern std::uint8_t __start___sancov_cntrs[] __attribute__((weak));
extern std::uint8_t __stop___sancov_cntrs[] __attribute__((weak));
}

std::size_t CounterBytes() {
  return __start___sancov_cntrs == nullptr ? 0 : static_cast<std::size_t>(__stop___sancov_cntrs - __start___sancov_cntrs);
}
void ResetWorkerCoverage() { std::memset(__start___sancov_cntrs, 0, CounterBytes()); }
std::string CollectWorkerCoverage() {
  return std::string(reinterpret_cast<const char*>(__start___sancov_cntrs), CounterBytes());
}
void MergeWorkerCoverage(std::string_view coverage) {
  HAPCO_FUZZ_CHECK(coverage.size() == CounterBytes(), "the worker's counters differ from this process's");
  for (std::size_t k = 0; k < coverage.size(); ++k) {
    const unsigned sum = __start___sancov_cntrs[k] + static_cast<std::uint8_t>(coverage[k]);
    __start___sancov_cntrs[k] = static_cast<std::uint8_t>(std::min(sum, 255u));
  }
}
[[maybe_unused]] const bool kCoverageHooksInstalled = [] {
  if (CounterBytes() > 0) {
    fclib::SetWorkerCoverageHooks({&ResetWorkerCoverage, &CollectWorkerCoverage, &MergeWorkerCoverage});
  }
  return true;
}();

std::string ScratchPath() {
  const char* dir = access("/dev/shm", W_OK) == 0 ? "/dev/shm" : "/tmp";
  return std::string(dir) + "/hapco-fuzz-fclib-" + std::to_string(getpid()) + ".h5";
}

// Reads fuzz bytes as fields; past the end everything is zero.
class Fields {
 public:
  Fields(const std::uint8_t* data, std::size_t size) : data_(data), size_(size) {}
  std::uint8_t Byte() { return at_ < size_ ? data_[at_++] : 0; }
  // Small values mostly (sizes, indices near the valid range), any int32 sometimes.
  int Int() {
    const std::uint8_t kind = Byte();
    if (kind < 0xF0) return static_cast<int>(static_cast<std::int8_t>(Byte()));
    std::uint32_t v = 0;
    for (int k = 0; k < 4; ++k) v |= static_cast<std::uint32_t>(Byte()) << (8 * k);
    int out = 0;
    std::memcpy(&out, &v, sizeof(out));
    return out;
  }
  double Double() {
    const std::uint8_t kind = Byte();
    if (kind < 0xE0) return static_cast<double>(static_cast<std::int8_t>(Byte())) / 8.0;
    std::uint64_t v = 0;
    for (int k = 0; k < 8; ++k) v |= static_cast<std::uint64_t>(Byte()) << (8 * k);
    double out = 0;
    std::memcpy(&out, &v, sizeof(out));
    return out;
  }

 private:
  const std::uint8_t* data_;
  std::size_t size_;
  std::size_t at_ = 0;
};

// n + 1 for a compressed matrix's index array, without overflowing a fuzzed INT_MAX (found by
// the long run: UB in this harness, not in the reader).
int PlusOne(int n) { return n == std::numeric_limits<int>::max() ? n : n + 1; }

// One dataset: absent, integers, doubles or a string; its length is fuzzed too.
void WriteDataset(hid_t file, const std::string& name, int expected, Fields* f) {
  const std::uint8_t how = f->Byte();
  if (how % 8 == 7) return;  // absent
  const int kind = how % 8 == 6 ? 2 : (how % 8 >= 3 ? 1 : 0);  // 0 int, 1 double, 2 string
  // In 64 bits: `expected` is fuzzed and may be INT_MAX (UB in int, found by the long run).
  long long count = expected;
  if ((how >> 3) % 4 == 3) count = std::max(0LL, count + static_cast<int>(static_cast<std::int8_t>(f->Byte())) % 5);
  count = std::clamp(count, 0LL, 256LL);
  const hsize_t dims[1] = {static_cast<hsize_t>(count)};
  if (kind == 2) {
    std::string text(1, 's');  // (not "s" + to_string: GCC 12 warns -Wrestrict falsely)
    text += std::to_string(f->Byte());
    hid_t type = H5Tcopy(H5T_C_S1);
    H5Tset_size(type, text.size());
    hid_t space = H5Screate(H5S_SCALAR);
    hid_t set = H5Dcreate2(file, name.c_str(), type, space, H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT);
    if (set >= 0) H5Dwrite(set, type, H5S_ALL, H5S_ALL, H5P_DEFAULT, text.data()), H5Dclose(set);
    H5Sclose(space);
    H5Tclose(type);
    return;
  }
  hid_t space = H5Screate_simple(1, dims, nullptr);
  if (kind == 0) {
    std::vector<int> values(static_cast<std::size_t>(count) + 1);
    for (int k = 0; k < count; ++k) values[static_cast<std::size_t>(k)] = f->Int();
    hid_t set = H5Dcreate2(file, name.c_str(), H5T_NATIVE_INT, space, H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT);
    if (set >= 0) H5Dwrite(set, H5T_NATIVE_INT, H5S_ALL, H5S_ALL, H5P_DEFAULT, values.data()), H5Dclose(set);
  } else {
    std::vector<double> values(static_cast<std::size_t>(count) + 1);
    for (int k = 0; k < count; ++k) values[static_cast<std::size_t>(k)] = f->Double();
    hid_t set = H5Dcreate2(file, name.c_str(), H5T_NATIVE_DOUBLE, space, H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT);
    if (set >= 0) H5Dwrite(set, H5T_NATIVE_DOUBLE, H5S_ALL, H5S_ALL, H5P_DEFAULT, values.data()), H5Dclose(set);
  }
  H5Sclose(space);
}

void WriteScalar(hid_t file, const std::string& name, int value, Fields* f) {
  if (f->Byte() % 16 == 15) return;  // absent
  const hsize_t dims[1] = {1};
  hid_t space = H5Screate_simple(1, dims, nullptr);
  hid_t set = H5Dcreate2(file, name.c_str(), H5T_NATIVE_INT, space, H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT);
  if (set >= 0) H5Dwrite(set, H5T_NATIVE_INT, H5S_ALL, H5S_ALL, H5P_DEFAULT, &value), H5Dclose(set);
  H5Sclose(space);
}

void Group(hid_t file, const char* name) {
  hid_t group = H5Gcreate2(file, name, H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT);
  if (group >= 0) H5Gclose(group);
}

bool WriteLayout(const std::string& path, Fields* f) {
  H5Eset_auto2(H5E_DEFAULT, nullptr, nullptr);
  hid_t file = H5Fcreate(path.c_str(), H5F_ACC_TRUNC, H5P_DEFAULT, H5P_DEFAULT);
  if (file < 0) return false;
  const std::uint8_t groups = f->Byte();
  if (groups & 1u) {
    Group(file, "/fclib_global");
    if (groups & 128u) {  // a global problem's layout (M, H, optional G, vectors)
      WriteScalar(file, "/fclib_global/spacedim", (groups & 4u) ? f->Int() : 3, f);
      const int n = f->Int(), nc3 = f->Int();
      for (const char* matrix : {"M", "H"}) {
        const std::string g = std::string("/fclib_global/") + matrix;
        Group(file, g.c_str());
        const int rows = n, cols = matrix[0] == 'M' ? n : nc3, nz = f->Int(), nzmax = f->Int();
        WriteScalar(file, g + "/m", rows, f);
        WriteScalar(file, g + "/n", cols, f);
        WriteScalar(file, g + "/nz", nz, f);
        WriteScalar(file, g + "/nzmax", nzmax, f);
        WriteDataset(file, g + "/p", nz >= 0 ? nz : PlusOne(cols), f);
        WriteDataset(file, g + "/i", nz >= 0 ? nz : nzmax, f);
        WriteDataset(file, g + "/x", nzmax, f);
      }
      if (groups & 8u) Group(file, "/fclib_global/G");
      Group(file, "/fclib_global/vectors");
      WriteDataset(file, "/fclib_global/vectors/f", n, f);
      WriteDataset(file, "/fclib_global/vectors/w", nc3, f);
      WriteDataset(file, "/fclib_global/vectors/mu", nc3 / 3, f);
      if (groups & 64u) {
        Group(file, "/solution");
        WriteDataset(file, "/solution/v", n, f);
        WriteDataset(file, "/solution/r", nc3, f);
        WriteDataset(file, "/solution/u", nc3, f);
      }
      H5Fclose(file);
      return true;
    }
  }
  if (!(groups & 2u)) {
    Group(file, "/fclib_local");
    const int m = f->Int(), n = f->Int(), nz = f->Int(), nzmax = f->Int();
    WriteScalar(file, "/fclib_local/spacedim", (groups & 4u) ? f->Int() : 3, f);
    Group(file, "/fclib_local/W");
    WriteScalar(file, "/fclib_local/W/m", m, f);
    WriteScalar(file, "/fclib_local/W/n", n, f);
    WriteScalar(file, "/fclib_local/W/nz", nz, f);
    WriteScalar(file, "/fclib_local/W/nzmax", nzmax, f);
    const int entries = nz >= 0 ? nz : nzmax;
    WriteDataset(file, "/fclib_local/W/p", nz >= 0 ? nz : PlusOne(n), f);
    WriteDataset(file, "/fclib_local/W/i", entries, f);
    WriteDataset(file, "/fclib_local/W/x", nzmax, f);
    if (groups & 8u) {
      WriteDataset(file, "/fclib_local/W/conditioning", 1, f);
      WriteDataset(file, "/fclib_local/W/determinant", 1, f);
      WriteDataset(file, "/fclib_local/W/rank", 1, f);
      WriteDataset(file, "/fclib_local/W/comment", 1, f);
    }
    Group(file, "/fclib_local/vectors");
    WriteDataset(file, "/fclib_local/vectors/q", m, f);
    WriteDataset(file, "/fclib_local/vectors/mu", m / 3, f);
    if (groups & 16u) WriteDataset(file, "/fclib_local/V", 3, f);
    if (groups & 32u) {
      Group(file, "/fclib_local/info");
      WriteDataset(file, "/fclib_local/info/title", 1, f);
      WriteDataset(file, "/fclib_local/info/description", 1, f);
      WriteDataset(file, "/fclib_local/info/math_info", 1, f);
    }
    if (groups & 64u) {
      Group(file, "/solution");
      WriteDataset(file, "/solution/r", m, f);
      WriteDataset(file, "/solution/u", m, f);
    }
  }
  H5Fclose(file);
  return true;
}

}  // namespace

int FclibLocal(const std::uint8_t* data, std::size_t size) {
  static const std::string path = ScratchPath();
  // Every file open allocates HDF5's metadata cache (~1 MB); above its default free-list
  // limits HDF5 returns it to malloc at close, and under ASan each open then maps and zeroes
  // fresh pages (half the run time). Larger limits keep it on HDF5's free lists.
  static const bool cached = H5set_free_list_limits(64 << 20, 16 << 20, 64 << 20, 16 << 20, 64 << 20, 16 << 20) >= 0;
  (void)cached;
  if (size >= 1 && data[0] == 'L') {
    Fields fields(data + 1, size - 1);
    if (!WriteLayout(path, &fields)) return 0;
  } else {
    std::FILE* file = std::fopen(path.c_str(), "wb");
    if (file == nullptr) return 0;
    const bool written = std::fwrite(data, 1, size, file) == size;
    std::fclose(file);
    if (!written) return 0;
  }
  try {
    if (fclib::ReadFclibKind(path) == fclib::FclibKind::kGlobal) {
      fclib::FclibGlobalDetails details;
      const contact::GlobalContactProblem problem = fclib::ReadFclibGlobalProblem(path, &details);
      HAPCO_FUZZ_CHECK(problem.num_contacts() >= 1 && problem.num_contacts() <= fclib::kMaxContacts,
                       "accepted a contact count out of range");
      HAPCO_FUZZ_CHECK(problem.h.rows() == problem.m.rows() && problem.h.cols() == 3 * problem.num_contacts(),
                       "accepted inconsistent sizes");
      const auto solution = fclib::ReadFclibGlobalSolution(path);
      if (solution) HAPCO_FUZZ_CHECK(solution->velocity.size() == problem.m.rows(), "solution of another size");
      throw InputError("done");  // the local reader below is for local files
    }
    fclib::FclibFileDetails details;
    const contact::ContactProblem problem = fclib::ReadFclibLocalProblem(path, &details);
    const int m = problem.num_contacts();
    HAPCO_FUZZ_CHECK(m >= 1 && m <= fclib::kMaxContacts, "accepted a contact count out of range");
    HAPCO_FUZZ_CHECK(problem.flexibility_m_per_n.allFinite(), "accepted a non-finite W");
    const auto solution = fclib::ReadFclibSolution(path);
    if (solution) HAPCO_FUZZ_CHECK(solution->force_n.size() == 3 * m, "solution of another size");
  } catch (const InputError&) {
  }
  // HDF5 keeps every open identifier reachable, so LeakSanitizer cannot see one that
  // fclib_io forgot to close (and HDF5's own leaks on corrupt files are suppressed,
  // tests/fuzz/lsan.supp): count them instead. The worker checks its own after every read;
  // here, the layout writer's and anything the reader opened in this process.
  HAPCO_FUZZ_CHECK(H5Fget_obj_count(H5F_OBJ_ALL, H5F_OBJ_ALL) == 0, "an HDF5 identifier was left open");
  std::remove(path.c_str());
  return 0;
}

}  // namespace hapco::fuzz
