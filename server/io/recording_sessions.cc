#include "io/recording_sessions.h"

namespace hapco::io {

void ClientSessions::Add(const recording::Step& step) {
  // The newest session of the same server (interleaving with another server's does not end it).
  RecordedSession* current = nullptr;
  for (auto it = sessions_.rbegin(); it != sessions_.rend(); ++it) {
    if (it->server_id == step.server_id()) {
      current = &*it;
      break;
    }
  }
  const std::uint64_t number = step.step();
  // A force-only step numbered at or below one already seen, or the frame of a step written
  // from its force just before (the frame came late: the same number): the same session.
  if (current != nullptr &&
      ((number <= current->last_step && step.contacts_missing()) ||
       (number == current->last_step && current->last_force_only))) {
    ++current->steps;
    current->last_force_only = step.contacts_missing();
    return;
  }
  if (current == nullptr || number <= current->last_step) {
    sessions_.push_back({step.server_id(), number, number, 1, 0, step.contacts_missing()});
    return;
  }
  const std::uint64_t gap = number - current->last_step - 1;
  current->missing += gap;
  if (gap > current->largest_gap) {
    current->largest_gap = gap;
    current->largest_gap_first = current->last_step + 1;
  }
  current->last_step = number;
  current->last_force_only = step.contacts_missing();
  ++current->steps;
}

}  // namespace hapco::io
