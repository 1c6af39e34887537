#pragma once
// RAII wrappers over the Cyclone DDS C API (there is no C++ binding in Debian,
// platform-notes.md). Construction = setup: every failure throws DdsError with the
// dds_strretcode text. Hot-path calls (Writer::Write, Reader::Take) are noexcept and return
// the DDS result; the caller counts failures.
//
// Lifetime: every wrapper deletes its entity in its destructor. Destroy children before
// their participant (declare the participant first); deleting a participant also deletes
// everything it owns, after which a child's own dds_delete is a harmless no-op.
#include <dds/dds.h>

#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <string_view>
#include <utility>

#include "service/dds_error.h"
#include "service/qos.h"
#include "service/security.h"
#include "service/topics.h"

namespace hapco::service {

// A DDS entity handle, deleted on destruction. Move-only.
class Entity {
 public:
  Entity() = default;
  explicit Entity(dds_entity_t handle) : handle_(handle) {}
  ~Entity() { Reset(); }
  Entity(const Entity&) = delete;
  Entity& operator=(const Entity&) = delete;
  Entity(Entity&& other) noexcept : handle_(std::exchange(other.handle_, 0)) {}
  Entity& operator=(Entity&& other) noexcept {
    if (this != &other) {
      Reset();
      handle_ = std::exchange(other.handle_, 0);
    }
    return *this;
  }
  dds_entity_t handle() const { return handle_; }
  void Reset() {
    if (handle_ > 0) dds_delete(handle_);  // result ignored: the parent may be gone already
    handle_ = 0;
  }

 private:
  dds_entity_t handle_ = 0;
};

// An explicitly configured domain (dds_create_domain): `config` is XML or "file://path".
// Participants created afterwards in `domain_id` use it. Throws if the domain exists already.
class Domain {
 public:
  Domain(dds_domainid_t domain_id, const std::string& config);
  dds_entity_t handle() const { return entity_.handle(); }

 private:
  Entity entity_;
};

class Participant {
 public:
  // Uses CYCLONEDDS_URI (or the Domain created before) for the configuration. With an
  // enabled `identity` the participant is secured (service/security.h): the identity is
  // checked first (InputError with what to fix), then DDS-Security authenticates it.
  explicit Participant(dds_domainid_t domain_id, const SecurityIdentity& identity = {});
  dds_entity_t handle() const { return entity_.handle(); }
  dds_domainid_t domain_id() const { return domain_id_; }

 private:
  Entity entity_;
  dds_domainid_t domain_id_;
};

// A publisher / subscriber in one partition ("" = the default partition).
class Publisher {
 public:
  explicit Publisher(const Participant& participant, std::string_view partition = {});
  dds_entity_t handle() const { return entity_.handle(); }

 private:
  Entity entity_;
};

class Subscriber {
 public:
  explicit Subscriber(const Participant& participant, std::string_view partition = {});
  dds_entity_t handle() const { return entity_.handle(); }

 private:
  Entity entity_;
};

template <typename T>
class Topic {
 public:
  // The name and QoS default to the HapCo topic of T (topics.h).
  explicit Topic(const Participant& participant,
                 std::string_view name = TopicTraits<T>::kName,
                 const Qos& qos = TopicTraits<T>::DefaultQos())
      : entity_(CheckEntity(dds_create_topic(participant.handle(), TopicTraits<T>::Descriptor(),
                                             std::string(name).c_str(), qos.get(), nullptr),
                            "dds_create_topic(" + std::string(name) + ")")) {}
  dds_entity_t handle() const { return entity_.handle(); }

 private:
  Entity entity_;
};

namespace detail {
// Blocks until the matched count (publication or subscription matched status) reaches
// `count`, or `timeout_ns` elapses. Setup-time helper: creates a waitset.
bool WaitForMatched(dds_entity_t reader_or_writer, bool is_writer, uint32_t count,
                    dds_duration_t timeout_ns);
uint32_t MatchedCount(dds_entity_t reader_or_writer, bool is_writer);
}  // namespace detail

template <typename T>
class Writer {
 public:
  Writer(const Publisher& publisher, const Topic<T>& topic,
         const Qos& qos = TopicTraits<T>::DefaultQos())
      : entity_(CheckEntity(dds_create_writer(publisher.handle(), topic.handle(), qos.get(), nullptr),
                            std::string("dds_create_writer(") + TopicTraits<T>::kName + ")")) {}
  dds_entity_t handle() const { return entity_.handle(); }

