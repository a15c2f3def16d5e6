#include "tarmac/transport/fleet.hpp"

#include <algorithm>
#include <atomic>
#include <deque>
#include <mutex>
#include <utility>

#include <fastdds/rtps/common/InstanceHandle.h>
#include <fastdds/dds/subscriber/DataReader.hpp>
#include <fastdds/dds/subscriber/DataReaderListener.hpp>
#include <fastdds/dds/subscriber/SampleInfo.hpp>

#include "conversions.hpp"
#include "dds_endpoints.hpp"
#include "tarmac_msgsPubSubTypes.h"

namespace tarmac::transport {

namespace {
constexpr std::string_view kPartitionPrefix = "tarmac_fleet_";
}  // namespace

std::string fleet_partition(std::string_view vehicle_id) {
  return std::string(kPartitionPrefix) + std::string(vehicle_id);
}

/// The reader: like Reader<> (the listener only enqueues, overflow drops the oldest, counted),
/// but each sample keeps its writer's GUID, to check the vehicle id against its partition.
class FleetLink::Impl : private fdds::DataReaderListener {
 public:
  using PubSub = tarmac_msgs::msg::dds_::FleetBev_PubSubType;
  struct Received {
    FleetBevMsg message;
    std::vector<std::string> partitions;  ///< its writer's, looked up on arrival
  };

  Impl(std::shared_ptr<ParticipantImpl> participant, FleetLinkOptions options)
      : participant_(std::move(participant)), options_(std::move(options)) {}

  ~Impl() override {
    if (reader_ != nullptr) {
      reader_->set_listener(nullptr);
      subscriber_->delete_datareader(reader_);
    }
  }
  Impl(const Impl&) = delete;
  Impl& operator=(const Impl&) = delete;

  core::Status create_reader() {
    auto topic = participant_->topic(options_.topic, fdds::TypeSupport(new PubSub()));
    if (!topic) return topic.error();
    const std::string every_vehicle = std::string(kPartitionPrefix) + "*";
    subscriber_ = participant_->subscriber(every_vehicle);
    if (subscriber_ != nullptr) {
      reader_ = subscriber_->create_datareader(topic.value(), to_reader_qos(options_.qos), this,
                                               fdds::StatusMask::data_available()
                                                   << fdds::StatusMask::sample_lost());
    }
    if (reader_ == nullptr) {
      return core::Error{"dds.reader", "cannot create a reader on " + options_.topic +
                                           " in partition " + every_vehicle +
                                           security_refusal_hint(*participant_)};
    }
    return core::Ok{};
  }

  std::size_t drain(FleetSink& sink) {
    {
      std::lock_guard lock(mutex_);
      batch_.swap(queue_);
    }
    const std::size_t n = batch_.size();
    for (auto& r : batch_) {
      // The writer's partition names the vehicle it may speak for (granted per vehicle when
      // DDS Security is on): a summary under another id is refused — this vehicle's own id
      // included, unless it comes from this vehicle's own partition (its own echo, skipped).
      const std::string& id = r.message.vehicle_id();
      const bool its_own_partition = std::find(r.partitions.begin(), r.partitions.end(),
                                               fleet_partition(id)) != r.partitions.end();
      if (its_own_partition && id == options_.vehicle_id) continue;
      auto message = from_fleet_bev(r.message, options_.frame_id);
      if (!message) {
        sink.reject(message.error().code);
        continue;
      }
      if (!its_own_partition) {
        sink.reject("fleet.impersonation");
        continue;
      }
      sink.summary(std::move(message).value());
    }
    batch_.clear();
    return n;
  }

  std::shared_ptr<ParticipantImpl> participant_;
  FleetLinkOptions options_;
  std::unique_ptr<Writer<PubSub>> writer;
  FleetBevMsg out;  // kept: its tile buffers are reused
  std::size_t last_bytes = 0;
  std::atomic<std::uint64_t> dropped{0};
  std::atomic<std::uint64_t> lost{0};
  fdds::Subscriber* subscriber_ = nullptr;
  fdds::DataReader* reader_ = nullptr;

 private:
  void on_data_available(fdds::DataReader* reader) override {
    Received r;
    fdds::SampleInfo info;
    while (reader->take_next_sample(&r.message, &info) == ReturnCode_t::RETCODE_OK) {
      if (!info.valid_data) continue;
      // On arrival: the writer is matched now, and may be gone by the next drain.
      r.partitions = participant_->discovered_writers().partitions(
          eprosima::fastrtps::rtps::iHandle2GUID(info.publication_handle));
      std::lock_guard lock(mutex_);
      if (queue_.size() == options_.queue_depth) {
        queue_.pop_front();
        dropped.fetch_add(1);
      }
      queue_.push_back(std::move(r));
      r = Received();
    }
  }

  void on_sample_lost(fdds::DataReader* /*reader*/, const fdds::SampleLostStatus& status) override {
    if (status.total_count_change > 0) {
      lost.fetch_add(static_cast<std::uint64_t>(status.total_count_change));
    }
  }

  std::mutex mutex_;
  std::deque<Received> queue_;
  std::deque<Received> batch_;
};

core::Result<std::unique_ptr<FleetLink>> FleetLink::create(const Participant& participant,
                                                           const FleetLinkOptions& options) {
  if (auto valid = options.qos.validate(); !valid) return valid.error();
  if (options.queue_depth == 0) return core::Error{"config.qos", "queue_depth: must be >= 1"};
  auto impl = std::make_unique<Impl>(participant.impl(), options);
  if (!options.vehicle_id.empty()) {
    auto writer = Writer<Impl::PubSub>::create(participant, options.topic, options.qos,
                                               fleet_partition(options.vehicle_id));
    if (!writer) return writer.error();
    impl->writer = std::move(writer).value();
  }
  if (auto reader = impl->create_reader(); !reader) return reader.error();
  return std::unique_ptr<FleetLink>(new FleetLink(std::move(impl)));
}

FleetLink::FleetLink(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
FleetLink::~FleetLink() = default;

bool FleetLink::publish(const core::BevMessage& message) {
  if (!impl_->writer) return false;
  fill_fleet_bev(message, impl_->options_.frame_id, impl_->out);
  impl_->last_bytes = 4 + FleetBevMsg::getCdrSerializedSize(impl_->out);  // + encapsulation
  return impl_->writer->write(impl_->out);
}

std::size_t FleetLink::last_bytes() const {
  return impl_->last_bytes;
}

std::size_t FleetLink::drain(FleetSink& sink) {
  return impl_->drain(sink);
}

std::uint64_t FleetLink::overflow_drops() const {
  return impl_->dropped.load();
}

std::uint64_t FleetLink::transport_lost() const {
  return impl_->lost.load();
}

std::size_t FleetLink::matched_writers() const {
  fdds::SubscriptionMatchedStatus status;
  impl_->reader_->get_subscription_matched_status(status);
  return static_cast<std::size_t>(status.current_count);
}

std::size_t FleetLink::matched_readers() const {
  return impl_->writer ? impl_->writer->matched_readers() : 0;
}

}  // namespace tarmac::transport
