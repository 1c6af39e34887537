// BackgroundDeleter: objects are destroyed on the deleter's own thread, the caller is never
// held up by a destructor that blocks, and nothing queued is left undestroyed at shutdown.
#include <atomic>
#include <future>
#include <memory>
#include <thread>

#include <gtest/gtest.h>

#include "common/background_deleter.h"

namespace hapco {
namespace {

// Its destructor says on which thread it runs, then waits until the test opens the gate.
class BlocksInDestructor {
 public:
  BlocksInDestructor(std::shared_future<void> gate, std::promise<std::thread::id>* started)
      : gate_(std::move(gate)), started_(started) {}
  ~BlocksInDestructor() {
    started_->set_value(std::this_thread::get_id());
    gate_.wait();
  }

 private:
  std::shared_future<void> gate_;
  std::promise<std::thread::id>* started_;
};

class Counted {
 public:
  explicit Counted(std::atomic<int>* destroyed) : destroyed_(destroyed) {}
  ~Counted() { destroyed_->fetch_add(1); }

 private:
  std::atomic<int>* destroyed_;
};

TEST(BackgroundDeleterTest, ABlockingDestructorRunsOnTheDeletersThreadAndHoldsUpNoCaller) {
  std::promise<void> gate;
  std::promise<std::thread::id> started;
  std::atomic<int> counted_destroyed{0};
  auto deleter = std::make_unique<BackgroundDeleter>();
  deleter->Retire(std::make_unique<BlocksInDestructor>(gate.get_future().share(), &started));
  // Retire returned although that destructor cannot finish before the gate opens.
  const std::thread::id destroyer = started.get_future().get();
  EXPECT_NE(destroyer, std::this_thread::get_id());
  EXPECT_EQ(deleter->destroyed(), 0u);
  // Queued behind the blocked one: destroyed once it finishes, at the latest by the
  // deleter's destructor (which drains, then joins).
  for (int k = 0; k < 5; ++k) deleter->Retire(std::make_unique<Counted>(&counted_destroyed));
  deleter->Retire(std::unique_ptr<Counted>());  // nothing: ignored
  EXPECT_EQ(counted_destroyed.load(), 0);
  gate.set_value();
  deleter.reset();
  EXPECT_EQ(counted_destroyed.load(), 5);
}

}  // namespace
}  // namespace hapco
