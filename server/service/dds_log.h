#pragma once
// Cyclone DDS's own log lines (errors, warnings, info) on stderr, rate limited per call site.
// A link that went down made Cyclone print "ddsi_udp_conn_write to udp/... failed with
// retcode -1" on every write: 2 996 lines in 3 s from one phantom (a helper session), which
// buried the tool's own lines. Each call site may print 5 lines at once and one every 10 s
// after that; the next line it prints says how many were held back. Installed by the first
// Participant (service/dds.h), for the whole process.
#include <cstdint>

namespace hapco::service {

// Routes Cyclone's log through the limiter (idempotent; thread safe).
void InstallDdsLogLimiter();

// Lines Cyclone logged about a failed network send (ddsi_udp_conn_write ... failed), printed or
// not: a DDS write that returned OK can still fail in the transport.
std::uint64_t DdsSendFailuresLogged();

// Cyclone log lines held back by the limiter so far.
std::uint64_t DdsLogLinesSuppressed();

}  // namespace hapco::service
