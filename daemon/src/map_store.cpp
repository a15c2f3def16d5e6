#include "map_store.hpp"

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <exception>
#include <utility>
#include <vector>

#include <fcntl.h>
#include <sys/resource.h>
#include <unistd.h>

#include <spdlog/spdlog.h>

#include "tarmac/daemon/clock.hpp"

namespace tarmac::daemon {

namespace {
using Clock = std::chrono::steady_clock;
}  // namespace

MapStore::MapStore(const config::Config& config, std::string hash)
    : state_(config.state),
      tsdf_(config.mapping.tsdf),
      static_voxel_size_m_(static_cast<float>(config.mapping.occupancy.voxel_size_m)),
      frame_id_(config.outputs.frame_id),
      hash_(std::move(hash)) {}

MapStore::~MapStore() {
  if (saver_.joinable()) stop_saver();
}

std::filesystem::path MapStore::tsdf_path() const {
  return std::filesystem::path(state_.dir) / state_.tsdf_file;
}

core::TsdfMapInfo MapStore::tsdf_info(std::int64_t newest_stamp_ns) const {
  core::TsdfMapInfo info;
  info.frame_id = frame_id_;
  info.config_hash = hash_;
  // A save made before the first scan after a restart holds the loaded map: its stamp.
  info.stamp_ns = std::max(newest_stamp_ns, loaded_stamp_ns_);
  return info;
}

core::StaticOccupancy MapStore::static_occupancy(const core::Mapper& mapper) const {
  core::StaticOccupancy s;
  s.voxel_size_m = static_voxel_size_m_;
  // Paged, the static layer is in the tile store (the pager's store_all / store_changed).
  if (!pager_) mapper.occupancy().export_static(s.voxels);
  return s;
}

core::Status MapStore::save_window(const core::OccupancyMap& map, std::int64_t stamp_ns) const {
  const std::filesystem::path dir = state_.dir;
  std::error_code ec;
  std::filesystem::create_directories(dir, ec);
  if (ec) return core::Error{"state.io", state_.dir + ": " + ec.message()};
  std::vector<float> log_odds;
  map.export_log_odds(log_odds);
  const std::filesystem::path file = dir / state_.map_file;
  const std::filesystem::path tmp = file.string() + ".tmp";
  // A self-describing header line, then float32 log-odds in window order (x fastest).
  const auto dims = map.window_size();
  const auto& min = map.window_min();
  char header[256];
  const int n =
      std::snprintf(header, sizeof header,
                    "tarmac occupancy window v1 voxel_size_m %.6f min_vox %d %d %d dims %d %d %d "
                    "stamp_ns %lld float32-log-odds unknown=-1e9\n",
                    map.params().voxel_size_m, min.x(), min.y(), min.z(), dims.x(), dims.y(),
                    dims.z(), static_cast<long long>(stamp_ns));
  const int fd = ::open(tmp.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
  if (fd < 0) return core::Error{"state.io", tmp.string() + ": cannot be written"};
  const auto write_all = [fd](const void* data, std::size_t size) {
    const auto* p = static_cast<const char*>(data);
    while (size > 0) {
      const ssize_t w = ::write(fd, p, size);
      if (w < 0 && errno == EINTR) continue;
      if (w <= 0) return false;
      p += w;
      size -= static_cast<std::size_t>(w);
    }
    return true;
  };
  // On the device before the rename: after a power cut the file is the old save or the new
  // one, never a new name over unwritten blocks.
  const bool written = write_all(header, static_cast<std::size_t>(n)) &&
                       write_all(log_odds.data(), log_odds.size() * sizeof(float)) &&
                       ::fsync(fd) == 0;
  ::close(fd);
  if (!written) return core::Error{"state.io", tmp.string() + ": write failed"};
  std::filesystem::rename(tmp, file, ec);
  if (ec) return core::Error{"state.io", file.string() + ": " + ec.message()};
  if (const int dfd = ::open(dir.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC); dfd >= 0) {
    ::fsync(dfd);  // the rename itself; best effort, it is atomic either way
    ::close(dfd);
  }
  return core::Ok{};
}

core::Status MapStore::save_tsdf(core::Mapper& mapper, std::int64_t newest_stamp_ns) {
  std::error_code ec;
  std::filesystem::create_directories(state_.dir, ec);
  if (ec) return core::Error{"state.io", state_.dir + ": " + ec.message()};
  const core::StaticOccupancy occupancy = static_occupancy(mapper);
  if (pager_) {
    if (auto stored = pager_->store_all(mapper.tsdf()); !stored) return stored;
    const core::TsdfLayer none(tsdf_.voxel_size_m, tsdf_.truncation_m);
    return core::save_tsdf(tsdf_path(), none, tsdf_info(newest_stamp_ns), &occupancy);
  }
  return core::save_tsdf(tsdf_path(), mapper.tsdf(), tsdf_info(newest_stamp_ns), &occupancy);
}

core::Status MapStore::open_pager(core::Mapper& mapper) {
  if (pager_ || !tsdf_.enabled || tsdf_.resident_limit_mb == 0) return core::Ok{};
  TsdfPagerParams p = TsdfPagerParams::for_mapper(mapper.params(),
                                                  std::filesystem::path(state_.dir) / "tsdf_tiles");
  // tarmacd never waits for a tile: a late one is counted (its samples refused), not waited for.
  p.wait_for_loads = false;
  const bool loaded_blocks =
      mapper.tsdf().block_count() > 0 || mapper.occupancy().static_count() > 0;
  p.resume = state_.load_on_start && !loaded_blocks;
  if (loaded_blocks) {
    spdlog::warn(
        "state: {} holds a TSDF or static occupancy (saved without tsdf.resident_limit_mb): it "
        "is the map, the tile store {} is emptied",
        tsdf_path().string(), p.dir.string());
  }
  auto opened = TsdfPager::open(p, mapper.tsdf(), &mapper.occupancy());
  if (!opened) return opened.error();
  pager_ = std::move(opened).value();
  const TsdfPagerStats st = pager_->stats();
  spdlog::info("state: TSDF paged through {} (limit {} MiB): {} tiles stored, {:.1f} MiB",
               p.dir.string(), tsdf_.resident_limit_mb, st.stored_tiles,
               static_cast<double>(st.stored_bytes) / (1024.0 * 1024.0));
  return core::Ok{};
}

TsdfLoadResult MapStore::load_tsdf(core::Mapper& mapper) {
  TsdfLoadResult result;
  if (!tsdf_.enabled || !state_.load_on_start) return result;
  const std::filesystem::path file = tsdf_path();
  std::error_code ec;
  // A save cut short (a crash, kill -9, power loss) leaves its .tmp; the file itself is only
  // ever replaced whole (rename), so it is the last complete save.
  const std::filesystem::path partial = file.string() + ".tmp";
  if (std::filesystem::exists(partial, ec)) {
    std::filesystem::remove(partial, ec);
    spdlog::warn(
        "state: {} is a save cut short (crash or kill); removed, the last complete "
        "save is {}",
        partial.string(), file.string());
  }
  if (!std::filesystem::exists(file, ec)) {
    result.kind = TsdfLoadResult::Kind::kAbsent;
    spdlog::info("state: no saved TSDF at {}; starting with an empty TSDF", file.string());
    return result;
  }
  core::Status checked = core::Ok{};
  core::Result<core::LoadedTsdf> loaded = core::Error{"tsdf_io.open", "not read"};
  try {
    loaded = core::load_tsdf(file);
    checked = loaded ? core::check_tsdf_matches(loaded.value().info, frame_id_, tsdf_.voxel_size_m,
                                                tsdf_.truncation_m)
                     : core::Status(loaded.error());
    if (checked) {
      checked =
          core::check_static_occupancy_matches(loaded.value().occupancy, static_voxel_size_m_);
      if (!checked) {
        checked = core::Error{checked.error().code, file.string() + ": " + checked.error().message};
      }
    }
  } catch (const std::exception& e) {
    checked = core::Error{"tsdf_io.corrupt", file.string() + ": " + e.what()};
  }
  if (!checked) {
    result.kind = TsdfLoadResult::Kind::kRefused;
    result.error = checked.error().code + ": " + checked.error().message;
    // Kept aside for inspection, and so the save on exit does not overwrite the evidence.
    const std::filesystem::path aside = file.string() + ".refused";
    std::filesystem::rename(file, aside, ec);
    spdlog::error("state: saved TSDF {} refused ({}); starting with an empty TSDF ({})",
                  file.string(), result.error,
                  ec ? "could not be moved aside: " + ec.message() : "moved to " + aside.string());
    return result;
  }
  auto& map = loaded.value();
  if (map.info.config_hash != hash_) {
    spdlog::warn(
        "state: saved TSDF was built with config {} (now {}); frame, voxel size and "
        "truncation match, so it is used",
        map.info.config_hash, hash_);
  }
  result.kind = TsdfLoadResult::Kind::kLoaded;
  result.voxels = map.layer.voxel_count();
  result.static_voxels = map.occupancy.voxels.size();
  loaded_stamp_ns_ = map.info.stamp_ns;
  mapper.tsdf() = std::move(map.layer);
  mapper.occupancy().import_static(map.occupancy.voxels);
  spdlog::info(
      "state: TSDF loaded from {}: {} voxels in {} blocks, static occupancy {} voxels (saved at "
      "stamp {} ns)",
      file.string(), result.voxels, mapper.tsdf().block_count(), result.static_voxels,
      map.info.stamp_ns);
  return result;
}

bool MapStore::periodic() const {
  return tsdf_.enabled && state_.save_period_s > 0.0;
}

std::uint64_t MapStore::period_ticks(double rate_hz) const {
  return static_cast<std::uint64_t>(std::max(1.0, std::round(state_.save_period_s * rate_hz)));
}

void MapStore::start_saver() {
  saver_ = std::thread([this] { saver_loop(); });
}

void MapStore::stop_saver() {
  {
    std::lock_guard lock(saver_mutex_);
    saver_stop_ = true;
  }
  saver_wake_.notify_one();
  saver_.join();
}

MapStore::SaveCounts MapStore::counts() const {
  return {saves_.load(), failures_.load(), skipped_.load()};
}

void MapStore::snapshot(core::Mapper& mapper, std::int64_t newest_stamp_ns) {
  if (saver_busy_.load()) {
    ++skipped_;
    spdlog::warn("state: periodic TSDF save skipped, the previous one is still being written");
    return;
  }
  const auto t0 = Clock::now();
  std::unique_ptr<core::TsdfLayer> copy;
  if (pager_) {
    // The tiles changed since they were last stored, copied now and written by the pager's
    // thread; the file keeps the static occupancy.
    pager_->store_changed(mapper.tsdf());
    copy = std::make_unique<core::TsdfLayer>(tsdf_.voxel_size_m, tsdf_.truncation_m);
  } else {
    copy = std::make_unique<core::TsdfLayer>(mapper.tsdf().clone());
  }
  core::StaticOccupancy static_copy = static_occupancy(mapper);
  const double copy_ms = ms_between(t0, Clock::now());
  saver_busy_ = true;
  {
    std::lock_guard lock(saver_mutex_);
    saver_snapshot_ = std::move(copy);
    saver_static_ = std::move(static_copy);
    saver_info_ = tsdf_info(newest_stamp_ns);
  }
  saver_wake_.notify_one();
  spdlog::debug("state: TSDF snapshot for the periodic save copied in {:.1f} ms", copy_ms);
}

void MapStore::saver_loop() {
  setpriority(PRIO_PROCESS, static_cast<id_t>(gettid()), 10);  // best effort: below the cycle
  std::unique_lock lock(saver_mutex_);
  while (true) {
    saver_wake_.wait(lock, [this] { return saver_stop_ || saver_snapshot_ != nullptr; });
    if (saver_snapshot_ == nullptr) return;  // stop requested, nothing pending
    std::unique_ptr<core::TsdfLayer> layer = std::move(saver_snapshot_);
    const core::StaticOccupancy occupancy = std::move(saver_static_);
    const core::TsdfMapInfo info = saver_info_;
    lock.unlock();
    // Said before the write: after a crash, the log shows whether one was in flight (its
    // .tmp is left behind, the previous complete save stands).
    spdlog::info("state: periodic TSDF save to {} started ({} voxels, stamp {} ns)",
                 tsdf_path().string(), layer->voxel_count(), info.stamp_ns);
    const auto t0 = Clock::now();
    std::error_code ec;
    std::filesystem::create_directories(state_.dir, ec);
    const core::Status saved = core::save_tsdf(tsdf_path(), *layer, info, &occupancy);
    const double ms = ms_between(t0, Clock::now());
    ++(saved ? saves_ : failures_);
    if (saved) {
      spdlog::info("state: periodic TSDF save to {} ({} voxels, stamp {} ns) in {:.0f} ms",
                   tsdf_path().string(), layer->voxel_count(), info.stamp_ns, ms);
    } else {
      spdlog::error("state: periodic TSDF save failed: {} [{}]", saved.error().message,
                    saved.error().code);
    }
    layer.reset();
    saver_busy_ = false;
    lock.lock();
  }
}

}  // namespace tarmac::daemon
