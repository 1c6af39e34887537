#pragma once
// Progress of long computations inside the libraries (a scene's precomputation can take
// minutes on a user's mesh), for the tools to show. A library reports; a tool decides where it
// goes (hapco-scene, hapco-sim and hapco-server send it to stderr). Without a sink, nothing is
// printed: tests and embedding programs stay quiet.
#include <functional>
#include <string>

namespace hapco {

// Sets the process's progress sink (empty: none). Call before the long work starts, from one
// thread; ReportProgress may then be called from any thread.
void SetProgressSink(std::function<void(const std::string& line)> sink);

// Sends one line to the sink, if there is one.
void ReportProgress(const std::string& line);

}  // namespace hapco
