#include "service/config.h"

#include <cstdint>
#include <cstdlib>

#include "common/error.h"

namespace hapco::service {

std::string LoopbackConfigXml(int max_participant_index) {
  if (max_participant_index < 0 || max_participant_index > 119) {
    throw InputError("MaxAutoParticipantIndex must be in [0, 119] (two unicast ports per "
                     "participant must fit in the 250 ports of a domain), got " +
                     std::to_string(max_participant_index));
  }
  return "<CycloneDDS><Domain id=\"any\">"
         "<General><Interfaces><NetworkInterface name=\"lo\"/></Interfaces>"
         "<AllowMulticast>false</AllowMulticast></General>"
         "<Discovery><ParticipantIndex>auto</ParticipantIndex>"
         "<MaxAutoParticipantIndex>" +
         std::to_string(max_participant_index) +
         "</MaxAutoParticipantIndex>"
         "<Peers><Peer address=\"127.0.0.1\"/></Peers></Discovery>"
         "</Domain></CycloneDDS>";
}

void UseLoopbackConfig() {
  const std::string xml = LoopbackConfigXml();
  HAPCO_ASSERT(setenv("CYCLONEDDS_URI", xml.c_str(), 1) == 0, "setenv(CYCLONEDDS_URI) failed");
}

dds_domainid_t DomainIdForName(std::string_view name) {
  uint32_t hash = 2166136261u;  // FNV-1a, 32 bit
  for (char c : name) {
    hash ^= static_cast<unsigned char>(c);
    hash *= 16777619u;
  }
  return 1 + hash % 230;
}

}  // namespace hapco::service
