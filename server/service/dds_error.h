#pragma once
// DDS return codes turned into exceptions. Used at setup time only (creating entities,
// setting QoS, waiting for discovery): the 1 kHz path checks the dds_return_t of dds_write /
// dds_take itself and counts failures, it never throws (design.md, example 2).
#include <dds/dds.h>

#include <stdexcept>
#include <string>
#include <string_view>

namespace hapco::service {

class DdsError : public std::runtime_error {
 public:
  DdsError(std::string_view what, dds_return_t code);
  dds_return_t code() const { return code_; }

 private:
  dds_return_t code_;
};

// Throws DdsError("<what>: <dds_strretcode(rc)> (<rc>)") when rc < 0, else returns rc.
dds_return_t CheckReturn(dds_return_t rc, std::string_view what);
// The same for calls that return an entity handle (negative = error code).
dds_entity_t CheckEntity(dds_entity_t entity, std::string_view what);

}  // namespace hapco::service
