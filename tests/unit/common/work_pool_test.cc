// WorkPool: every job runs exactly once per batch, on several threads when there are several,
// batch after batch (the 1 kHz server reuses one pool for every tick).
#include <atomic>
#include <set>
#include <thread>
#include <vector>

#include <gtest/gtest.h>

#include "common/error.h"
#include "common/work_pool.h"

namespace hapco {
namespace {

TEST(WorkPoolTest, EveryJobRunsExactlyOncePerBatch) {
  for (int threads : {1, 2, 3, 5}) {
    WorkPool pool(threads);
    EXPECT_EQ(pool.threads(), threads);
    std::vector<std::atomic<int>> runs(37);
    for (int batch = 0; batch < 200; ++batch) {
      const int count = 1 + batch % 37;
      auto job = [&](int i) { runs[static_cast<std::size_t>(i)].fetch_add(1); };
      pool.Run(count, job);
      // Run returned: all of this batch's increments are visible.
      int total = 0;
      for (auto& r : runs) total += r.exchange(0);
      ASSERT_EQ(total, count) << "threads " << threads << " batch " << batch;
    }
  }
}

TEST(WorkPoolTest, JobsOfABatchRunOnSeveralThreads) {
  WorkPool pool(3);
  // Each job waits until three distinct threads have entered a job of the batch: this returns
  // only if the workers really take part (a pool running jobs one after another would hang,
  // so the wait is bounded and the count checked).
  std::atomic<int> entered{0};
  std::vector<std::thread::id> ids(3);
  auto job = [&](int i) {
    ids[static_cast<std::size_t>(i)] = std::this_thread::get_id();
    entered.fetch_add(1);
    for (long spin = 0; entered.load() < 3 && spin < 2'000'000'000L; ++spin) {
    }
  };
  pool.Run(3, job);
  EXPECT_EQ(entered.load(), 3);
  EXPECT_EQ(std::set<std::thread::id>(ids.begin(), ids.end()).size(), 3u);
}

TEST(WorkPoolTest, RefusesZeroThreads) {
  EXPECT_THROW(WorkPool(0), InputError);
  EXPECT_GE(WorkPool::DefaultThreads(), 1);
}

}  // namespace
}  // namespace hapco
