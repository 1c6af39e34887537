#pragma once
// Secured DDS (OMG DDS-Security, Cyclone DDS 0.10.2's builtin plugins): the identity a
// participant runs with, checked before DDS sees it, and the participant QoS that carries it.
// A deployment directory is made by scripts/dds-security (docs/security.md):
//   DIR/public/{identity_ca.pem, permissions_ca.pem, crl.pem, governance.xml.p7s}: what every
//   participant reads (no secret), DIR/NAME/{cert.pem, key.pem, permissions.xml.p7s} for NAME =
//   server, recorder, monitor and each client id (a participant needs public/ and its own
//   NAME/ only), DIR/ca/: the CA keys, never given to a participant.
#include <dds/dds.h>

#include <string>

namespace hapco::service {

struct SecurityIdentity {
  std::string dir;   // deployment directory (scripts/dds-security init DIR)
  std::string name;  // server | recorder | monitor | a client id
  bool enabled() const { return !dir.empty(); }
};

// Throws InputError with one line naming the file and what to fix when a file is missing or
// unreadable, the certificate is not yet valid or expired (local clock, as Cyclone checks),
// its common name is not `name` (a client must not run under another client's identity), or
// it is not signed by the deployment's identity CA.
void ValidateSecurityIdentity(const SecurityIdentity& identity);

// A participant QoS with the dds.sec.* properties of `identity` (after validation). The
// caller owns it (dds_delete_qos).
dds_qos_t* CreateSecurityQos(const SecurityIdentity& identity);

}  // namespace hapco::service
