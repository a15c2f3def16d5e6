#include "tarmac/core/distance_field.hpp"

#include <cmath>
#include <random>

#include <gtest/gtest.h>

namespace tarmac::core {
namespace {

/// Small runner that runs tasks in reverse order: results must not depend on task order.
class ReverseRunner final : public TaskRunner {
 public:
  void parallel_for(std::size_t count, TaskFn fn) override {
    for (std::size_t i = count; i-- > 0;) fn(i);
  }
  [[nodiscard]] std::size_t concurrency() const override { return 4; }
};

std::vector<CellState> random_states(const Eigen::Vector3i& dims, double p_occ, double p_unknown,
                                     std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::vector<CellState> states(static_cast<std::size_t>(dims.prod()));
  for (auto& s : states) {
    const double u = static_cast<double>(rng() >> 11) / 9007199254740992.0;
    s = u < p_occ ? CellState::kOccupied
                  : (u < p_occ + p_unknown ? CellState::kUnknown : CellState::kFree);
  }
  return states;
}

/// Brute force: squared distance (cell units) from every cell to every site.
void check_against_brute_force(const Eigen::Vector3i& dims, const std::vector<CellState>& states,
                               UnknownPolicy policy, const DistanceField& field) {
  const double cell = field.cell_size_m;
  std::vector<Eigen::Vector3i> sites;
  for (int z = 0; z < dims.z(); ++z)
    for (int y = 0; y < dims.y(); ++y)
      for (int x = 0; x < dims.x(); ++x) {
        const auto s = states[(static_cast<std::size_t>(z) * dims.y() + y) * dims.x() + x];
        if (s == CellState::kOccupied ||
            (s == CellState::kUnknown && policy == UnknownPolicy::kUnknownIsOccupied)) {
          sites.emplace_back(x, y, z);
        }
      }
  std::size_t i = 0;
  for (int z = 0; z < dims.z(); ++z)
    for (int y = 0; y < dims.y(); ++y)
      for (int x = 0; x < dims.x(); ++x, ++i) {
        if (states[i] == CellState::kUnknown && policy == UnknownPolicy::kReportUnknown) {
          ASSERT_TRUE(std::isnan(field.distance_m[i]));
          ASSERT_EQ(field.gradient_x[i], 0.0f);
          ASSERT_EQ(field.gradient_y[i], 0.0f);
          ASSERT_EQ(field.gradient_z[i], 0.0f);
          continue;
        }
        std::int64_t best = std::numeric_limits<std::int64_t>::max();
        for (const auto& s : sites) {
          const Eigen::Vector3i d = Eigen::Vector3i(x, y, z) - s;
          best = std::min<std::int64_t>(best, std::int64_t{d.x()} * d.x() +
                                                  std::int64_t{d.y()} * d.y() +
                                                  std::int64_t{d.z()} * d.z());
        }
        if (sites.empty()) {
          ASSERT_EQ(field.distance_m[i], std::numeric_limits<float>::infinity());
          continue;
        }
        const float expected = static_cast<float>(std::sqrt(static_cast<double>(best)) * cell);
        ASSERT_EQ(field.distance_m[i], expected) << "cell " << x << "," << y << "," << z;
        // The gradient points away from a nearest obstacle: following it back by the distance
        // lands exactly on an obstacle cell centre at that distance.
        if (best > 0) {
          const Eigen::Vector3d g(field.gradient_x[i], field.gradient_y[i], field.gradient_z[i]);
          ASSERT_NEAR(g.norm(), 1.0, 1e-6);
          const Eigen::Vector3d site =
              Eigen::Vector3d(x, y, z) - g * std::sqrt(static_cast<double>(best));
          const Eigen::Vector3i rounded = site.array().round().cast<int>();
          ASSERT_LT((site - rounded.cast<double>()).norm(), 1e-3);
          const auto s =
              states[(static_cast<std::size_t>(rounded.z()) * dims.y() + rounded.y()) * dims.x() +
                     rounded.x()];
          ASSERT_TRUE(s == CellState::kOccupied ||
                      (s == CellState::kUnknown && policy == UnknownPolicy::kUnknownIsOccupied));
        } else {
          ASSERT_EQ(field.gradient_x[i], 0.0f);
          ASSERT_EQ(field.gradient_y[i], 0.0f);
          ASSERT_EQ(field.gradient_z[i], 0.0f);
        }
      }
}

TEST(DistanceField, Exact2D_EqualsBruteForceOnRandomScenes) {
  SerialRunner runner;
  for (std::uint64_t seed = 1; seed <= 6; ++seed) {
    const Eigen::Vector3i dims(37 + seed, 29, 1);
    const auto states = random_states(dims, 0.002 * seed * seed, 0.1, seed);
    for (const auto policy : {UnknownPolicy::kReportUnknown, UnknownPolicy::kUnknownIsOccupied}) {
      DistanceField field;
      DistanceFieldScratch scratch;
      compute_distance_field(states, dims, 0.2, policy, field, scratch, runner);
      check_against_brute_force(dims, states, policy, field);
    }
  }
}

TEST(DistanceField, Exact3D_EqualsBruteForceOnRandomScenes) {
  SerialRunner runner;
  for (std::uint64_t seed = 11; seed <= 13; ++seed) {
    const Eigen::Vector3i dims(21, 17, 9);
    const auto states = random_states(dims, 0.003, 0.05, seed);
    DistanceField field;
    DistanceFieldScratch scratch;
    compute_distance_field(states, dims, 0.1, UnknownPolicy::kReportUnknown, field, scratch,
                           runner);
    check_against_brute_force(dims, states, UnknownPolicy::kReportUnknown, field);
  }
}

TEST(DistanceField, Exact3D_UnknownIsOccupied_EqualsBruteForce) {
  SerialRunner runner;
  for (std::uint64_t seed = 21; seed <= 23; ++seed) {
    const Eigen::Vector3i dims(19, 23, 7);
    const auto states = random_states(dims, 0.002, 0.004, seed);
    DistanceField field;
    DistanceFieldScratch scratch;
    compute_distance_field(states, dims, 0.2, UnknownPolicy::kUnknownIsOccupied, field, scratch,
                           runner);
    check_against_brute_force(dims, states, UnknownPolicy::kUnknownIsOccupied, field);
  }
}

// Very sparse scenes: most lines of every pass hold no obstacle, some planes none at all.
TEST(DistanceField, SparseScenes_EqualBruteForce) {
  SerialRunner runner;
  for (std::uint64_t seed = 31; seed <= 36; ++seed) {
    const Eigen::Vector3i dims2(53, 41, 1);
    const auto states2 = random_states(dims2, 0.0015, 0.2, seed);
    DistanceField field;
    DistanceFieldScratch scratch;
    compute_distance_field(states2, dims2, 0.2, UnknownPolicy::kReportUnknown, field, scratch,
                           runner);
    check_against_brute_force(dims2, states2, UnknownPolicy::kReportUnknown, field);
    const Eigen::Vector3i dims3(23, 19, 11);
    const auto states3 = random_states(dims3, 0.0004, 0.1, seed);
    compute_distance_field(states3, dims3, 0.2, UnknownPolicy::kReportUnknown, field, scratch,
                           runner);
    check_against_brute_force(dims3, states3, UnknownPolicy::kReportUnknown, field);
  }
}

// The field and scratch are reused across calls of other shapes (3D, then 2D, then 3D): every
// output, the 2D field's zero z gradient included, comes from the call that wrote it.
TEST(DistanceField, ReusedAcrossShapes_EqualsBruteForce) {
  SerialRunner runner;
  DistanceField field;
  DistanceFieldScratch scratch;
  const Eigen::Vector3i a(17, 13, 5), b(31, 27, 1), c(9, 21, 4);
  for (const auto& dims : {a, b, c, b}) {
    const auto states = random_states(dims, 0.01, 0.1, static_cast<std::uint64_t>(dims.prod()));
    compute_distance_field(states, dims, 0.2, UnknownPolicy::kReportUnknown, field, scratch,
                           runner);
    check_against_brute_force(dims, states, UnknownPolicy::kReportUnknown, field);
    if (dims.z() == 1) {
      for (const float g : field.gradient_z) ASSERT_EQ(g, 0.0f);
    }
  }
}

// Many layers (the z pass is a minimum over all layers, keyed by layer in the low bits) and the
// longest sides the transform takes (4096, the window limit): the envelope's integer division
// by reciprocal and the 64-bit layer keys (sides too long for 32-bit ones) stay exact.
TEST(DistanceField, ManyLayersAndLongestSides_EqualBruteForce) {
  SerialRunner runner;
  DistanceField field;
  DistanceFieldScratch scratch;
  const Eigen::Vector3i tall(13, 11, 70);
  const auto states = random_states(tall, 0.004, 0.1, 7);
  compute_distance_field(states, tall, 0.2, UnknownPolicy::kReportUnknown, field, scratch, runner);
  check_against_brute_force(tall, states, UnknownPolicy::kReportUnknown, field);
  const Eigen::Vector3i wide(4096, 3, 65);  // 64-bit layer keys
  auto sparse = random_states(wide, 0.0, 0.05, 8);
  for (const int i : {0, 4095 + 4096 * 2, 4096 * 3 * 64 + 2000, 4096 * 3 * 40 + 4096 + 17}) {
    sparse[static_cast<std::size_t>(i)] = CellState::kOccupied;
  }
  compute_distance_field(sparse, wide, 0.2, UnknownPolicy::kReportUnknown, field, scratch, runner);
  check_against_brute_force(wide, sparse, UnknownPolicy::kReportUnknown, field);
  // 2D, 4096 × 4096, three corner sites: squared distances up to 2 · 4095².
  const Eigen::Vector3i big(4096, 4096, 1);
  std::vector<CellState> corners(static_cast<std::size_t>(big.prod()), CellState::kFree);
  corners[0] = CellState::kOccupied;
  corners[4095] = CellState::kOccupied;
  corners[static_cast<std::size_t>(4096) * 4095 + 1] = CellState::kOccupied;
  compute_distance_field(corners, big, 0.2, UnknownPolicy::kReportUnknown, field, scratch, runner);
  check_against_brute_force(big, corners, UnknownPolicy::kReportUnknown, field);
}

TEST(DistanceField, NoObstacle_IsInfinite) {
  SerialRunner runner;
  const Eigen::Vector3i dims(5, 4, 1);
  std::vector<CellState> states(20, CellState::kFree);
  DistanceField field;
  DistanceFieldScratch scratch;
  compute_distance_field(states, dims, 0.2, UnknownPolicy::kReportUnknown, field, scratch, runner);
  for (const float d : field.distance_m) EXPECT_EQ(d, std::numeric_limits<float>::infinity());
}

TEST(DistanceField, SameResultForAnyTaskOrder) {
  const Eigen::Vector3i dims(64, 48, 6);
  const auto states = random_states(dims, 0.01, 0.1, 99);
  SerialRunner serial;
  ReverseRunner reverse;
  DistanceField a, b;
  DistanceFieldScratch sa, sb;
  compute_distance_field(states, dims, 0.2, UnknownPolicy::kReportUnknown, a, sa, serial);
  compute_distance_field(states, dims, 0.2, UnknownPolicy::kReportUnknown, b, sb, reverse);
  EXPECT_EQ(0, std::memcmp(a.distance_m.data(), b.distance_m.data(), a.distance_m.size() * 4));
  EXPECT_EQ(a.gradient_x, b.gradient_x);
  EXPECT_EQ(a.gradient_y, b.gradient_y);
  EXPECT_EQ(a.gradient_z, b.gradient_z);
}

}  // namespace
}  // namespace tarmac::core
