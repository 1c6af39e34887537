#pragma once
// Closing an output file so that a write error (a full disk, /dev/full) is an error, not a
// silently truncated file: fprintf's errors are sticky on the stream, and the last buffered
// bytes fail only at the flush. (A helper session saw hapco-report, hapco-phantom and
// hapco-server exit 0 after writing their CSVs to a full disk.)
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <string>

#include "common/error.h"

namespace hapco {

// Flushes and closes `file` (which may be null: nothing to do). Throws InputError naming
// `path` and the system's reason when any write to it failed.
inline void CloseOutputFile(std::FILE* file, const std::string& path) {
  if (file == nullptr) return;
  const bool flushed = std::fflush(file) == 0 && std::ferror(file) == 0;
  const int flush_errno = errno;
  const bool closed = std::fclose(file) == 0;
  if (!flushed || !closed) {
    throw InputError("cannot write " + path + ": " + std::strerror(flushed ? errno : flush_errno) +
                     " (disk full?); the file is incomplete");
  }
}

}  // namespace hapco
