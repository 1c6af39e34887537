#pragma once
// A fixed pool of threads that runs a batch of independent jobs and returns when all are done:
// the server steps its sessions (independent, on one immutable model) on every core
// (issue 13; design.md ex. 4). Built for the 1 kHz path: no allocation and no mutex per batch;
// workers sleep on an atomic (futex) between batches and take jobs with one fetch_add each.
// The calling thread works too, so WorkPool(1) has no workers and runs jobs inline, and a
// batch of one job never wakes a worker.
//
// Threads are created in the constructor and inherit the creating thread's scheduling policy
// (SCHED_FIFO after UseRealtimePriority).
#include <atomic>
#include <cstdint>
#include <thread>
#include <vector>

namespace hapco {

class WorkPool {
 public:
  // threads >= 1 in total (the caller of Run included); InputError otherwise.
  explicit WorkPool(int threads);
  ~WorkPool();
  WorkPool(const WorkPool&) = delete;
  WorkPool& operator=(const WorkPool&) = delete;

  int threads() const { return static_cast<int>(workers_.size()) + 1; }

  // Runs job(i) for every i in [0, count) and returns when all have returned. Jobs must be
  // independent and must not throw (a thrown exception terminates: catch inside the job).
  // Call from one thread at a time.
  template <typename Job>
  void Run(int count, Job& job) {
    RunErased(count, [](void* context, int i) { (*static_cast<Job*>(context))(i); }, &job);
  }

  // Default for --threads: one per online core.
  static int DefaultThreads();

 private:
  using Function = void (*)(void*, int);
  void RunErased(int count, Function function, void* context);
  void WorkerLoop();
  void TakeJobs();

  std::vector<std::thread> workers_;
  // The batch: written by Run before generation_ is bumped, read by workers after they see
  // the new generation; Run waits for every worker to finish the batch before the next.
  Function function_ = nullptr;
  void* context_ = nullptr;
  int count_ = 0;
  std::atomic<int> next_{0};
  std::atomic<std::uint64_t> generation_{0};
  std::atomic<int> finished_workers_{0};
  std::atomic<bool> stop_{false};
};

}  // namespace hapco
