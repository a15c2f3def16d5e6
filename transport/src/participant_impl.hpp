#pragma once
/// @file Internal: the Fast DDS entities behind tarmac::transport::Participant. Not a public
/// header (it exposes Fast DDS types); used by this library, its tests and tools that need the
/// raw IDL types.

#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include <fastdds/dds/domain/DomainParticipant.hpp>
#include <fastdds/dds/domain/DomainParticipantListener.hpp>
#include <fastdds/dds/publisher/Publisher.hpp>
#include <fastdds/dds/subscriber/Subscriber.hpp>
#include <fastdds/dds/topic/Topic.hpp>
#include <fastdds/dds/topic/TypeSupport.hpp>

#include <fastdds/dds/publisher/qos/DataWriterQos.hpp>
#include <fastdds/dds/subscriber/qos/DataReaderQos.hpp>

#include "tarmac/transport/participant.hpp"
#include "tarmac/transport/qos.hpp"

namespace tarmac::transport {

namespace fdds = eprosima::fastdds::dds;

/// The partitions of every writer discovered (remote or local), by GUID: what a reader needs to
/// know which partition a sample came from (Fast DDS 2.9 has no get_matched_publication_data).
class DiscoveredWriters final : public fdds::DomainParticipantListener {
 public:
  void on_publisher_discovery(fdds::DomainParticipant* participant,
                              eprosima::fastrtps::rtps::WriterDiscoveryInfo&& info) override;
  /// The partitions writer `guid` was announced with; empty when unknown (or the default).
  [[nodiscard]] std::vector<std::string> partitions(
      const eprosima::fastrtps::rtps::GUID_t& guid) const;

 private:
  mutable std::mutex mutex_;
  std::map<eprosima::fastrtps::rtps::GUID_t, std::vector<std::string>> partitions_;
};

class ParticipantImpl {
 public:
  ParticipantImpl(ParticipantConfig config, fdds::DomainParticipant* participant,
                  fdds::Publisher* publisher, fdds::Subscriber* subscriber,
                  std::unique_ptr<DiscoveredWriters> writers)
      : config_(std::move(config)),
        participant_(participant),
        publisher_(publisher),
        subscriber_(subscriber),
        writers_(std::move(writers)) {}
  ~ParticipantImpl();
  ParticipantImpl(const ParticipantImpl&) = delete;
  ParticipantImpl& operator=(const ParticipantImpl&) = delete;

  /// Registers `type` (once per type name) and returns the topic `name` (created once).
  /// Fails when the topic exists with another type.
  core::Result<fdds::Topic*> topic(const std::string& name, fdds::TypeSupport type);

  [[nodiscard]] const ParticipantConfig& config() const { return config_; }
  [[nodiscard]] fdds::DomainParticipant* participant() const { return participant_; }
  [[nodiscard]] fdds::Publisher* publisher() const { return publisher_; }
  [[nodiscard]] fdds::Subscriber* subscriber() const { return subscriber_; }
  /// The publisher (subscriber) whose DDS partition is `partition`, created on first use; the
  /// default ones for an empty name. nullptr when Fast DDS refused it (with security on: no
  /// grant for the partition).
  fdds::Publisher* publisher(const std::string& partition);
  fdds::Subscriber* subscriber(const std::string& partition);
  [[nodiscard]] const DiscoveredWriters& discovered_writers() const { return *writers_; }

 private:
  ParticipantConfig config_;
  fdds::DomainParticipant* participant_;
  fdds::Publisher* publisher_;
  fdds::Subscriber* subscriber_;
  std::mutex mutex_;  // guards topics_, type registration and the partitioned entities
  std::map<std::string, fdds::Topic*> topics_;
  std::map<std::string, fdds::Publisher*> partition_publishers_;
  std::map<std::string, fdds::Subscriber*> partition_subscribers_;
  std::unique_ptr<DiscoveredWriters>
      writers_;  // outlives participant_ (deleted in ~ParticipantImpl)
};

/// Error entries Fast DDS logged since the last call (its log is asynchronous: this flushes it
/// first), joined with "; ", at most the last few. Collected only once a secured participant
/// was created (the security plugins explain their refusals only there). Empty when none.
std::string take_dds_errors();

/// For an endpoint Fast DDS refused: with security on, the likely reason (a missing grant) and
/// what Fast DDS said; empty otherwise.
std::string security_refusal_hint(const ParticipantImpl& impl);

/// Converts a QosSpec into Fast DDS writer/reader QoS.
fdds::DataWriterQos to_writer_qos(const QosSpec& spec);
fdds::DataReaderQos to_reader_qos(const QosSpec& spec);

}  // namespace tarmac::transport
