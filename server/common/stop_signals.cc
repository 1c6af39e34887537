#include "common/stop_signals.h"

#include <signal.h>
#include <unistd.h>

#include <cerrno>
#include <cstdio>
#include <stdexcept>

namespace hapco {
namespace {

int g_pipe[2] = {-1, -1};

extern "C" void OnStopSignal(int signal) {
  const unsigned char value = static_cast<unsigned char>(signal);
  const ssize_t ignored = write(g_pipe[1], &value, 1);
  (void)ignored;
}

}  // namespace

StopSignals::StopSignals() {
  if (g_pipe[0] >= 0) throw std::logic_error("StopSignals: one instance per process");
  if (pipe(g_pipe) != 0) throw std::runtime_error("pipe() failed");
  struct sigaction action {};
  action.sa_handler = &OnStopSignal;
  sigemptyset(&action.sa_mask);
  action.sa_flags = SA_RESTART;
  sigaction(SIGINT, &action, nullptr);
  sigaction(SIGTERM, &action, nullptr);
}

StopSignals::Watching::~Watching() {
  if (thread_.joinable()) {
    const unsigned char zero = 0;  // "no signal": ends the thread without on_stop
    if (write(g_pipe[1], &zero, 1) != 1) std::perror("StopSignals: write");
    thread_.join();
  }
}

StopSignals::Watching StopSignals::Watch(std::function<void()> on_stop) {
  return Watching(std::thread([this, on_stop = std::move(on_stop)] {
    unsigned char value = 0;
    while (read(g_pipe[0], &value, 1) < 0 && errno == EINTR) {
    }
    if (value == 0) return;
    received_ = value;
    on_stop();
  }));
}

const char* StopSignals::ReceivedName(const char* otherwise) const {
  switch (received_.load()) {
    case SIGINT: return "SIGINT";
    case SIGTERM: return "SIGTERM";
    default: return otherwise;
  }
}

}  // namespace hapco
