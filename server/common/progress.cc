#include "common/progress.h"

#include <mutex>
#include <utility>

namespace hapco {
namespace {

std::mutex& SinkMutex() {
  static std::mutex mutex;
  return mutex;
}

std::function<void(const std::string&)>& Sink() {
  static std::function<void(const std::string&)> sink;
  return sink;
}

}  // namespace

void SetProgressSink(std::function<void(const std::string& line)> sink) {
  const std::lock_guard<std::mutex> lock(SinkMutex());
  Sink() = std::move(sink);
}

void ReportProgress(const std::string& line) {
  const std::lock_guard<std::mutex> lock(SinkMutex());
  if (Sink()) Sink()(line);
}

}  // namespace hapco
