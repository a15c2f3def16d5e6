#pragma once
/// @file Internal: explains why Fast DDS refused a participant's DDS Security material. Fast DDS
/// 2.9.1 only logs "Cannot create participant due to initialization error"; these checks redo
/// with OpenSSL what its PKI-DH and Access-Permissions plugins check, to name the faulty file.

#include <string>

#include "tarmac/transport/participant.hpp"

namespace tarmac::transport {

/// The first fault found, as "dds.security.<key>: why", or empty when every check passes
/// (Fast DDS may still refuse, e.g. for a grant whose validity or domains do not match).
/// Called only after a refusal: Fast DDS stays the authority on what is accepted.
std::string diagnose_security(const SecurityConfig& security);

}  // namespace tarmac::transport
