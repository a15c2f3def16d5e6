#pragma once
/// @file Internal: typed DDS reader and writer over fastddsgen types, RAII-owned.
/// The listener thread only enqueues into a bounded queue (overflow drops the oldest sample
/// and counts it); the owner drains without blocking (DESIGN.md §3 step 2).

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <deque>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include <fastdds/dds/core/status/PublicationMatchedStatus.hpp>
#include <fastdds/dds/core/status/SubscriptionMatchedStatus.hpp>
#include <fastdds/dds/publisher/DataWriter.hpp>
#include <fastdds/dds/subscriber/DataReader.hpp>
#include <fastdds/dds/subscriber/DataReaderListener.hpp>
#include <fastdds/dds/subscriber/SampleInfo.hpp>

#include "participant_impl.hpp"

namespace tarmac::transport {

namespace detail {
/// Polls `count()` until it reaches `n` or `timeout` passes. For tests, tools and startup only.
template <typename CountFn>
bool wait_until_count(CountFn count, std::size_t n, std::chrono::milliseconds timeout) {
  const auto deadline = std::chrono::steady_clock::now() + timeout;
  while (count() < n) {
    if (std::chrono::steady_clock::now() >= deadline) return false;
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  return true;
}
}  // namespace detail

/// Writes samples of one fastddsgen type (`PubSubType::type`) on one topic.
template <typename PubSubType>
class Writer {
 public:
  using Message = typename PubSubType::type;

  /// @param partition the writer's DDS partition (empty: the default partition)
  static core::Result<std::unique_ptr<Writer>> create(const Participant& participant,
                                                      const std::string& topic_name,
                                                      const QosSpec& qos,
                                                      const std::string& partition = {}) {
    if (auto valid = qos.validate(); !valid) return valid.error();
    const auto& impl = participant.impl();
    auto topic = impl->topic(topic_name, fdds::TypeSupport(new PubSubType()));
    if (!topic) return topic.error();
    fdds::Publisher* publisher = impl->publisher(partition);
    fdds::DataWriter* writer =
        publisher == nullptr ? nullptr
                             : publisher->create_datawriter(topic.value(), to_writer_qos(qos));
    if (writer == nullptr) {
      return core::Error{"dds.writer", "cannot create a writer on " + topic_name +
                                           (partition.empty() ? "" : " in partition " + partition) +
                                           security_refusal_hint(*impl)};
    }
    return std::unique_ptr<Writer>(new Writer(impl, publisher, writer));
  }

  ~Writer() { publisher_->delete_datawriter(writer_); }
  Writer(const Writer&) = delete;
  Writer& operator=(const Writer&) = delete;

  /// Publishes one sample; false when Fast DDS refuses it (e.g. history full while reliable).
  bool write(const Message& message) {
    // Fast DDS takes a non-const pointer but does not modify the sample.
    return writer_->write(const_cast<Message*>(
        &message));  // NOLINT(cppcoreguidelines-pro-type-const-cast): API quirk
  }

  [[nodiscard]] std::size_t matched_readers() const {
    fdds::PublicationMatchedStatus status;
    writer_->get_publication_matched_status(status);
    return static_cast<std::size_t>(status.current_count);
  }

  /// Waits until at least `n` readers matched. Not for the cycle.
  bool wait_for_readers(std::size_t n, std::chrono::milliseconds timeout) const {
    return detail::wait_until_count([this] { return matched_readers(); }, n, timeout);
  }

  /// Waits until every reliable reader acknowledged what was written. Not for the cycle.
  bool wait_for_acknowledgments(std::chrono::milliseconds timeout) {
    const eprosima::fastrtps::Duration_t max_wait(static_cast<double>(timeout.count()) / 1000.0);
    return writer_->wait_for_acknowledgments(max_wait) == ReturnCode_t::RETCODE_OK;
  }

 private:
  Writer(std::shared_ptr<ParticipantImpl> impl, fdds::Publisher* publisher,
         fdds::DataWriter* writer)
      : impl_(std::move(impl)), publisher_(publisher), writer_(writer) {}

  std::shared_ptr<ParticipantImpl> impl_;
  fdds::Publisher* publisher_;
  fdds::DataWriter* writer_;
};

/// Reads samples of one fastddsgen type into a bounded queue.
template <typename PubSubType>
class Reader : private fdds::DataReaderListener {
 public:
  using Message = typename PubSubType::type;

