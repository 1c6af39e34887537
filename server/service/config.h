#pragma once
// Cyclone DDS configuration for loopback tests and containers, and per-test domain ids.
// Why: with multicast off (loopback, containers) Cyclone only discovers peers it is told
// about, and only with ParticipantIndex auto; MaxAutoParticipantIndex defaults to 9, i.e.
// 10 processes per host (platform-notes.md). docker/cyclonedds-loopback.xml holds the same
// settings as a file for CYCLONEDDS_URI=file://...
#include <dds/dds.h>

#include <string>
#include <string_view>

namespace hapco::service {

// Highest participant index (= processes per host - 1) of the loopback config.
inline constexpr int kLoopbackMaxParticipantIndex = 50;

// <CycloneDDS><Domain id="any"> on interface "lo", multicast off, peer 127.0.0.1,
// ParticipantIndex auto, MaxAutoParticipantIndex = max_participant_index.
// Usable as CYCLONEDDS_URI value or as the config of dds_create_domain.
std::string LoopbackConfigXml(int max_participant_index = kLoopbackMaxParticipantIndex);

// setenv("CYCLONEDDS_URI", LoopbackConfigXml()): call before the first participant of a
// domain is created (Cyclone reads the variable when it creates the domain).
void UseLoopbackConfig();

// A domain id in [1, 230] from a name (FNV-1a hash), so that tests that run in parallel use
// different domains and hence different UDP ports (port = 7400 + 250 * domain + ...; 230
// keeps every port of the domain below 65536).
dds_domainid_t DomainIdForName(std::string_view name);

}  // namespace hapco::service
