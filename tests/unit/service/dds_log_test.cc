// Cyclone's own log lines are rate limited per call site (service/dds_log.h): a link that went
// down printed one "ddsi_udp_conn_write ... failed" line per write, 2 996 in 3 s.
#include "service/dds_log.h"

#include <dds/dds.h>
#include <gtest/gtest.h>

#include <string>

namespace hapco::service {
namespace {

int CountOf(const std::string& text, const std::string& what) {
  int count = 0;
  for (std::size_t at = text.find(what); at != std::string::npos; at = text.find(what, at + 1)) ++count;
  return count;
}

TEST(DdsLogLimiter, ACallSiteRepeatingItselfIsHeldBackAndSendFailuresAreCounted) {
  InstallDdsLogLimiter();
  InstallDdsLogLimiter();  // idempotent
  const std::uint64_t failures_before = DdsSendFailuresLogged();
  const std::uint64_t suppressed_before = DdsLogLinesSuppressed();
  testing::internal::CaptureStderr();
  for (int k = 0; k < 100; ++k) {
    dds_log(DDS_LC_WARNING, "ddsi_udp.c", 4242, "ddsi_udp_conn_write",
            "ddsi_udp_conn_write to udp/10.77.0.1:7410 failed with retcode -1\n");
  }
  dds_log(DDS_LC_ERROR, "other.c", 7, "other", "a different warning\n");
  const std::string printed = testing::internal::GetCapturedStderr();
  EXPECT_EQ(CountOf(printed, "ddsi_udp_conn_write to udp/10.77.0.1:7410 failed"), 5) << printed;
  EXPECT_EQ(CountOf(printed, "a different warning"), 1) << "another call site has its own budget";
  EXPECT_EQ(DdsSendFailuresLogged() - failures_before, 100u) << "every failed send is counted, printed or not";
  EXPECT_EQ(DdsLogLinesSuppressed() - suppressed_before, 95u);
}

}  // namespace
}  // namespace hapco::service
