#include "tarmac/transport/participant.hpp"

#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <deque>
#include <fstream>
#include <mutex>

#include <fastdds/rtps/attributes/ServerAttributes.h>
#include <fastdds/rtps/transport/UDPv4TransportDescriptor.h>
#include <fastdds/rtps/transport/shared_mem/SharedMemTransportDescriptor.h>
#include <fastrtps/utils/IPLocator.h>
#include <fastdds/dds/domain/DomainParticipantFactory.hpp>
#include <fastdds/dds/domain/qos/DomainParticipantQos.hpp>
#include <fastdds/dds/log/Log.hpp>

#include "addresses.hpp"
#include "participant_impl.hpp"
#include "security_check.hpp"
#include "tarmac/transport/qos.hpp"

namespace tarmac::transport {

using eprosima::fastrtps::rtps::IPLocator;
using eprosima::fastrtps::rtps::Locator_t;

namespace {

Locator_t udp_locator(const std::string& address) {
  Locator_t locator;
  locator.kind = LOCATOR_KIND_UDPv4;
  IPLocator::setIPv4(locator, address);
  return locator;
}

/// Keeps Fast DDS's recent error entries so a refusal can be explained in the returned error.
class ErrorCollector final : public eprosima::fastdds::dds::LogConsumer {
 public:
  void Consume(const eprosima::fastdds::dds::Log::Entry& entry) override {
    if (entry.kind != eprosima::fastdds::dds::Log::Kind::Error) return;
    std::lock_guard lock(mutex_);
    std::string text = entry.message;
    for (char& c : text) {
      if (c == '\n' || c == '\r') c = ' ';
    }
    while (!text.empty() && text.back() == ' ') text.pop_back();
    if (entry.context.category != nullptr) text = std::string(entry.context.category) + ": " + text;
    entries_.push_back(std::move(text));
    while (entries_.size() > kKept) entries_.pop_front();
  }
  std::string take() {
    std::lock_guard lock(mutex_);
    std::string joined;
    for (const auto& e : entries_) joined += (joined.empty() ? "" : "; ") + e;
    entries_.clear();
    return joined;
  }

