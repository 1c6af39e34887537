#pragma once
// Recording files (proto/recording.proto): an append-only sequence of checksummed records.
// Writing never rewrites what is already in the file; each record is flushed to the kernel as
// it is written, so a writer killed with SIGKILL leaves every complete record readable.
// Reading stops at a torn tail and resyncs past a damaged record, and says so.
#include <cstdint>
#include <cstdio>
#include <memory>
#include <functional>
#include <string>
#include <string_view>
#include <vector>

#include "recording.pb.h"

namespace hapco::io {

// CRC-32 (IEEE 802.3, reflected, polynomial 0xEDB88320) of `size` bytes.
std::uint32_t Crc32(const void* data, std::size_t size);

// What a writer does with a file that already holds data.
enum class ExistingFile {
  kReplace,  // truncate it (hapco-sim: a run can be repeated)
  kRefuse,   // throw InputError (hapco-recorder: a live recording cannot be made again)
};

class RecordingWriter {
 public:
  // Creates the file (truncating it, or refusing it if it holds data, per `existing`) and
  // writes the file magic and the header record. The file is locked (flock) while the writer
  // lives: a second writer on the same file is refused instead of interleaving its records.
  // Throws InputError if the file cannot be created, is locked or is refused.
  RecordingWriter(const std::string& path, const recording::Header& header,
                  ExistingFile existing = ExistingFile::kReplace);
  ~RecordingWriter();
  RecordingWriter(const RecordingWriter&) = delete;
  RecordingWriter& operator=(const RecordingWriter&) = delete;

  // Appends one record and hands it to the kernel (fflush). Throws InputError on I/O errors.
  void Append(const recording::Record& record);
  void AppendStep(const recording::Step& step);
  std::int64_t records_written() const { return records_written_; }

 private:
  std::FILE* file_ = nullptr;
  std::string path_;
  std::string buffer_;  // reused serialization buffer
  std::int64_t records_written_ = 0;
};

struct RecordingReadReport {
  std::int64_t records = 0;           // complete, checksum-valid records returned
  std::int64_t damaged_records = 0;   // records skipped for a bad checksum or unparsable payload
  std::int64_t skipped_bytes = 0;     // bytes skipped while resyncing past damage
  bool torn_tail = false;             // the file ends inside a record (writer killed mid-write)
  std::int64_t torn_tail_bytes = 0;
  // One line for the user, e.g. "310 records; torn tail of 17 bytes ignored".
  std::string Summary() const;
};

// Reads every complete record. Throws InputError if the file cannot be opened or does not
// start with the recording magic (not a HapCo recording).
std::vector<recording::Record> ReadRecording(const std::string& path, RecordingReadReport* report);

// The same, one record at a time, without holding the file or the records: the file is
// mapped (its pages are the page cache's, not the process's own) and each complete record is
// parsed into one reused message and handed to `visit`. hapco-report held every record of a
// 104 MB recording at once: 465 MB resident, ~4.5x the file (a helper session; an hour of
// one client at ~1.5 MB/s would have needed ~24 GB).
void VisitRecording(const std::string& path, RecordingReadReport* report,
                    const std::function<void(const recording::Record&)>& visit);

// Same, from the file's bytes already in memory; `source_name` is used in messages.
std::vector<recording::Record> ParseRecording(std::string_view data, const std::string& source_name,
                                              RecordingReadReport* report);

}  // namespace hapco::io
