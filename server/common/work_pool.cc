#include "common/work_pool.h"

#include <string>

#include "common/error.h"

namespace hapco {

WorkPool::WorkPool(int threads) {
  if (threads < 1) throw InputError("--threads must be >= 1 (got " + std::to_string(threads) + ")");
  workers_.reserve(static_cast<std::size_t>(threads - 1));
  for (int t = 1; t < threads; ++t) workers_.emplace_back([this] { WorkerLoop(); });
}

WorkPool::~WorkPool() {
  stop_.store(true);
  generation_.fetch_add(1);
  generation_.notify_all();
  for (std::thread& worker : workers_) worker.join();
}

int WorkPool::DefaultThreads() {
  const unsigned cores = std::thread::hardware_concurrency();
  return cores == 0 ? 1 : static_cast<int>(cores);
}

void WorkPool::TakeJobs() {
  for (int i = next_.fetch_add(1); i < count_; i = next_.fetch_add(1)) function_(context_, i);
}

void WorkPool::WorkerLoop() {
  std::uint64_t seen = 0;
  for (;;) {
    generation_.wait(seen);
    seen = generation_.load();
    if (stop_.load()) return;
    TakeJobs();
    finished_workers_.fetch_add(1);
    finished_workers_.notify_one();
  }
}

void WorkPool::RunErased(int count, Function function, void* context) {
  if (count <= 0) return;
  if (count == 1 || workers_.empty()) {
    for (int i = 0; i < count; ++i) function(context, i);
    return;
  }
  function_ = function;
  context_ = context;
  count_ = count;
  next_.store(0);
  finished_workers_.store(0);
  generation_.fetch_add(1);  // publishes the batch (seq_cst)
  generation_.notify_all();
  TakeJobs();
  // Every worker takes part in every batch (it may find no job left), so none can still be
  // reading this batch when the next one is written.
  const int workers = static_cast<int>(workers_.size());
  for (int finished = finished_workers_.load(); finished != workers; finished = finished_workers_.load()) {
    finished_workers_.wait(finished);
  }
}

}  // namespace hapco
