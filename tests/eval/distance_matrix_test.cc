// The distance-matrix builder against a serial double loop, on several
// thread counts, with per-worker state; the leave-one-out queries it gives.
#include "eval/lib/distance_matrix.h"

#include <gtest/gtest.h>

#include <atomic>
#include <cmath>
#include <set>
#include <thread>

#include "common/parallel.h"

namespace tpr::eval {
namespace {

double Oracle(size_t i, size_t j) {
  return std::abs(std::sin(static_cast<double>(i)) -
                  std::sin(static_cast<double>(j)));
}

TEST(DistanceMatrixTest, MatchesTheSerialLoopOnAnyThreadCount) {
  for (size_t n : {0, 1, 2, 7, 40}) {
    for (int threads : {1, 2, 5, 64}) {
      std::atomic<int> workers{0};
      double thread_ms = -1;
      const DistanceMatrix d = PairwiseDistances(
          n, threads,
          [&] {
            ++workers;
            // Per-worker state: a call counter no other thread touches.
            return [calls = 0](size_t i, size_t j) mutable {
              ++calls;
              return Oracle(i, j);
            };
          },
          &thread_ms);
      ASSERT_EQ(d.size(), n);
      EXPECT_GE(thread_ms, 0.0);
      EXPECT_LE(workers.load(),
                std::max(1, std::min<int>(threads, std::max<size_t>(1, n))));
      for (size_t i = 0; i < n; ++i) {
        EXPECT_EQ(d(i, i), 0.0);
        for (size_t j = 0; j < n; ++j) {
          if (i != j) {
            EXPECT_EQ(d(i, j), Oracle(std::min(i, j), std::max(i, j)));
          }
        }
      }
    }
  }
}

TEST(DistanceMatrixTest, LeaveOneOutQueriesRankEveryOtherModel) {
  const DistanceMatrix d = PairwiseDistances(5, 2, [] { return Oracle; });
  const std::vector<Query> queries = LeaveOneOutQueries(d);
  ASSERT_EQ(queries.size(), 5u);
  for (size_t i = 0; i < queries.size(); ++i) {
    EXPECT_EQ(queries[i].model, static_cast<int>(i));
    std::set<int> seen;
    for (const Retrieved& r : queries[i].ranking) {
      EXPECT_NE(r.model, static_cast<int>(i));
      EXPECT_EQ(r.distance, d(i, r.model));
      seen.insert(r.model);
    }
    EXPECT_EQ(seen.size(), 4u);
  }
}

TEST(ParallelForTest, VisitsEveryIndexExactlyOnce) {
  for (int threads : {0, 1, 3, 16}) {
    std::vector<std::atomic<int>> visits(1000);
    common::ParallelFor(visits.size(), threads, [&](size_t i) { ++visits[i]; });
    for (const auto& v : visits) EXPECT_EQ(v.load(), 1);
  }
}

// Separation against a hand count: within = d(0,1) = 1, between =
// mean(4, 2) = 3.
TEST(DistanceMatrixTest, SeparationAndRestrict) {
  DistanceMatrix d(3);
  d.Set(0, 1, 1.0);
  d.Set(0, 2, 4.0);
  d.Set(1, 2, 2.0);
  const ClassSeparation s = Separation({"a", "a", "b"}, d);
  EXPECT_DOUBLE_EQ(s.within, 1.0);
  EXPECT_DOUBLE_EQ(s.between, 3.0);
  EXPECT_DOUBLE_EQ(s.Ratio(), 1.0 / 3.0);
  EXPECT_EQ(Separation({"a", "a", "a"}, d).Ratio(),
            0.0);  // no pair across classes
  const ClassSeparation q = Separation({"a", "a", "b"}, LeaveOneOutQueries(d));
  EXPECT_DOUBLE_EQ(q.within, s.within);
  EXPECT_DOUBLE_EQ(q.between, s.between);
  const DistanceMatrix r = Restrict(d, {2, 0});
  ASSERT_EQ(r.size(), 2u);
  EXPECT_EQ(r(0, 1), 4.0);
  EXPECT_EQ(r(1, 0), 4.0);
  EXPECT_EQ(r(0, 0), 0.0);
}

}  // namespace
}  // namespace tpr::eval
