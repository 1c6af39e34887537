// Unit tests of hapco::service that create no DDS entity: QoS profiles read back through the
// Cyclone getters, partition names, client-id validation, loopback config, error texts.
#include <gtest/gtest.h>

#include <set>
#include <string>

#include "common/error.h"
#include "service/config.h"
#include "service/dds.h"
#include "service/qos.h"

namespace hapco::service {
namespace {

struct Expected {
  dds_reliability_kind_t reliability;
  dds_duration_t max_blocking_ns;
  int32_t depth;
  dds_durability_kind_t durability;
};

void ExpectProfile(const Qos& qos, const Expected& e) {
  dds_reliability_kind_t kind{};
  dds_duration_t blocking = -1;
  ASSERT_TRUE(qos.GetReliability(&kind, &blocking));
  EXPECT_EQ(kind, e.reliability);
  if (e.reliability == DDS_RELIABILITY_RELIABLE) {
    EXPECT_EQ(blocking, e.max_blocking_ns);
  }
  dds_history_kind_t history{};
  int32_t depth = 0;
  ASSERT_TRUE(qos.GetHistory(&history, &depth));
  EXPECT_EQ(history, DDS_HISTORY_KEEP_LAST);
  EXPECT_EQ(depth, e.depth);
  dds_durability_kind_t durability{};
  ASSERT_TRUE(qos.GetDurability(&durability));
  EXPECT_EQ(durability, e.durability);
  dds_duration_t budget = -1;
  ASSERT_TRUE(qos.GetLatencyBudget(&budget));
  EXPECT_EQ(budget, 0);  // non-zero would let Cyclone delay the send (platform-notes.md)
}

TEST(QosProfiles, MatchTheDocumentedTable) {
  // Values from docs/dds-qos.md, the table the server and clients are written against.
  ExpectProfile(PoseQos(), {DDS_RELIABILITY_BEST_EFFORT, 0, 1, DDS_DURABILITY_VOLATILE});
  ExpectProfile(ForceQos(), {DDS_RELIABILITY_BEST_EFFORT, 0, 1, DDS_DURABILITY_VOLATILE});
  ExpectProfile(ContactStateQos(), {DDS_RELIABILITY_RELIABLE, 0, 8, DDS_DURABILITY_TRANSIENT_LOCAL});
  ExpectProfile(ContactStateQos(3), {DDS_RELIABILITY_RELIABLE, 0, 3, DDS_DURABILITY_TRANSIENT_LOCAL});
  ExpectProfile(StatusQos(), {DDS_RELIABILITY_RELIABLE, 0, 1, DDS_DURABILITY_TRANSIENT_LOCAL});
  ExpectProfile(SessionQos(), {DDS_RELIABILITY_RELIABLE, 0, 8, DDS_DURABILITY_VOLATILE});
  // ServerStatus alone carries a liveliness lease: clients know a killed server is gone 50 ms
  // after its last message; the streams keep Cyclone's default (automatic, infinite).
  dds_liveliness_kind_t liveliness{};
  dds_duration_t lease_ns = 0;
  ASSERT_TRUE(StatusQos().GetLiveliness(&liveliness, &lease_ns));
  EXPECT_EQ(liveliness, DDS_LIVELINESS_AUTOMATIC);
  EXPECT_EQ(lease_ns, DDS_MSECS(50));
  EXPECT_FALSE(ForceQos().GetLiveliness(&liveliness, &lease_ns));
}

TEST(QosProfiles, CopyAndMoveKeepThePolicies) {
  Qos original = StatusQos();
  Qos copy = original;
  Qos moved = std::move(original);
  for (const Qos* q : {&copy, &moved}) {
    dds_durability_kind_t durability{};
    ASSERT_TRUE(q->GetDurability(&durability));
    EXPECT_EQ(durability, DDS_DURABILITY_TRANSIENT_LOCAL);
  }
  copy = ForceQos();
  dds_reliability_kind_t kind{};
  dds_duration_t blocking = 0;
  ASSERT_TRUE(copy.GetReliability(&kind, &blocking));
  EXPECT_EQ(kind, DDS_RELIABILITY_BEST_EFFORT);
}

TEST(QosProfiles, RejectsNonPositiveDepth) {
  EXPECT_THROW(ContactStateQos(0), InputError);
}

TEST(Partitions, ClientPartitionNameAndWildcard) {
  EXPECT_EQ(ClientPartition("phantom-1"), "hapco/client/phantom-1");
  EXPECT_EQ(PartitionQos(ClientPartition("a.b_c")).GetPartition(), "hapco/client/a.b_c");
  EXPECT_EQ(std::string(kAllClientsPartition), std::string(kClientPartitionPrefix) + "*");
}

TEST(Partitions, ClientIdValidation) {
  EXPECT_NO_THROW(ValidateClientId(std::string(64, 'x')));
  EXPECT_THROW(ValidateClientId(std::string(65, 'x')), InputError);  // string<64> key
  EXPECT_THROW(ValidateClientId(""), InputError);
  EXPECT_THROW(ValidateClientId("a*"), InputError);  // partition wildcard
  EXPECT_THROW(ValidateClientId("a?"), InputError);
  EXPECT_THROW(ValidateClientId("a/b"), InputError);
  try {
    ClientPartition("bad id");
    FAIL() << "expected InputError";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("letters, digits"), std::string::npos) << e.what();
  }
}

TEST(Samples, SetClientIdTerminatesAndValidates) {
  char field[65];
  std::fill(std::begin(field), std::end(field), 'z');
  SetClientId(field, "abc");
  EXPECT_STREQ(field, "abc");
  SetClientId(field, std::string(64, 'q'));
  EXPECT_EQ(std::string(field), std::string(64, 'q'));
  EXPECT_EQ(field[64], '\0');
  EXPECT_THROW(SetClientId(field, "no spaces"), InputError);
}

TEST(Samples, ReserveContactsRespectsTheIdlBound) {
  auto frame = MakeSample<hapco_idl_ContactStateFrame>();
  ReserveContacts(frame.get(), 1024);
  EXPECT_EQ(frame->contacts._maximum, 1024u);
  EXPECT_EQ(frame->contacts._length, 0u);
  ASSERT_NE(frame->contacts._buffer, nullptr);
  frame->contacts._buffer[1023].id = 7;  // the whole buffer is writable (ASan checks this)
  ReserveContacts(frame.get(), 16);      // frees the previous buffer
  EXPECT_EQ(frame->contacts._maximum, 16u);
  EXPECT_THROW(ReserveContacts(frame.get(), 1025), InputError);
}

TEST(Config, LoopbackXmlHasTheDiscoverySettings) {
  const std::string xml = LoopbackConfigXml(42);
  for (const char* needle :
       {"<NetworkInterface name=\"lo\"/>", "<AllowMulticast>false</AllowMulticast>",
        "<ParticipantIndex>auto</ParticipantIndex>",
        "<MaxAutoParticipantIndex>42</MaxAutoParticipantIndex>", "<Peer address=\"127.0.0.1\"/>"}) {
    EXPECT_NE(xml.find(needle), std::string::npos) << needle;
  }
  EXPECT_THROW(LoopbackConfigXml(120), InputError);  // ports would spill into the next domain
}

TEST(Config, DomainIdsAreInRangeAndSpread) {
  std::set<dds_domainid_t> ids;
  for (int i = 0; i < 100; ++i) {
    const dds_domainid_t id = DomainIdForName("Suite.Test" + std::to_string(i));
    EXPECT_GE(id, 1u);
    EXPECT_LE(id, 230u);
    ids.insert(id);
  }
  EXPECT_EQ(DomainIdForName("same"), DomainIdForName("same"));
  // 100 names into 230 slots: a uniform hash leaves ~81 distinct values; 60 catches a hash
  // that collapses (e.g. ignores the suffix).
  EXPECT_GT(ids.size(), 60u);
}

TEST(Errors, CheckReturnCarriesTheDdsText) {
  // Texts as printed by Cyclone's dds_strretcode.
  try {
    CheckReturn(DDS_RETCODE_BAD_PARAMETER, "dds_write(pose)");
    FAIL() << "expected DdsError";
  } catch (const DdsError& e) {
    EXPECT_EQ(e.code(), DDS_RETCODE_BAD_PARAMETER);
    const std::string what = e.what();
    EXPECT_NE(what.find("dds_write(pose)"), std::string::npos) << what;
    EXPECT_NE(what.find("Bad Parameter"), std::string::npos) << what;
  }
  EXPECT_EQ(CheckReturn(5, "ok"), 5);
  EXPECT_EQ(CheckEntity(123, "ok"), 123);
  EXPECT_THROW(CheckEntity(DDS_RETCODE_PRECONDITION_NOT_MET, "x"), DdsError);
}

}  // namespace
}  // namespace hapco::service
