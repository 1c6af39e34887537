#include "service/dds_error.h"

namespace hapco::service {

namespace {
std::string Message(std::string_view what, dds_return_t code) {
  std::string message(what);
  message += ": ";
  message += dds_strretcode(code);
  message += " (DDS return code " + std::to_string(code) + ")";
  if (code == DDS_RETCODE_NOT_ALLOWED_BY_SECURITY) {
    message += ": this participant's DDS-Security permissions do not grant it (a client may write and read only "
               "its own partition: run it with the identity of its own client id, docs/security.md)";
  }
  return message;
}
}  // namespace

DdsError::DdsError(std::string_view what, dds_return_t code)
    : std::runtime_error(Message(what, code)), code_(code) {}

dds_return_t CheckReturn(dds_return_t rc, std::string_view what) {
  if (rc < 0) throw DdsError(what, rc);
  return rc;
}

dds_entity_t CheckEntity(dds_entity_t entity, std::string_view what) {
  if (entity < 0) throw DdsError(what, entity);
  return entity;
}

}  // namespace hapco::service