  // Hot path. DDS_RETCODE_OK, or e.g. DDS_RETCODE_TIMEOUT when a reliable writer with
  // max_blocking_time 0 drops the sample instead of waiting (qos.h, ContactStateQos).
  dds_return_t Write(const T& sample) noexcept { return dds_write(entity_.handle(), &sample); }

  // Waits until all written data is acknowledged by the matched reliable readers.
  // DDS_RETCODE_OK or DDS_RETCODE_TIMEOUT.
  dds_return_t WaitForAcks(dds_duration_t timeout_ns) {
    return dds_wait_for_acks(entity_.handle(), timeout_ns);
  }
  // Discovery: true once `count` readers are matched, false after timeout_ns.
  bool WaitForReaders(uint32_t count, dds_duration_t timeout_ns) {
    return detail::WaitForMatched(entity_.handle(), true, count, timeout_ns);
  }
  uint32_t MatchedReaders() const { return detail::MatchedCount(entity_.handle(), true); }

 private:
  Entity entity_;
};

template <typename T>
class Reader {
 public:
  Reader(const Subscriber& subscriber, const Topic<T>& topic,
         const Qos& qos = TopicTraits<T>::DefaultQos())
      : entity_(CheckEntity(dds_create_reader(subscriber.handle(), topic.handle(), qos.get(), nullptr),
                            std::string("dds_create_reader(") + TopicTraits<T>::kName + ")")),
        condition_(CheckEntity(dds_create_readcondition(entity_.handle(), DDS_ANY_STATE),
                               "dds_create_readcondition")),
        waitset_(CheckEntity(dds_create_waitset(dds_get_participant(entity_.handle())),
                             "dds_create_waitset")) {
    CheckReturn(dds_waitset_attach(waitset_.handle(), condition_.handle(), 0), "dds_waitset_attach");
  }
  dds_entity_t handle() const { return entity_.handle(); }
  // Triggered while the reader holds any sample; attach it to your own WaitSet to wait on
  // several readers at once.
  dds_entity_t data_condition() const { return condition_.handle(); }

  // Hot path: takes the oldest sample into *sample (deserialised in place: bounded strings
  // are inline arrays, and a sequence whose buffer is large enough is reused, so a sample
  // prepared once with MakeSample/ReserveContacts makes this allocation-free).
  // Returns true if a valid sample was taken; skips dispose/unregister notifications.
  bool Take(T* sample, dds_sample_info_t* info = nullptr) noexcept {
    dds_sample_info_t local_info;
    dds_sample_info_t* si = (info != nullptr) ? info : &local_info;
    for (;;) {
      void* buffer[1] = {sample};
      const dds_return_t n = dds_take(entity_.handle(), buffer, si, 1, 1);
      if (n <= 0) return false;
      if (si->valid_data) return true;
    }
  }

  // Blocks until the reader holds a sample or timeout_ns elapses (true = data available).
  bool WaitForData(dds_duration_t timeout_ns) {
    const dds_return_t n = dds_waitset_wait(waitset_.handle(), nullptr, 0, timeout_ns);
    CheckReturn(n, "dds_waitset_wait");
    return n > 0;
  }
  // Discovery: true once `count` writers are matched, false after timeout_ns.
  bool WaitForWriters(uint32_t count, dds_duration_t timeout_ns) {
    return detail::WaitForMatched(entity_.handle(), false, count, timeout_ns);
  }
  uint32_t MatchedWriters() const { return detail::MatchedCount(entity_.handle(), false); }

