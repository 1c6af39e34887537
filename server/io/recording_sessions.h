#pragma once
// A client's sessions in a recording, for hapco-report: which server stepped it, from which
// step to which, and how many steps of each are in the file.
//
// A session is one server's step counter for the client, counted from 1. A new one starts when
// that server's counter starts again (a restarted client or server, a SESSION_RESET, or the
// client coming back after a move) or when another server steps the client for the first time.
// Two things do not start one, both seen in overloaded compose runs (docs/several-servers.md):
// steps of two servers interleaved in time (poses sent to the old server before a move arrive
// there late and are stepped there; its session goes on), and steps written from a force whose
// frame was lost (contacts_missing), whose step number is only the lowest possible and may
// repeat one already seen (or be repeated by the frame itself when it comes late).
#include <cstdint>
#include <string>
#include <vector>

#include "recording.pb.h"

namespace hapco::io {

struct RecordedSession {
  std::string server_id;
  std::uint64_t first_step = 0, last_step = 0;
  long steps = 0;             // step records of this session in the file
  std::uint64_t missing = 0;  // steps of the server's counter between first and last not in the file
  // Steps 1..first_step-1 of the counter, made before the first one in the file (the recorder
  // started, or the client joined its server's recording, after them).
  std::uint64_t before_first() const { return first_step > 1 ? first_step - 1 : 0; }
  bool last_force_only = false;  // the record of last_step was written from a force alone
  // The longest run of the counter's steps between first and last not in the file: where
  // `missing` is (the report gave the count only; a stopped recorder's 1 838 steps were
  // found in the CSV; a helper session). 0 when none.
  std::uint64_t largest_gap = 0, largest_gap_first = 0;
};

// Accumulates one client's step records in file order.
class ClientSessions {
 public:
  void Add(const recording::Step& step);
  // In order of their first step in the file.
  const std::vector<RecordedSession>& sessions() const { return sessions_; }

 private:
  std::vector<RecordedSession> sessions_;
};

}  // namespace hapco::io