  /// @param queue_capacity samples kept between drains; when full the oldest is dropped.
  /// @param partition the reader's DDS partition, wildcards allowed (empty: the default one)
  static core::Result<std::unique_ptr<Reader>> create(const Participant& participant,
                                                      const std::string& topic_name,
                                                      const QosSpec& qos,
                                                      std::size_t queue_capacity,
                                                      const std::string& partition = {}) {
    if (auto valid = qos.validate(); !valid) return valid.error();
    if (queue_capacity == 0) return core::Error{"config.qos", "queue_capacity: must be >= 1"};
    const auto& impl = participant.impl();
    auto topic = impl->topic(topic_name, fdds::TypeSupport(new PubSubType()));
    if (!topic) return topic.error();
    std::unique_ptr<Reader> reader(new Reader(impl, queue_capacity));
    reader->subscriber_ = impl->subscriber(partition);
    if (reader->subscriber_ == nullptr) {
      return core::Error{"dds.reader", "cannot create a subscriber in partition " + partition +
                                           security_refusal_hint(*impl)};
    }
    // The listener is attached at creation so no sample arrives unseen.
    // Lost and rejected samples too: a scan lost in transport (fragments overflowing a socket
    // buffer, a gap in a best-effort stream) is counted, never silent.
    reader->reader_ = reader->subscriber_->create_datareader(
        topic.value(), to_reader_qos(qos), reader.get(),
        fdds::StatusMask::data_available()
            << fdds::StatusMask::sample_lost() << fdds::StatusMask::sample_rejected());
    if (reader->reader_ == nullptr) {
      return core::Error{"dds.reader",
                         "cannot create a reader on " + topic_name + security_refusal_hint(*impl)};
    }
    return reader;
  }

  ~Reader() override {
    if (reader_ != nullptr) {
      reader_->set_listener(nullptr);
      subscriber_->delete_datareader(reader_);
    }
  }
  Reader(const Reader&) = delete;
  Reader& operator=(const Reader&) = delete;

  /// Moves every queued sample to the end of `out`, oldest first; never blocks on DDS.
  /// Returns the number moved.
  std::size_t take_all(std::vector<Message>& out) {
    std::lock_guard lock(mutex_);
    const std::size_t n = queue_.size();
    for (auto& message : queue_) out.push_back(std::move(message));
    queue_.clear();
    return n;
  }

  /// Blocks until at least one sample is queued or `timeout` passes. Not for the cycle.
  bool wait_for_sample(std::chrono::milliseconds timeout) {
    std::unique_lock lock(mutex_);
    return cv_.wait_for(lock, timeout, [this] { return !queue_.empty(); });
  }

  /// Samples dropped because the queue was full (oldest first), since creation.
  [[nodiscard]] std::uint64_t dropped() const { return dropped_.load(); }
  /// Samples received, since creation.
  [[nodiscard]] std::uint64_t received() const { return received_.load(); }
  /// Samples DDS reports lost before they reached this reader (SAMPLE_LOST), since creation.
  [[nodiscard]] std::uint64_t lost() const { return lost_.load(); }
  /// Samples DDS received but refused for lack of resources (SAMPLE_REJECTED), since creation.
  [[nodiscard]] std::uint64_t rejected() const { return rejected_.load(); }

  [[nodiscard]] std::size_t matched_writers() const {
    fdds::SubscriptionMatchedStatus status;
    reader_->get_subscription_matched_status(status);
    return static_cast<std::size_t>(status.current_count);
  }

  bool wait_for_writers(std::size_t n, std::chrono::milliseconds timeout) const {
    return detail::wait_until_count([this] { return matched_writers(); }, n, timeout);
  }

 private:
  Reader(std::shared_ptr<ParticipantImpl> impl, std::size_t capacity)
      : impl_(std::move(impl)), capacity_(capacity) {}

  void on_data_available(fdds::DataReader* reader) override {
    Message message;
    fdds::SampleInfo info;
    while (reader->take_next_sample(&message, &info) == ReturnCode_t::RETCODE_OK) {
      if (!info.valid_data) continue;
      received_.fetch_add(1);
      {
        std::lock_guard lock(mutex_);
        if (queue_.size() == capacity_) {
          queue_.pop_front();
          dropped_.fetch_add(1);
        }
        queue_.push_back(std::move(message));
      }
      cv_.notify_all();
      message = Message();
    }
  }

  void on_sample_lost(fdds::DataReader* /*reader*/, const fdds::SampleLostStatus& status) override {
    if (status.total_count_change > 0) {
      lost_.fetch_add(static_cast<std::uint64_t>(status.total_count_change));
    }
  }

  void on_sample_rejected(fdds::DataReader* /*reader*/,
                          const fdds::SampleRejectedStatus& status) override {
    if (status.total_count_change > 0) {
      rejected_.fetch_add(static_cast<std::uint64_t>(status.total_count_change));
    }
  }

  std::shared_ptr<ParticipantImpl> impl_;
  fdds::Subscriber* subscriber_ = nullptr;
  fdds::DataReader* reader_ = nullptr;
  const std::size_t capacity_;
  std::mutex mutex_;
  std::condition_variable cv_;
  std::deque<Message> queue_;
  std::atomic<std::uint64_t> dropped_{0};
  std::atomic<std::uint64_t> received_{0};
  std::atomic<std::uint64_t> lost_{0};
  std::atomic<std::uint64_t> rejected_{0};
};

}  // namespace tarmac::transport
