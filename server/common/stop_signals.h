#pragma once
// SIGINT/SIGTERM as a clean-shutdown request for a long-running tool (hapco-server,
// hapco-recorder). Self-pipe: the handler only write()s the signal number (async-signal-safe);
// a thread of ours reads it and calls the tool's stop function (e.g. wake its WaitSet).
// Blocking the signals instead is not enough: a thread a library created before main() would
// still take the default action.
#include <atomic>
#include <functional>
#include <thread>

namespace hapco {

class StopSignals {
 public:
  // Installs the handlers at once, so a signal during a long setup is kept until Watch().
  // One instance per process.
  StopSignals();
  StopSignals(const StopSignals&) = delete;
  StopSignals& operator=(const StopSignals&) = delete;

  // The watching thread; ends (without calling on_stop) and is joined when this goes out of
  // scope. Declare it after everything on_stop touches, so it ends before they do.
  class Watching {
   public:
    Watching(Watching&&) = default;
    ~Watching();

   private:
    friend class StopSignals;
    explicit Watching(std::thread thread) : thread_(std::move(thread)) {}
    std::thread thread_;
  };

  // Starts the thread: on SIGINT/SIGTERM it records the signal and calls on_stop once.
  [[nodiscard]] Watching Watch(std::function<void()> on_stop);
  int received() const { return received_.load(); }  // SIGINT, SIGTERM, or 0
  // "SIGINT", "SIGTERM", or `otherwise` when no signal stopped the tool.
  const char* ReceivedName(const char* otherwise) const;

 private:
  std::atomic<int> received_{0};
};

}  // namespace hapco