 private:
  static constexpr std::size_t kKept = 4;
  std::mutex mutex_;
  std::deque<std::string> entries_;
};

std::atomic<ErrorCollector*> g_collector{nullptr};  // owned by Fast DDS's Log once registered
std::once_flag g_collector_once;

void collect_dds_errors() {
  std::call_once(g_collector_once, [] {
    auto collector = std::make_unique<ErrorCollector>();
    g_collector = collector.get();
    // Appended to the consumers: Fast DDS still prints its own log as before.
    eprosima::fastdds::dds::Log::RegisterConsumer(std::move(collector));
  });
}

std::string file_uri(const std::string& path) {
  // Fast DDS strips "file://" and opens the rest: absolute paths give "file:///...".
  return "file://" + path;
}

void add_security_properties(const SecurityConfig& s, fdds::DomainParticipantQos& qos) {
  auto& props = qos.properties().properties();
  props.emplace_back("dds.sec.auth.plugin", "builtin.PKI-DH");
  props.emplace_back("dds.sec.auth.builtin.PKI-DH.identity_ca", file_uri(s.identity_ca));
  props.emplace_back("dds.sec.auth.builtin.PKI-DH.identity_certificate",
                     file_uri(s.identity_certificate));
  props.emplace_back("dds.sec.auth.builtin.PKI-DH.private_key", file_uri(s.private_key));
  props.emplace_back("dds.sec.access.plugin", "builtin.Access-Permissions");
  props.emplace_back("dds.sec.access.builtin.Access-Permissions.permissions_ca",
                     file_uri(s.permissions_ca));
  props.emplace_back("dds.sec.access.builtin.Access-Permissions.governance",
                     file_uri(s.governance));
  props.emplace_back("dds.sec.access.builtin.Access-Permissions.permissions",
                     file_uri(s.permissions));
  props.emplace_back("dds.sec.crypto.plugin", "builtin.AES-GCM-GMAC");
}

std::shared_ptr<eprosima::fastdds::rtps::UDPv4TransportDescriptor> udp_transport(
    const ParticipantConfig& config) {
  auto udp = std::make_shared<eprosima::fastdds::rtps::UDPv4TransportDescriptor>();
  udp->receiveBufferSize = config.udp_receive_buffer_bytes;
  udp->sendBufferSize = config.udp_send_buffer_bytes;
  return udp;
}

/// The size the kernel grants for `option` (SO_RCVBUF / SO_SNDBUF) when asked for `bytes`, or
/// -1 when no socket can be made. Linux reports twice the granted size (bookkeeping overhead).
long granted_buffer(int option, std::uint32_t bytes) {
  const int fd = ::socket(AF_INET, SOCK_DGRAM | SOCK_CLOEXEC, 0);
  if (fd < 0) return -1;
  const int asked = static_cast<int>(std::min<std::uint32_t>(bytes, 1u << 30));
  ::setsockopt(fd, SOL_SOCKET, option, &asked, sizeof asked);
  int got = 0;
  socklen_t len = sizeof got;
  const int rc = ::getsockopt(fd, SOL_SOCKET, option, &got, &len);
  ::close(fd);
  return rc == 0 ? got / 2 : -1;
}

std::string read_sysctl(const char* path) {
  std::ifstream in(path);
  std::string value;
  in >> value;
  return value.empty() ? "?" : value;
}

fdds::DomainParticipantQos participant_qos(const ParticipantConfig& config) {
  fdds::DomainParticipantQos qos;
  qos.name(config.name);
  if (config.security.enabled) add_security_properties(config.security, qos);
  // Only the transports chosen here: the built-in ones would bind every interface.
  qos.transport().use_builtin_transports = false;

  auto shm = std::make_shared<eprosima::fastdds::rtps::SharedMemTransportDescriptor>();
  shm->segment_size(config.shm_segment_bytes);
  shm->max_message_size(config.shm_max_message_bytes);
  qos.transport().user_transports.push_back(shm);

  auto& builtin = qos.wire_protocol().builtin;
  switch (config.transport) {
    case TransportMode::kSharedMemoryOnly: break;
    case TransportMode::kLocalhost: {
      auto udp = udp_transport(config);
      udp->interfaceWhiteList.emplace_back("127.0.0.1");
      // Discovery goes to the initial peer's ports of participant ids 0..N-1 only (default 4).
      // A machine runs tarmacd, replay, audit, echo, rviz and tests side by side: with more
      // than 4 participants two late ones would never find each other. 32 costs 32 loopback
      // datagrams per announcement.
      udp->maxInitialPeersRange = 32;
      qos.transport().user_transports.push_back(udp);
      builtin.initialPeersList.push_back(udp_locator("127.0.0.1"));
      break;
    }
    case TransportMode::kNetwork: {
      auto udp = udp_transport(config);
      udp->interfaceWhiteList = config.network_interfaces;
      qos.transport().user_transports.push_back(udp);
      for (const auto& peer : config.initial_peers) {
        builtin.initialPeersList.push_back(udp_locator(peer));
      }
      break;
    }
  }
  if (!config.discovery_servers.empty()) {
    // A client of the servers: it announces itself to them only, and they tell it of the
    // others (validate() checked each entry).
    builtin.discovery_config.discoveryProtocol =
        eprosima::fastrtps::rtps::DiscoveryProtocol::CLIENT;
    builtin.initialPeersList.clear();
    for (std::size_t id = 0; id < config.discovery_servers.size(); ++id) {
      std::string address;
      std::uint32_t port = 0;
      split_server(config.discovery_servers[id], address, port);
      eprosima::fastdds::rtps::RemoteServerAttributes server;
      eprosima::fastdds::rtps::get_server_client_default_guidPrefix(static_cast<int>(id),
                                                                    server.guidPrefix);
      Locator_t locator = udp_locator(address);
      locator.port = port;
      server.metatrafficUnicastLocatorList.push_back(locator);
      builtin.discovery_config.m_DiscoveryServers.push_back(server);
    }
  }
  return qos;
}

}  // namespace

std::vector<std::string> udp_buffer_shortfalls(const ParticipantConfig& config) {
  std::vector<std::string> out;
  if (config.transport == TransportMode::kSharedMemoryOnly) return out;
  struct Buffer {
    const char* key;
    int option;
    std::uint32_t bytes;
    const char* sysctl;
  };
  for (const Buffer& b : {Buffer{"dds.udp_receive_buffer_bytes", SO_RCVBUF,
                                 config.udp_receive_buffer_bytes, "net.core.rmem_max"},
                          Buffer{"dds.udp_send_buffer_bytes", SO_SNDBUF,
                                 config.udp_send_buffer_bytes, "net.core.wmem_max"}}) {
    const long granted = granted_buffer(b.option, b.bytes);
    if (granted < 0 || granted >= static_cast<long>(b.bytes)) continue;
    std::string proc = std::string("/proc/sys/") + b.sysctl;
    for (char& c : proc) {
      if (c == '.') c = '/';
    }
    out.push_back(std::string(b.key) + ": " + std::to_string(b.bytes) +
                  " bytes asked, the kernel grants " + std::to_string(granted) + " (" + b.sysctl +
                  " = " + read_sysctl(proc.c_str()) +
                  "); large samples over UDP will be lost: " + "raise it, e.g. sysctl -w " +
                  b.sysctl + "=" + std::to_string(b.bytes) + " (systemd/99-tarmac-net.conf)");
  }
  return out;
}

std::string take_dds_errors() {
  ErrorCollector* collector = g_collector.load();
  if (collector == nullptr) return {};
  eprosima::fastdds::dds::Log::Flush();
  return collector->take();
}

std::string security_refusal_hint(const ParticipantImpl& impl) {
  if (!impl.config().security.enabled) return {};
  std::string hint =
      " (DDS Security is on: does the permissions file grant this topic to the participant's "
      "identity?";
  if (const std::string why = take_dds_errors(); !why.empty()) hint += " Fast DDS: " + why;
  return hint + ")";
}

core::Result<Participant> Participant::create(const ParticipantConfig& config) {
  if (auto valid = config.validate(); !valid) return valid.error();

  auto* factory = fdds::DomainParticipantFactory::get_instance();
  if (config.security.enabled) {
    collect_dds_errors();
    take_dds_errors();  // only this creation's refusals below
  }
  auto writers = std::make_unique<DiscoveredWriters>();
  fdds::DomainParticipant* participant = factory->create_participant(
      config.domain_id, participant_qos(config), writers.get(), fdds::StatusMask::none());
  if (participant == nullptr && config.security.enabled) {
    const std::string logged = take_dds_errors();
    std::string why = diagnose_security(config.security);
    if (why.empty()) {
      why =
          "no fault found in the files (check the grant's validity dates and domains, and "
          "the governance's domain rules); Fast DDS: " +
          (logged.empty() ? std::string("no reason given") : logged);
    }
    return core::Error{"dds.security",
                       "Fast DDS refused the DDS Security material of participant '" + config.name +
                           "' on domain " + std::to_string(config.domain_id) + ": " + why};
  }
  if (participant == nullptr) {
    return core::Error{"dds.participant", "Fast DDS refused to create a participant on domain " +
                                              std::to_string(config.domain_id) + " (transport " +
                                              to_string(config.transport) + ")"};
  }
  fdds::Publisher* publisher = participant->create_publisher(fdds::PUBLISHER_QOS_DEFAULT);
  fdds::Subscriber* subscriber = participant->create_subscriber(fdds::SUBSCRIBER_QOS_DEFAULT);
  auto impl = std::make_shared<ParticipantImpl>(config, participant, publisher, subscriber,
                                                std::move(writers));
  if (publisher == nullptr || subscriber == nullptr) {
    return core::Error{"dds.participant", "Fast DDS refused to create a publisher/subscriber"};
  }
  return Participant(std::move(impl));
}

const ParticipantConfig& Participant::config() const {
  return impl_->config();
}

ParticipantImpl::~ParticipantImpl() {
  // Endpoints hold a shared_ptr to this object, so all of them are gone by now.
  participant_->delete_contained_entities();
  fdds::DomainParticipantFactory::get_instance()->delete_participant(participant_);
}

void DiscoveredWriters::on_publisher_discovery(
    fdds::DomainParticipant* /*participant*/,
    eprosima::fastrtps::rtps::WriterDiscoveryInfo&& info) {
  using Status = eprosima::fastrtps::rtps::WriterDiscoveryInfo::DISCOVERY_STATUS;
  std::lock_guard lock(mutex_);
  if (info.status == Status::REMOVED_WRITER) {
    partitions_.erase(info.info.guid());
  } else {
    partitions_[info.info.guid()] = info.info.m_qos.m_partition.getNames();
  }
}

std::vector<std::string> DiscoveredWriters::partitions(
    const eprosima::fastrtps::rtps::GUID_t& guid) const {
  std::lock_guard lock(mutex_);
  const auto it = partitions_.find(guid);
  return it == partitions_.end() ? std::vector<std::string>{} : it->second;
}

namespace {

/// The entity of `partition` in `cache`, created with `qos` (its partition added) on first use.
template <typename Entity, typename Qos, typename Create>
Entity* partitioned(std::map<std::string, Entity*>& cache, const std::string& partition, Qos qos,
                    Create create) {
  Entity*& entity = cache[partition];
  if (entity == nullptr) {
    qos.partition().push_back(partition.c_str());
    entity = create(qos);
  }
  return entity;
}

}  // namespace

fdds::Publisher* ParticipantImpl::publisher(const std::string& partition) {
  if (partition.empty()) return publisher_;
  std::lock_guard lock(mutex_);
  return partitioned(
      partition_publishers_, partition, fdds::PUBLISHER_QOS_DEFAULT,
      [&](const fdds::PublisherQos& q) { return participant_->create_publisher(q); });
}

fdds::Subscriber* ParticipantImpl::subscriber(const std::string& partition) {
  if (partition.empty()) return subscriber_;
  std::lock_guard lock(mutex_);
  return partitioned(
      partition_subscribers_, partition, fdds::SUBSCRIBER_QOS_DEFAULT,
      [&](const fdds::SubscriberQos& q) { return participant_->create_subscriber(q); });
}

core::Result<fdds::Topic*> ParticipantImpl::topic(const std::string& name, fdds::TypeSupport type) {
  std::lock_guard lock(mutex_);
  if (auto it = topics_.find(name); it != topics_.end()) {
    if (it->second->get_type_name() != type.get_type_name()) {
      return core::Error{"dds.topic", "topic " + name + " already exists with type " +
                                          it->second->get_type_name()};
    }
    return it->second;
  }
  if (participant_->find_type(type.get_type_name()).empty() &&
      type.register_type(participant_) != ReturnCode_t::RETCODE_OK) {
    return core::Error{"dds.topic", "cannot register type " + type.get_type_name()};
  }
  fdds::Topic* topic =
      participant_->create_topic(name, type.get_type_name(), fdds::TOPIC_QOS_DEFAULT);
  if (topic == nullptr) return core::Error{"dds.topic", "cannot create topic " + name};
  topics_.emplace(name, topic);
  return topic;
}

namespace {
template <typename Qos>
void apply(const QosSpec& spec, Qos& qos) {
  qos.reliability().kind = spec.reliability == Reliability::kReliable
                               ? fdds::RELIABLE_RELIABILITY_QOS
                               : fdds::BEST_EFFORT_RELIABILITY_QOS;
  qos.durability().kind = spec.durability == Durability::kTransientLocal
                              ? fdds::TRANSIENT_LOCAL_DURABILITY_QOS
                              : fdds::VOLATILE_DURABILITY_QOS;
  qos.history().kind = fdds::KEEP_LAST_HISTORY_QOS;
  qos.history().depth = static_cast<std::int32_t>(spec.history_depth);
}
}  // namespace

fdds::DataWriterQos to_writer_qos(const QosSpec& spec) {
  fdds::DataWriterQos qos = fdds::DATAWRITER_QOS_DEFAULT;
  apply(spec, qos);
  return qos;
}

fdds::DataReaderQos to_reader_qos(const QosSpec& spec) {
  fdds::DataReaderQos qos = fdds::DATAREADER_QOS_DEFAULT;
  apply(spec, qos);
  return qos;
}

}  // namespace tarmac::transport