  // Calls `callback` on Cyclone's receive thread when data arrives (~30 us faster than a
  // waitset, platform-notes.md). The callback must not block nor create/delete entities;
  // it typically calls Take. Setup time only; replaces a previous callback.
  void SetOnDataAvailable(std::function<void()> callback) {
    auto holder = std::make_unique<std::function<void()>>(std::move(callback));
    std::swap(on_data_, holder);
    InstallListener();  // the previous callback (now in holder) is no longer referenced after this
  }
  // Calls `callback` on a Cyclone thread when a matched writer's liveliness changes (its lease
  // lapsed, or it is alive again): status.last_publication_handle is that writer (the
  // publication_handle of its samples), status.alive_count_change is -1 or +1. Same rules as
  // SetOnDataAvailable; both callbacks may be set.
  void SetOnLivelinessChanged(std::function<void(const dds_liveliness_changed_status_t&)> callback) {
    auto holder = std::make_unique<std::function<void(const dds_liveliness_changed_status_t&)>>(std::move(callback));
    std::swap(on_liveliness_, holder);
    InstallListener();
  }
  // Removes the listener; returns once no callback runs any more (dds_set_listener waits for
  // the callbacks in progress), so what the callback uses may be destroyed afterwards.
  void ClearListener() noexcept { dds_set_listener(entity_.handle(), nullptr); }

 private:
  void InstallListener() {
    dds_listener_t* listener = dds_create_listener(nullptr);
    if (on_data_) dds_lset_data_available_arg(listener, &Reader::OnDataAvailable, on_data_.get(), true);
    if (on_liveliness_) {
      dds_lset_liveliness_changed_arg(listener, &Reader::OnLivelinessChanged, on_liveliness_.get(), true);
    }
    const dds_return_t rc = dds_set_listener(entity_.handle(), listener);
    dds_delete_listener(listener);
    CheckReturn(rc, "dds_set_listener");
  }
  static void OnDataAvailable(dds_entity_t /*reader*/, void* arg) {
    (*static_cast<std::function<void()>*>(arg))();
  }
  static void OnLivelinessChanged(dds_entity_t /*reader*/, const dds_liveliness_changed_status_t status, void* arg) {
    (*static_cast<std::function<void(const dds_liveliness_changed_status_t&)>*>(arg))(status);
  }
  // Declared first so they are destroyed last: the reader (and its listener) goes before them.
  std::unique_ptr<std::function<void()>> on_data_;
  std::unique_ptr<std::function<void(const dds_liveliness_changed_status_t&)>> on_liveliness_;
  Entity entity_;
  Entity condition_;
  Entity waitset_;
};

// A waitset over several conditions (e.g. the data_condition() of many readers) plus a
// guard condition to wake it from another thread (shutdown).
class WaitSet {
 public:
  explicit WaitSet(const Participant& participant);
  void Attach(dds_entity_t condition, dds_attach_t token);
  // Number of triggered conditions (0 = timeout); their tokens in tokens[0..n).
  int Wait(dds_duration_t timeout_ns, dds_attach_t* tokens = nullptr, size_t capacity = 0);
  // Wakes Wait() from any thread; the token of the wake-up is kWakeToken.
  void Wake();
  static constexpr dds_attach_t kWakeToken = ~dds_attach_t{0};

 private:
  Entity waitset_;
  Entity guard_;
};

// --- Samples -------------------------------------------------------------------------------

template <typename T>
struct SampleDeleter {
  void operator()(T* sample) const noexcept {
    dds_sample_free(sample, TopicTraits<T>::Descriptor(), DDS_FREE_ALL);
  }
};
template <typename T>
using SamplePtr = std::unique_ptr<T, SampleDeleter<T>>;

// A zeroed sample owned by a unique_ptr that frees its sequences too (dds_sample_free).
template <typename T>
SamplePtr<T> MakeSample() {
  return SamplePtr<T>(static_cast<T*>(dds_alloc(sizeof(T))));
}

// Gives frame->contacts a buffer of `capacity` samples (length 0), so that filling it on
// the writer side and taking into it on the reader side never allocates.
// Throws InputError if capacity exceeds hapco_idl_MAX_CONTACT_SAMPLES.
void ReserveContacts(hapco_idl_ContactStateFrame* frame, uint32_t capacity);

// Copies client_id into a string<64> key field; throws InputError if it is not a valid id.
void SetClientId(char (&field)[65], std::string_view client_id);

}  // namespace hapco::service
