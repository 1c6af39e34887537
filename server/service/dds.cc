#include "service/dds.h"

#include <cstring>

#include "common/error.h"
#include "service/dds_log.h"

namespace hapco::service {

Domain::Domain(dds_domainid_t domain_id, const std::string& config)
    : entity_(CheckEntity(dds_create_domain(domain_id, config.c_str()),
                          "dds_create_domain(" + std::to_string(domain_id) + ")")) {}

namespace {

dds_entity_t CreateParticipant(dds_domainid_t domain_id, const SecurityIdentity& identity) {
  InstallDdsLogLimiter();  // before DDS starts its threads and logs
  if (!identity.enabled()) return dds_create_participant(domain_id, nullptr, nullptr);
  std::unique_ptr<dds_qos_t, decltype(&dds_delete_qos)> qos(CreateSecurityQos(identity), &dds_delete_qos);
  const dds_entity_t participant = dds_create_participant(domain_id, qos.get(), nullptr);
  if (participant < 0) {
    throw DdsError("secured participant '" + identity.name + "' (" + identity.dir +
                       "): DDS-Security refused its identity, permissions or governance (signed by other CAs? "
                       "outside the grant's validity?)",
                   participant);
  }
  return participant;
}

}  // namespace

Participant::Participant(dds_domainid_t domain_id, const SecurityIdentity& identity)
    : entity_(CheckEntity(CreateParticipant(domain_id, identity),
                          "dds_create_participant(domain " + std::to_string(domain_id) +
                              "; check CYCLONEDDS_URI)")),
      domain_id_(domain_id) {}

Publisher::Publisher(const Participant& participant, std::string_view partition)
    : entity_(CheckEntity(
          dds_create_publisher(participant.handle(),
                               partition.empty() ? nullptr : PartitionQos(partition).get(), nullptr),
          "dds_create_publisher(partition '" + std::string(partition) + "')")) {}

Subscriber::Subscriber(const Participant& participant, std::string_view partition)
    : entity_(CheckEntity(
          dds_create_subscriber(participant.handle(),
                                partition.empty() ? nullptr : PartitionQos(partition).get(), nullptr),
          "dds_create_subscriber(partition '" + std::string(partition) + "')")) {}

namespace detail {

uint32_t MatchedCount(dds_entity_t reader_or_writer, bool is_writer) {
  if (is_writer) {
    dds_publication_matched_status_t status;
    CheckReturn(dds_get_publication_matched_status(reader_or_writer, &status),
                "dds_get_publication_matched_status");
    return status.current_count;
  }
  dds_subscription_matched_status_t status;
  CheckReturn(dds_get_subscription_matched_status(reader_or_writer, &status),
              "dds_get_subscription_matched_status");
  return status.current_count;
}

bool WaitForMatched(dds_entity_t reader_or_writer, bool is_writer, uint32_t count,
                    dds_duration_t timeout_ns) {
  const uint32_t mask = is_writer ? DDS_PUBLICATION_MATCHED_STATUS : DDS_SUBSCRIPTION_MATCHED_STATUS;
  const dds_time_t deadline = dds_time() + timeout_ns;
  Entity waitset(CheckEntity(dds_create_waitset(dds_get_participant(reader_or_writer)),
                             "dds_create_waitset"));
  // The entity triggers the waitset while a status in its mask is set. Only the matched
  // status (reset by reading it): any other status left set (e.g. data available, which a
  // listener never resets for the waitset) would wake the wait at once, for ever.
  uint32_t old_mask = 0;
  CheckReturn(dds_get_status_mask(reader_or_writer, &old_mask), "dds_get_status_mask");
  CheckReturn(dds_set_status_mask(reader_or_writer, mask), "dds_set_status_mask");
  CheckReturn(dds_waitset_attach(waitset.handle(), reader_or_writer, 0), "dds_waitset_attach");
  bool matched = false;
  for (;;) {
    // Reading the status resets its "changed" flag, so check after each wake-up.
    if (MatchedCount(reader_or_writer, is_writer) >= count) {
      matched = true;
      break;
    }
    if (dds_time() >= deadline) break;  // also when spurious wake-ups never let the wait time out
    const dds_return_t n = dds_waitset_wait_until(waitset.handle(), nullptr, 0, deadline);
    CheckReturn(n, "dds_waitset_wait_until");
  }
  dds_waitset_detach(waitset.handle(), reader_or_writer);
  dds_set_status_mask(reader_or_writer, old_mask);
  return matched;
}

}  // namespace detail

WaitSet::WaitSet(const Participant& participant)
    : waitset_(CheckEntity(dds_create_waitset(participant.handle()), "dds_create_waitset")),
      guard_(CheckEntity(dds_create_guardcondition(participant.handle()),
                         "dds_create_guardcondition")) {
  CheckReturn(dds_waitset_attach(waitset_.handle(), guard_.handle(), kWakeToken),
              "dds_waitset_attach(guard)");
}

void WaitSet::Attach(dds_entity_t condition, dds_attach_t token) {
  CheckReturn(dds_waitset_attach(waitset_.handle(), condition, token), "dds_waitset_attach");
}

int WaitSet::Wait(dds_duration_t timeout_ns, dds_attach_t* tokens, size_t capacity) {
  const dds_return_t n = dds_waitset_wait(waitset_.handle(), tokens, capacity, timeout_ns);
  CheckReturn(n, "dds_waitset_wait");
  bool triggered = false;
  // A guard condition stays triggered until taken; take it so the next Wait blocks again.
  dds_take_guardcondition(guard_.handle(), &triggered);
  return n;
}

void WaitSet::Wake() {
  CheckReturn(dds_set_guardcondition(guard_.handle(), true), "dds_set_guardcondition");
}

void ReserveContacts(hapco_idl_ContactStateFrame* frame, uint32_t capacity) {
  HAPCO_ASSERT(frame != nullptr, "ReserveContacts: null frame");
  if (capacity > hapco_idl_MAX_CONTACT_SAMPLES) {
    throw InputError("contact capacity " + std::to_string(capacity) + " exceeds the IDL bound " +
                     std::to_string(hapco_idl_MAX_CONTACT_SAMPLES));
  }
  dds_sequence_hapco_idl_ContactSample& seq = frame->contacts;
  if (seq._release && seq._buffer != nullptr) dds_free(seq._buffer);
  seq._buffer = (capacity > 0) ? static_cast<hapco_idl_ContactSample*>(dds_alloc(capacity * sizeof(hapco_idl_ContactSample))) : nullptr;
  seq._maximum = capacity;
  seq._length = 0;
  seq._release = true;
}

void SetClientId(char (&field)[65], std::string_view client_id) {
  ValidateClientId(client_id);
  std::memset(field, 0, sizeof(field));
  std::memcpy(field, client_id.data(), client_id.size());
}

}  // namespace hapco::service
