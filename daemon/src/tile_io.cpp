// The tile store's disk thread (tile_io.hpp).

#include "tile_io.hpp"

#include <filesystem>
#include <string>
#include <utility>
#include <vector>

#include <pthread.h>
#include <sched.h>

namespace tarmac::daemon {

TileIo::TileIo(TileFiles files) : files_(std::move(files)) {
  worker_ = std::thread([this] { run(); });
}

TileIo::~TileIo() {
  {
    std::lock_guard lock(mutex_);
    stopping_ = true;
  }
  wake_worker_.notify_all();
  if (worker_.joinable()) worker_.join();
}

void TileIo::submit(TileWork work) {
  {
    std::lock_guard lock(mutex_);
    jobs_.push_back(std::move(work));
  }
  wake_worker_.notify_one();
}

void TileIo::take_done(std::deque<TileWork>& out) {
  out.clear();
  std::lock_guard lock(mutex_);
  out.swap(done_);
}

bool TileIo::wait_done(std::deque<TileWork>& out) {
  out.clear();
  std::unique_lock lock(mutex_);
  wake_waiter_.wait(lock, [&] { return !done_.empty() || (jobs_.empty() && busy_ == 0); });
  out.swap(done_);
  return !out.empty();
}

std::size_t TileIo::queued() const {
  std::lock_guard lock(mutex_);
  return jobs_.size() + busy_;
}

void TileIo::run() {
  // The cycle's threads may run SCHED_FIFO; the disk work must never compete with them.
  sched_param sp{};
  pthread_setschedparam(pthread_self(), SCHED_OTHER, &sp);
  std::unique_lock lock(mutex_);
  while (true) {
    wake_worker_.wait(lock, [&] { return stopping_ || !jobs_.empty(); });
    if (jobs_.empty()) return;
    TileWork w = std::move(jobs_.front());
    jobs_.pop_front();
    ++busy_;
    lock.unlock();
    work(w);
    lock.lock();
    --busy_;
    done_.push_back(std::move(w));
    wake_waiter_.notify_all();
  }
}

void TileIo::work(TileWork& w) const {
  switch (w.kind) {
    case TileWork::Kind::kWriteTsdf: return write_tsdf(w);
    case TileWork::Kind::kReadTsdf: return read_tsdf(w);
    case TileWork::Kind::kWriteStatic: return write_static(w);
    case TileWork::Kind::kReadStatic: return read_static(w);
    case TileWork::Kind::kDropStatics: return drop_statics();
  }
}

void TileIo::write_tsdf(TileWork& w) const {
  const std::vector<std::uint8_t> bytes = w.data->encode(files_.voxel_size_m, files_.truncation_m);
  w.bytes = bytes.size();
  if (const core::Status s = write_file_atomic(files_.tsdf_file(w.tile), bytes); !s) {
    w.error = s.error();  // the tile goes back to the layer: nothing is lost
    return;
  }
  w.data.reset();  // written: the memory goes back now, on this thread
}

void TileIo::read_tsdf(TileWork& w) const {
  core::Result<core::TsdfTile> t = files_.read_tsdf(w.tile);
  if (t) {
    w.data = std::move(t).value();
    return;
  }
  w.error = t.error();
  std::error_code ec;
  const std::filesystem::path file = files_.tsdf_file(w.tile);
  std::filesystem::rename(file, file.string() + ".refused", ec);
}

void TileIo::write_static(TileWork& w) const {
  const std::vector<std::uint8_t> bytes = w.static_data.encode(files_.occupancy_voxel_m);
  w.bytes = bytes.size();
  if (const core::Status s = write_file_atomic(files_.static_file(w.static_data.index), bytes);
      !s) {
    w.error = s.error();
  }
}

void TileIo::read_static(TileWork& w) const {
  const core::StaticTileIndex t = w.static_data.index;
  core::Result<core::StaticTile> read = files_.read_static(t);
  if (read) {
    w.static_data = std::move(read).value();
    return;
  }
  w.error = read.error();
  w.static_data = core::StaticTile{t, {}};
  std::error_code ec;
  const std::filesystem::path file = files_.static_file(t);
  std::filesystem::rename(file, file.string() + ".refused", ec);
}

void TileIo::drop_statics() const {
  std::error_code ec;
  for (const auto& f : std::filesystem::directory_iterator(files_.dir, ec)) {
    if (parse_static_file_name(f.path().filename().string())) std::filesystem::remove(f.path(), ec);
  }
}

}  // namespace tarmac::daemon
