#include "tarmac/transport/qos.hpp"

namespace tarmac::transport {

core::Status QosSpec::validate() const {
  if (history_depth < 1) return core::Error{"config.qos", "history_depth: must be >= 1"};
  return core::Ok{};
}

}  // namespace tarmac::transport
