#pragma once
// The HapCo topics: generated C type (idl/hapco_types.idl) -> descriptor, topic name and QoS
// profile (qos.h, docs/dds-qos.md).
#include <dds/dds.h>

#include "hapco_types.h"
#include "service/qos.h"

namespace hapco::service {

template <typename T>
struct TopicTraits;  // specialised for each topic type below

// client -> server, 1 kHz, default partition (the server reads every client's poses).
template <>
struct TopicTraits<hapco_idl_DevicePose> {
  static constexpr const char* kName = "hapco/pose";
  static const dds_topic_descriptor_t* Descriptor() { return &hapco_idl_DevicePose_desc; }
  static Qos DefaultQos() { return PoseQos(); }
};

// server -> client, 1 kHz, partition ClientPartition(client_id).
template <>
struct TopicTraits<hapco_idl_FeedbackForce> {
  static constexpr const char* kName = "hapco/force";
  static const dds_topic_descriptor_t* Descriptor() { return &hapco_idl_FeedbackForce_desc; }
  static Qos DefaultQos() { return ForceQos(); }
};

// server -> recorder, per step, partition ClientPartition(client_id); a recorder subscribes
// to kAllClientsPartition.
template <>
struct TopicTraits<hapco_idl_ContactStateFrame> {
  static constexpr const char* kName = "hapco/contact_state";
  static const dds_topic_descriptor_t* Descriptor() { return &hapco_idl_ContactStateFrame_desc; }
  static Qos DefaultQos() { return ContactStateQos(); }
};

// client -> server, default partition.
template <>
struct TopicTraits<hapco_idl_SessionControl> {
  static constexpr const char* kName = "hapco/session";
  static const dds_topic_descriptor_t* Descriptor() { return &hapco_idl_SessionControl_desc; }
  static Qos DefaultQos() { return SessionQos(); }
};

// server -> anyone, ~1 Hz, default partition.
template <>
struct TopicTraits<hapco_idl_ServerStatus> {
  static constexpr const char* kName = "hapco/status";
  static const dds_topic_descriptor_t* Descriptor() { return &hapco_idl_ServerStatus_desc; }
  static Qos DefaultQos() { return StatusQos(); }
};

}  // namespace hapco::service
