#include "service/qos.h"

#include <utility>

#include "common/error.h"

namespace hapco::service {

Qos::Qos() : qos_(dds_create_qos()) {}
Qos::~Qos() {
  if (qos_ != nullptr) dds_delete_qos(qos_);
}
Qos::Qos(const Qos& other) : qos_(dds_create_qos()) { dds_copy_qos(qos_, other.qos_); }
Qos& Qos::operator=(const Qos& other) {
  if (this != &other) {
    dds_reset_qos(qos_);
    dds_copy_qos(qos_, other.qos_);
  }
  return *this;
}
Qos::Qos(Qos&& other) noexcept : qos_(std::exchange(other.qos_, nullptr)) {}
Qos& Qos::operator=(Qos&& other) noexcept {
  std::swap(qos_, other.qos_);
  return *this;
}

Qos& Qos::Reliable(dds_duration_t max_blocking_ns) {
  dds_qset_reliability(qos_, DDS_RELIABILITY_RELIABLE, max_blocking_ns);
  return *this;
}
Qos& Qos::BestEffort() {
  dds_qset_reliability(qos_, DDS_RELIABILITY_BEST_EFFORT, 0);
  return *this;
}
Qos& Qos::KeepLast(int32_t depth) {
  if (depth < 1) throw InputError("KEEP_LAST history depth must be >= 1, got " + std::to_string(depth));
  dds_qset_history(qos_, DDS_HISTORY_KEEP_LAST, depth);
  return *this;
}
Qos& Qos::Volatile() {
  dds_qset_durability(qos_, DDS_DURABILITY_VOLATILE);
  return *this;
}
Qos& Qos::HistoricalDepth(int32_t depth) {
  dds_qset_durability_service(qos_, 0, DDS_HISTORY_KEEP_LAST, depth, DDS_LENGTH_UNLIMITED, DDS_LENGTH_UNLIMITED,
                              DDS_LENGTH_UNLIMITED);
  return *this;
}

Qos& Qos::TransientLocal() {
  dds_qset_durability(qos_, DDS_DURABILITY_TRANSIENT_LOCAL);
  return *this;
}
Qos& Qos::LatencyBudget(dds_duration_t budget_ns) {
  dds_qset_latency_budget(qos_, budget_ns);
  return *this;
}
Qos& Qos::AutomaticLiveliness(dds_duration_t lease_ns) {
  dds_qset_liveliness(qos_, DDS_LIVELINESS_AUTOMATIC, lease_ns);
  return *this;
}
Qos& Qos::Partition(std::string_view name) {
  const std::string copy(name);
  dds_qset_partition1(qos_, copy.c_str());
  return *this;
}

bool Qos::GetReliability(dds_reliability_kind_t* kind, dds_duration_t* max_blocking_ns) const {
  return dds_qget_reliability(qos_, kind, max_blocking_ns);
}
bool Qos::GetHistory(dds_history_kind_t* kind, int32_t* depth) const {
  return dds_qget_history(qos_, kind, depth);
}
bool Qos::GetDurability(dds_durability_kind_t* kind) const {
  return dds_qget_durability(qos_, kind);
}
bool Qos::GetLatencyBudget(dds_duration_t* budget_ns) const {
  return dds_qget_latency_budget(qos_, budget_ns);
}
bool Qos::GetLiveliness(dds_liveliness_kind_t* kind, dds_duration_t* lease_ns) const {
  return dds_qget_liveliness(qos_, kind, lease_ns);
}
std::string Qos::GetPartition() const {
  uint32_t n = 0;
  char** names = nullptr;
  if (!dds_qget_partition(qos_, &n, &names)) return {};
  std::string result = (n == 1) ? std::string(names[0]) : std::string();
  // dds_qget_partition hands out copies allocated with dds_alloc.
  for (uint32_t i = 0; i < n; ++i) dds_free(names[i]);
  dds_free(names);
  return result;
}

namespace {
// Best effort, keep-last 1, volatile, no latency budget: the 1 kHz streams (qos.h).
Qos StreamQos() {
  Qos q;
  q.BestEffort().KeepLast(1).Volatile().LatencyBudget(0);
  return q;
}
}  // namespace

Qos PoseQos() { return StreamQos(); }
Qos ForceQos() { return StreamQos(); }

Qos ContactStateQos(int32_t depth) {
  Qos q;
  q.Reliable(0).KeepLast(depth).TransientLocal().HistoricalDepth(depth).LatencyBudget(0);
  return q;
}

Qos StatusQos() {
  Qos q;
  q.Reliable(0).KeepLast(1).TransientLocal().LatencyBudget(0).AutomaticLiveliness(kServerLivelinessLeaseNs);
  return q;
}

Qos SessionQos() {
  Qos q;
  q.Reliable(0).KeepLast(8).Volatile().LatencyBudget(0);
  return q;
}

void ValidateClientId(std::string_view client_id) {
  if (client_id.empty() || client_id.size() > 64) {
    throw InputError("client id must have 1 to 64 characters, got " +
                     std::to_string(client_id.size()) + " ('" + std::string(client_id) + "')");
  }
  for (char c : client_id) {
    const bool ok = (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9') ||
                    c == '_' || c == '.' || c == '-';
    if (!ok) {
      throw InputError("client id '" + std::string(client_id) +
                       "' may only contain letters, digits, '_', '.' and '-' (it becomes part "
                       "of a DDS partition name, where '*' and '?' are wildcards)");
    }
  }
}

std::string ClientPartition(std::string_view client_id) {
  ValidateClientId(client_id);
  std::string name(kClientPartitionPrefix);
  name += client_id;
  return name;
}

Qos PartitionQos(std::string_view name) {
  Qos q;
  q.Partition(name);
  return q;
}

}  // namespace hapco::service
