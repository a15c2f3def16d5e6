#include "tarmac/tools/phase_runner.hpp"

#include <algorithm>
#include <cstdio>

#include "tarmac/tools/stats.hpp"

namespace tarmac::tools {

namespace {

double ms_between(std::chrono::steady_clock::time_point a,
                  std::chrono::steady_clock::time_point b) {
  return std::chrono::duration<double, std::milli>(b - a).count();
}

/// p50 as every other table of the tools reads it.
double median(const std::vector<double>& v) {
  return percentile(v, 0.5);
}

std::string format(const char* fmt, double a, double b) {
  char buf[96];
  std::snprintf(buf, sizeof buf, fmt, a, b);
  return buf;
}

}  // namespace

void PhaseRunner::begin_stage() {
  stage_ = StagePhases{};
  last_ = Clock::now();
}

StagePhases PhaseRunner::end_stage() {
  stage_.serial_ms.push_back(ms_between(last_, Clock::now()));
  return std::move(stage_);
}

void PhaseRunner::parallel_for(std::size_t count, core::TaskFn fn) {
  const Clock::time_point t0 = Clock::now();
  stage_.serial_ms.push_back(ms_between(last_, t0));
  StagePhases::Call call;
  call.task_ms.assign(count, 0.0);
  inner_.parallel_for(count, [&](std::size_t task) {
    const Clock::time_point a = Clock::now();
    fn(task);
    call.task_ms[task] = ms_between(a, Clock::now());
  });
  last_ = Clock::now();
  call.wall_ms = ms_between(t0, last_);
  stage_.calls.push_back(std::move(call));
}

std::string summarize_phases(const std::string& stage, const std::vector<StagePhases>& scans,
                             std::size_t max_tasks_listed) {
  std::string out;
  if (scans.empty()) return out;
  // The scans whose stage made the most common sequence of calls (a stage may skip a call on
  // some scans, e.g. the window's scroll when the vehicle did not move a voxel).
  // (A shape: the task count of each call; ties go to the earliest scan's.)
  std::vector<std::vector<std::size_t>> shapes;
  for (const StagePhases& s : scans) {
    auto& tasks = shapes.emplace_back();
    for (const auto& c : s.calls) tasks.push_back(c.task_ms.size());
  }
  std::size_t best = 0;
  for (std::size_t k = 1; k < shapes.size(); ++k) {
    if (std::count(shapes.begin(), shapes.end(), shapes[k]) >
        std::count(shapes.begin(), shapes.end(), shapes[best])) {
      best = k;
    }
  }
  const std::vector<std::size_t>& common = shapes[best];
  const std::size_t calls = common.size();
  std::vector<const StagePhases*> same;
  for (std::size_t k = 0; k < scans.size(); ++k) {
    if (shapes[k] == common) same.push_back(&scans[k]);
  }
  char head[160];
  std::snprintf(head, sizeof head,
                "  %s: %zu parallel_for calls, %zu of %zu scans alike (ms: mean / p50)\n",
                stage.c_str(), calls, same.size(), scans.size());
  out += head;
  const auto column = [&](auto get) {
    std::vector<double> v;
    v.reserve(same.size());
    for (const StagePhases* s : same) v.push_back(get(*s));
    return v;
  };
  for (std::size_t c = 0; c <= calls; ++c) {
    const auto serial = column([&](const StagePhases& s) { return s.serial_ms[c]; });
    out += "    serial" + std::string(c == calls ? " (end)" : "      ") + "          " +
           format("%7.3f / %7.3f\n", mean(serial), median(serial));
    if (c == calls) break;
    const std::size_t tasks = common[c];
    const auto wall = column([&](const StagePhases& s) { return s.calls[c].wall_ms; });
    char label[64];
    std::snprintf(label, sizeof label, "    parallel_for #%zu, %2zu tasks", c + 1, tasks);
    out += label + format(" %7.3f / %7.3f", mean(wall), median(wall));
    if (tasks <= max_tasks_listed) {
      out += "   task p50:";
      for (std::size_t t = 0; t < tasks; ++t) {
        const auto task = column([&](const StagePhases& s) { return s.calls[c].task_ms[t]; });
        char buf[32];
        std::snprintf(buf, sizeof buf, " %.3f", median(task));
        out += buf;
      }
    } else {
      const auto longest = column([&](const StagePhases& s) {
        return *std::max_element(s.calls[c].task_ms.begin(), s.calls[c].task_ms.end());
      });
      const auto sum = column([&](const StagePhases& s) {
        double x = 0.0;
        for (const double t : s.calls[c].task_ms) x += t;
        return x;
      });
      out += format("   p50 longest task %.3f, of all tasks %.3f", median(longest), median(sum));
    }
    out += "\n";
  }
  return out;
}

}  // namespace tarmac::tools
