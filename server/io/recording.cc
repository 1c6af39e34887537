#include "io/recording.h"

#include <fcntl.h>
#include <sys/file.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <unistd.h>

#include <array>
#include <cerrno>
#include <cstring>

#include "common/error.h"

namespace hapco::io {
namespace {

constexpr char kFileMagic[8] = {'H', 'A', 'P', 'C', 'O', 'R', 'E', 'C'};
constexpr std::uint32_t kRecordMagic = 0x52435048u;  // "HPCR" little endian
constexpr std::size_t kFrameBytes = 12;              // magic, length, crc
constexpr std::uint32_t kMaxRecordBytes = 64u << 20;  // a sanity bound against damaged lengths

std::array<std::uint32_t, 256> MakeCrcTable() {
  std::array<std::uint32_t, 256> table{};
  for (std::uint32_t i = 0; i < 256; ++i) {
    std::uint32_t c = i;
    for (int k = 0; k < 8; ++k) c = (c & 1u) ? 0xEDB88320u ^ (c >> 1) : c >> 1;
    table[i] = c;
  }
  return table;
}

void PutU32(std::uint32_t value, char* out) {
  for (int i = 0; i < 4; ++i) out[i] = static_cast<char>((value >> (8 * i)) & 0xFFu);
}

std::uint32_t GetU32(const char* in) {
  std::uint32_t value = 0;
  for (int i = 0; i < 4; ++i) value |= static_cast<std::uint32_t>(static_cast<unsigned char>(in[i])) << (8 * i);
  return value;
}

}  // namespace

std::uint32_t Crc32(const void* data, std::size_t size) {
  static const std::array<std::uint32_t, 256> table = MakeCrcTable();
  const auto* bytes = static_cast<const unsigned char*>(data);
  std::uint32_t crc = 0xFFFFFFFFu;
  for (std::size_t i = 0; i < size; ++i) crc = table[(crc ^ bytes[i]) & 0xFFu] ^ (crc >> 8);
  return crc ^ 0xFFFFFFFFu;
}

RecordingWriter::RecordingWriter(const std::string& path, const recording::Header& header, ExistingFile existing)
    : path_(path) {
  // Opened without O_TRUNC: whether the data may go is decided after the lock is held (two
  // recorders on one --output interleaved their records and both reported success; a
  // restarted recorder truncated the steps its predecessor had recorded: a helper session).
  const int fd = ::open(path.c_str(), O_WRONLY | O_CREAT | O_CLOEXEC, 0644);
  if (fd < 0) throw InputError("cannot create recording file " + path + ": " + std::strerror(errno));
  if (::flock(fd, LOCK_EX | LOCK_NB) != 0) {
    ::close(fd);
    throw InputError("another process is writing " + path +
                     " (a second recorder on the same --output?): give each writer a file of its own");
  }
  struct stat status {};
  if (::fstat(fd, &status) == 0 && S_ISREG(status.st_mode) && status.st_size > 0) {
    if (existing == ExistingFile::kRefuse) {
      ::close(fd);
      throw InputError(path + " already holds " + std::to_string(status.st_size) +
                       " bytes (an earlier recording, or another file): give another --output (docker/compose.yaml "
                       "names recordings by their start time), or --overwrite to replace it");
    }
    if (::ftruncate(fd, 0) != 0) {
      ::close(fd);
      throw InputError("cannot truncate recording file " + path + ": " + std::strerror(errno));
    }
  }
  file_ = ::fdopen(fd, "wb");  // the lock lives as long as the descriptor, released by fclose
  if (file_ == nullptr) {
    ::close(fd);
    throw InputError("cannot create recording file " + path);
  }
  if (std::fwrite(kFileMagic, 1, sizeof(kFileMagic), file_) != sizeof(kFileMagic)) {
    throw InputError("cannot write recording file " + path);
  }
  recording::Record record;
  *record.mutable_header() = header;
  Append(record);
}

RecordingWriter::~RecordingWriter() {
  if (file_ != nullptr) std::fclose(file_);
}

void RecordingWriter::Append(const recording::Record& record) {
  buffer_.clear();
  if (!record.AppendToString(&buffer_)) throw InputError("cannot serialize a recording record");
  char frame[kFrameBytes];
  PutU32(kRecordMagic, frame);
  PutU32(static_cast<std::uint32_t>(buffer_.size()), frame + 4);
  PutU32(Crc32(buffer_.data(), buffer_.size()), frame + 8);
  if (std::fwrite(frame, 1, kFrameBytes, file_) != kFrameBytes ||
      std::fwrite(buffer_.data(), 1, buffer_.size(), file_) != buffer_.size() || std::fflush(file_) != 0) {
    throw InputError("error writing recording file " + path_ + " (disk full?)");
  }
  ++records_written_;
}

void RecordingWriter::AppendStep(const recording::Step& step) {
  recording::Record record;
  *record.mutable_step() = step;
  Append(record);
}

std::string RecordingReadReport::Summary() const {
  std::string text = std::to_string(records) + " records";
  if (damaged_records > 0) {
    text += "; " + std::to_string(damaged_records) + " damaged records skipped (" +
            std::to_string(skipped_bytes) + " bytes)";
  }
  if (torn_tail) text += "; torn tail of " + std::to_string(torn_tail_bytes) + " bytes ignored (writer stopped mid-record)";
  return text;
}

namespace {

// The parse loop of ParseRecording and VisitRecording: every complete, checksum-valid record
// goes to `visit` (`record` is reused; a visitor may move it out), damage is skipped by
// resyncing on the record magic.
void ParseRecords(std::string_view data, const std::string& path, RecordingReadReport* report,
                  const std::function<void(recording::Record&)>& visit) {
  if (data.size() < sizeof(kFileMagic) || std::memcmp(data.data(), kFileMagic, sizeof(kFileMagic)) != 0) {
    throw InputError(path + " is not a HapCo recording (missing the HAPCOREC magic)");
  }
  RecordingReadReport local;
  recording::Record record;
  std::size_t at = sizeof(kFileMagic);
  // Resync: look for the next record magic after damage.
  auto next_magic = [&](std::size_t from) {
    for (std::size_t i = from; i + 4 <= data.size(); ++i) {
      if (GetU32(data.data() + i) == kRecordMagic) return i;
    }
    return data.size();
  };
  while (at < data.size()) {
    const std::size_t remaining = data.size() - at;
    if (remaining < kFrameBytes) {
      local.torn_tail = true;
      local.torn_tail_bytes = static_cast<std::int64_t>(remaining);
      break;
    }
    const std::uint32_t magic = GetU32(data.data() + at);
    const std::uint32_t length = GetU32(data.data() + at + 4);
    const std::uint32_t crc = GetU32(data.data() + at + 8);
    if (magic != kRecordMagic || length > kMaxRecordBytes) {
      const std::size_t next = next_magic(at + 1);
      ++local.damaged_records;
      local.skipped_bytes += static_cast<std::int64_t>(next - at);
      at = next;
      continue;
    }
    if (remaining < kFrameBytes + length) {
      // Either the last record was cut short, or a damaged length points past the end: tell
      // them apart by looking for a later record.
      const std::size_t next = next_magic(at + 1);
      if (next == data.size()) {
        local.torn_tail = true;
        local.torn_tail_bytes = static_cast<std::int64_t>(remaining);
        break;
      }
      ++local.damaged_records;
      local.skipped_bytes += static_cast<std::int64_t>(next - at);
      at = next;
      continue;
    }
    const char* payload = data.data() + at + kFrameBytes;
    record.Clear();
    if (Crc32(payload, length) != crc || !record.ParseFromArray(payload, static_cast<int>(length))) {
      const std::size_t next = next_magic(at + 1);
      ++local.damaged_records;
      local.skipped_bytes += static_cast<std::int64_t>(next - at);
      at = next;
      continue;
    }
    ++local.records;
    visit(record);
    at += kFrameBytes + length;
  }
  if (report != nullptr) *report = local;
}

// VisitRecording's body, with a visitor that may move the record out (ReadRecording).
void VisitRecordsOfFile(const std::string& path, RecordingReadReport* report,
                        const std::function<void(recording::Record&)>& visit) {
  const int fd = open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) throw InputError("cannot open recording " + path);
  struct stat st {};
  if (fstat(fd, &st) != 0 || S_ISDIR(st.st_mode)) {
    close(fd);
    throw InputError("cannot read recording " + path + ": it is a directory");
  }
  if (!S_ISREG(st.st_mode)) {
    // A pipe or a device (hapco-report /dev/stdin < FILE): read into memory, as before.
    std::string data;
    char chunk[1 << 16];
    ssize_t got = 0;
    while ((got = read(fd, chunk, sizeof(chunk))) > 0) data.append(chunk, static_cast<std::size_t>(got));
    close(fd);
    ParseRecords(data, path, report, visit);
    return;
  }
  const auto size = static_cast<std::size_t>(st.st_size);
  if (size == 0) {
    close(fd);
    ParseRecords(std::string_view(), path, report, visit);  // throws: no magic
    return;
  }
  void* map = mmap(nullptr, size, PROT_READ, MAP_PRIVATE, fd, 0);
  close(fd);  // the mapping stays valid
  if (map == MAP_FAILED) throw InputError("cannot map recording " + path + ": " + std::strerror(errno));
  madvise(map, size, MADV_SEQUENTIAL);
  try {
    ParseRecords(std::string_view(static_cast<const char*>(map), size), path, report, visit);
  } catch (...) {
    munmap(map, size);
    throw;
  }
  munmap(map, size);
}

}  // namespace

void VisitRecording(const std::string& path, RecordingReadReport* report,
                    const std::function<void(const recording::Record&)>& visit) {
  VisitRecordsOfFile(path, report, [&visit](recording::Record& record) { visit(record); });
}

std::vector<recording::Record> ReadRecording(const std::string& path, RecordingReadReport* report) {
  std::vector<recording::Record> records;
  VisitRecordsOfFile(path, report, [&records](recording::Record& record) { records.push_back(std::move(record)); });
  return records;
}

std::vector<recording::Record> ParseRecording(std::string_view data, const std::string& path,
                                              RecordingReadReport* report) {
  std::vector<recording::Record> records;
  ParseRecords(data, path, report, [&records](recording::Record& record) { records.push_back(std::move(record)); });
  return records;
}

}  // namespace hapco::io
