#include "service/security.h"

#include <openssl/pem.h>
#include <openssl/x509.h>

#include <cstdio>
#include <filesystem>
#include <memory>

#include "common/error.h"

namespace hapco::service {
namespace {

using X509Ptr = std::unique_ptr<X509, decltype(&X509_free)>;

std::string FileOf(const SecurityIdentity& identity, const std::string& relative) {
  return (std::filesystem::path(identity.dir) / relative).string();
}

void RequireFile(const std::string& path, const std::string& what) {
  std::FILE* file = std::fopen(path.c_str(), "r");
  if (file == nullptr) {
    throw InputError("security: cannot read " + what + " " + path +
                     " (make the deployment with scripts/dds-security init DIR, or add-client DIR NAME)");
  }
  std::fclose(file);
}

X509Ptr ReadCertificate(const std::string& path, const std::string& what) {
  RequireFile(path, what);
  std::FILE* file = std::fopen(path.c_str(), "r");
  X509* certificate = PEM_read_X509(file, nullptr, nullptr, nullptr);
  std::fclose(file);
  if (certificate == nullptr) throw InputError("security: " + path + " is not a PEM certificate");
  return X509Ptr(certificate, &X509_free);
}

std::string CommonName(X509* certificate) {
  char name[256] = {0};
  if (X509_NAME_get_text_by_NID(X509_get_subject_name(certificate), NID_commonName, name, sizeof name) < 0) return "";
  return name;
}

}  // namespace

void ValidateSecurityIdentity(const SecurityIdentity& identity) {
  if (!std::filesystem::is_directory(identity.dir)) {
    throw InputError("security: no deployment directory " + identity.dir + " (scripts/dds-security init DIR)");
  }
  const std::string cert_path = FileOf(identity, identity.name + "/cert.pem");
  if (!std::filesystem::exists(cert_path)) {
    throw InputError("security: no identity '" + identity.name + "' in " + identity.dir +
                     " (scripts/dds-security add-client " + identity.dir + " " + identity.name + ")");
  }
  const X509Ptr certificate = ReadCertificate(cert_path, "the identity certificate");
  const X509Ptr ca = ReadCertificate(FileOf(identity, "public/identity_ca.pem"), "the identity CA");
  const std::string key_path = FileOf(identity, identity.name + "/key.pem");
  RequireFile(key_path, "the private key");
  RequireFile(FileOf(identity, identity.name + "/permissions.xml.p7s"), "the signed permissions");
  RequireFile(FileOf(identity, "public/governance.xml.p7s"), "the signed governance");
  RequireFile(FileOf(identity, "public/permissions_ca.pem"), "the permissions CA");
  RequireFile(FileOf(identity, "public/crl.pem"), "the revocation list");

  EVP_PKEY* ca_key = X509_get0_pubkey(ca.get());
  if (ca_key == nullptr || X509_verify(certificate.get(), ca_key) != 1) {
    throw InputError("security: the certificate " + cert_path + " is not signed by this deployment's identity CA " +
                     FileOf(identity, "public/identity_ca.pem"));
  }
  const std::string common_name = CommonName(certificate.get());
  if (common_name != identity.name) {
    throw InputError("security: the certificate " + cert_path + " belongs to '" + common_name + "', not to '" +
                     identity.name + "': a participant runs only under its own identity");
  }
  if (X509_cmp_current_time(X509_get0_notBefore(certificate.get())) >= 0) {
    throw InputError("security: the certificate " + cert_path + " is not valid yet (check this machine's clock)");
  }
  if (X509_cmp_current_time(X509_get0_notAfter(certificate.get())) <= 0) {
    throw InputError("security: the certificate " + cert_path + " has expired: make a new one with "
                     "scripts/dds-security renew " + identity.dir + " " + identity.name);
  }
  // The key must be the certificate's: with another identity's key.pem the handshake fails
  // inside DDS ("Failed to finalize digest context" on the server, once a second) and the
  // client only hears that no server answers (a helper session).
  if (std::FILE* file = std::fopen(key_path.c_str(), "r")) {
    EVP_PKEY* key = PEM_read_PrivateKey(file, nullptr, nullptr, const_cast<char*>(""));
    std::fclose(file);
    if (key == nullptr) {
      throw InputError("security: " + key_path + " is not an unencrypted PEM private key (DDS Security reads it "
                       "without a passphrase)");
    }
    const bool matches = X509_check_private_key(certificate.get(), key) == 1;
    EVP_PKEY_free(key);
    if (!matches) {
      throw InputError("security: the private key " + key_path + " does not belong to the certificate " + cert_path +
                       " (copied from another identity?): scripts/dds-security renew " + identity.dir + " " +
                       identity.name + " makes a matching pair");
    }
  }
  // Revoked (scripts/dds-security revoke): Cyclone reads the same CRL; say so before it does.
  const std::string crl_path = FileOf(identity, "public/crl.pem");
  if (std::FILE* file = std::fopen(crl_path.c_str(), "r")) {
    X509_CRL* crl = PEM_read_X509_CRL(file, nullptr, nullptr, nullptr);
    std::fclose(file);
    if (crl == nullptr) throw InputError("security: " + crl_path + " is not a PEM revocation list");
    X509_REVOKED* entry = nullptr;
    const bool revoked = X509_CRL_get0_by_cert(crl, &entry, certificate.get()) == 1;
    X509_CRL_free(crl);
    if (revoked) {
      throw InputError("security: the identity '" + identity.name + "' was revoked (" + crl_path +
                       "): scripts/dds-security add-client " + identity.dir + " NEW_NAME makes a new one");
    }
  }
}

dds_qos_t* CreateSecurityQos(const SecurityIdentity& identity) {
  ValidateSecurityIdentity(identity);
  const std::filesystem::path dir = std::filesystem::absolute(identity.dir);
  auto file = [&dir](const std::string& relative) { return "file:" + (dir / relative).string(); };
  dds_qos_t* qos = dds_create_qos();
  dds_qset_prop(qos, "dds.sec.auth.library.path", "dds_security_auth");
  dds_qset_prop(qos, "dds.sec.auth.library.init", "init_authentication");
  dds_qset_prop(qos, "dds.sec.auth.library.finalize", "finalize_authentication");
  dds_qset_prop(qos, "dds.sec.auth.identity_ca", file("public/identity_ca.pem").c_str());
  dds_qset_prop(qos, "dds.sec.auth.identity_certificate", file(identity.name + "/cert.pem").c_str());
  dds_qset_prop(qos, "dds.sec.auth.private_key", file(identity.name + "/key.pem").c_str());
  dds_qset_prop(qos, "org.eclipse.cyclonedds.sec.auth.crl", file("public/crl.pem").c_str());
  dds_qset_prop(qos, "dds.sec.access.library.path", "dds_security_ac");
  dds_qset_prop(qos, "dds.sec.access.library.init", "init_access_control");
  dds_qset_prop(qos, "dds.sec.access.library.finalize", "finalize_access_control");
  dds_qset_prop(qos, "dds.sec.access.governance", file("public/governance.xml.p7s").c_str());
  dds_qset_prop(qos, "dds.sec.access.permissions_ca", file("public/permissions_ca.pem").c_str());
  dds_qset_prop(qos, "dds.sec.access.permissions", file(identity.name + "/permissions.xml.p7s").c_str());
  dds_qset_prop(qos, "dds.sec.crypto.library.path", "dds_security_crypto");
  dds_qset_prop(qos, "dds.sec.crypto.library.init", "init_crypto");
  dds_qset_prop(qos, "dds.sec.crypto.library.finalize", "finalize_crypto");
  return qos;
}

}  // namespace hapco::service
