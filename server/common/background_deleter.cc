#include "common/background_deleter.h"

#include <pthread.h>
#include <sched.h>

namespace hapco {

BackgroundDeleter::BackgroundDeleter() : thread_([this] { Run(); }) {}

BackgroundDeleter::~BackgroundDeleter() {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    stopping_ = true;
  }
  wake_.notify_one();
  thread_.join();
}

void BackgroundDeleter::Push(std::shared_ptr<void> object) {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    queue_.push_back(std::move(object));
  }
  wake_.notify_one();
}

std::uint64_t BackgroundDeleter::destroyed() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return destroyed_;
}

void BackgroundDeleter::Run() {
  // Normal priority even when created by a SCHED_FIFO thread (threads inherit the policy).
  sched_param normal{};
  normal.sched_priority = 0;
  pthread_setschedparam(pthread_self(), SCHED_OTHER, &normal);
  std::vector<std::shared_ptr<void>> batch;
  std::unique_lock<std::mutex> lock(mutex_);
  for (;;) {
    wake_.wait(lock, [this] { return stopping_ || !queue_.empty(); });
    if (queue_.empty()) return;  // stopping, nothing left
    batch.swap(queue_);
    lock.unlock();
    const std::uint64_t count = batch.size();
    batch.clear();  // the destructors run here, outside the lock
    lock.lock();
    destroyed_ += count;
  }
}

}  // namespace hapco
