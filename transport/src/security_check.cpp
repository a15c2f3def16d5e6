#include "security_check.hpp"

#include <openssl/bio.h>
#include <openssl/err.h>
#include <openssl/evp.h>
#include <openssl/pem.h>
#include <openssl/pkcs7.h>
#include <openssl/x509.h>
#include <openssl/x509_vfy.h>

#include <memory>

namespace tarmac::transport {

namespace {

template <auto Free>
struct Deleter {
  template <typename T>
  void operator()(T* p) const {
    Free(p);
  }
};
using Bio = std::unique_ptr<BIO, Deleter<BIO_free_all>>;
using Cert = std::unique_ptr<X509, Deleter<X509_free>>;
using Key = std::unique_ptr<EVP_PKEY, Deleter<EVP_PKEY_free>>;
using Store = std::unique_ptr<X509_STORE, Deleter<X509_STORE_free>>;
using StoreCtx = std::unique_ptr<X509_STORE_CTX, Deleter<X509_STORE_CTX_free>>;
using Pkcs7 = std::unique_ptr<PKCS7, Deleter<PKCS7_free>>;

/// The newest OpenSSL error as text (and the queue cleared), or `fallback`.
std::string openssl_error(const char* fallback) {
  const unsigned long code = ERR_get_error();  // NOLINT(google-runtime-int): OpenSSL's type
  ERR_clear_error();
  if (code == 0) return fallback;
  char buf[256];
  ERR_error_string_n(code, buf, sizeof buf);
  return buf;
}

Cert read_cert(const std::string& path) {
  Bio bio(BIO_new_file(path.c_str(), "r"));
  if (!bio) return nullptr;
  return Cert(PEM_read_bio_X509(bio.get(), nullptr, nullptr, nullptr));
}

std::string subject_rfc2253(X509* cert) {
  Bio mem(BIO_new(BIO_s_mem()));
  X509_NAME_print_ex(mem.get(), X509_get_subject_name(cert), 0, XN_FLAG_RFC2253);
  char* data = nullptr;
  const long n = BIO_get_mem_data(mem.get(), &data);  // NOLINT(google-runtime-int)
  return n > 0 ? std::string(data, static_cast<std::size_t>(n)) : std::string();
}

/// Verifies an S/MIME-signed document against `ca`; returns its content or sets `why`.
bool verify_signed(const std::string& path, X509* ca, std::string& content, std::string& why) {
  Bio in(BIO_new_file(path.c_str(), "r"));
  if (!in) {
    why = "cannot open '" + path + "'";
    return false;
  }
  BIO* detached = nullptr;
  Pkcs7 p7(SMIME_read_PKCS7(in.get(), &detached));
  const Bio detached_owner(detached);
  if (!p7) {
    why = "'" + path + "' is not an S/MIME signed document (openssl smime -sign -text): " +
          openssl_error("unreadable");
    return false;
  }
  Store store(X509_STORE_new());
  X509_STORE_add_cert(store.get(), ca);
  Bio out(BIO_new(BIO_s_mem()));
  if (PKCS7_verify(p7.get(), nullptr, store.get(), detached, out.get(), PKCS7_TEXT) != 1) {
    why = "signature of '" + path + "' does not verify against dds.security.permissions_ca (" +
          openssl_error("verify failed") + ")";
    return false;
  }
  char* data = nullptr;
  const long n = BIO_get_mem_data(out.get(), &data);  // NOLINT(google-runtime-int)
  content = n > 0 ? std::string(data, static_cast<std::size_t>(n)) : std::string();
  return true;
}

}  // namespace

std::string diagnose_security(const SecurityConfig& s) {
  ERR_clear_error();
  const Cert identity_ca = read_cert(s.identity_ca);
  if (!identity_ca)
    return "dds.security.identity_ca: '" + s.identity_ca + "' is not a PEM certificate";
  const Cert cert = read_cert(s.identity_certificate);
  if (!cert) {
    return "dds.security.identity_certificate: '" + s.identity_certificate +
           "' is not a PEM certificate";
  }
  {
    Store store(X509_STORE_new());
    X509_STORE_add_cert(store.get(), identity_ca.get());
    StoreCtx ctx(X509_STORE_CTX_new());
    X509_STORE_CTX_init(ctx.get(), store.get(), cert.get(), nullptr);
    if (X509_verify_cert(ctx.get()) != 1) {
      return "dds.security.identity_certificate: '" + s.identity_certificate +
             "' does not verify against dds.security.identity_ca '" + s.identity_ca + "' (" +
             X509_verify_cert_error_string(X509_STORE_CTX_get_error(ctx.get())) + ")";
    }
  }
  {
    Bio bio(BIO_new_file(s.private_key.c_str(), "r"));
    // No passphrase callback: an encrypted key fails here, as it does in Fast DDS without
    // dds.sec.auth.builtin.PKI-DH.password.
    Key key(bio ? PEM_read_bio_PrivateKey(
                      bio.get(), nullptr, [](char*, int, int, void*) { return 0; }, nullptr)
                : nullptr);
    if (!key) {
      return "dds.security.private_key: '" + s.private_key +
             "' is not an unencrypted PEM private key (" + openssl_error("unreadable") + ")";
    }
    if (X509_check_private_key(cert.get(), key.get()) != 1) {
      ERR_clear_error();
      return "dds.security.private_key: '" + s.private_key +
             "' does not belong to dds.security.identity_certificate '" + s.identity_certificate +
             "'";
    }
  }
  const Cert permissions_ca = read_cert(s.permissions_ca);
  if (!permissions_ca) {
    return "dds.security.permissions_ca: '" + s.permissions_ca + "' is not a PEM certificate";
  }
  std::string governance, permissions, why;
  if (!verify_signed(s.governance, permissions_ca.get(), governance, why)) {
    return "dds.security.governance: " + why;
  }
  if (!verify_signed(s.permissions, permissions_ca.get(), permissions, why)) {
    return "dds.security.permissions: " + why;
  }
  const std::string subject = subject_rfc2253(cert.get());
  if (permissions.find("<subject_name>" + subject + "</subject_name>") == std::string::npos) {
    return "dds.security.permissions: no grant with <subject_name>" + subject +
           "</subject_name> (the subject of dds.security.identity_certificate)";
  }
  return {};
}

}  // namespace tarmac::transport
