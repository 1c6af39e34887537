#pragma once
// Destroys objects on a thread of its own, for objects whose destructor may block: a closing
// session deletes its DDS writers, and Cyclone's dds_delete of a writer waits for its readers'
// acknowledgements and for its own threads to pass a quiescent point. Measured 97-142 ms per
// session on a loaded 2-core host (2026-12-05), during which the server loop stepped no one:
// every other client of the server lost its forces when one client left. Handing the session
// here makes the close cost the loop a mutex and a push.
//
// The thread runs at normal priority (SCHED_OTHER), whatever its creator's: a blocked delete
// must never compete with the 1 kHz threads. The destructor destroys what is still queued,
// then joins; declare the deleter so it is destroyed before anything the objects use (e.g.
// after the DDS participant their writers belong to).
#include <condition_variable>
#include <cstdint>
#include <memory>
#include <mutex>
#include <thread>
#include <vector>

namespace hapco {

class BackgroundDeleter {
 public:
  BackgroundDeleter();
  ~BackgroundDeleter();
  BackgroundDeleter(const BackgroundDeleter&) = delete;
  BackgroundDeleter& operator=(const BackgroundDeleter&) = delete;

  // Queues `object` for destruction on the deleter's thread; returns without waiting.
  template <typename T>
  void Retire(std::unique_ptr<T> object) {
    if (object) Push(std::shared_ptr<void>(std::move(object)));
  }
  // Objects destroyed so far (for tests and logs).
  std::uint64_t destroyed() const;

 private:
  void Push(std::shared_ptr<void> object);
  void Run();

  mutable std::mutex mutex_;
  std::condition_variable wake_;
  std::vector<std::shared_ptr<void>> queue_;
  bool stopping_ = false;
  std::uint64_t destroyed_ = 0;
  std::thread thread_;  // last: started once the members above exist
};

}  // namespace hapco
