#include "eval/lib/metrics.h"

#include <gtest/gtest.h>

namespace tpr::eval {
namespace {

// Five models: A A A B B. Query 0 (class A: C = 3, two relevant).
const std::vector<std::string> kLabels = {"A", "A", "A", "B", "B"};

TEST(MetricsTest, HandWorkedRankingWithoutTies) {
  // Ranking B, A, B, A: gains 0 1 0 1.
  Query q{0, {{3, 0.1}, {1, 0.2}, {4, 0.3}, {2, 0.4}}};
  const Scores s = Evaluate(kLabels, {q});
  const Metrics& m = s.overall;
  EXPECT_EQ(m.queries, 1);
  EXPECT_DOUBLE_EQ(m.nn, 0.0);
  EXPECT_DOUBLE_EQ(m.ft, 0.5);  // 1 relevant in the top 2
  EXPECT_DOUBLE_EQ(m.st, 1.0);  // 2 relevant in the top 4
  // E over the top 32: P = 2/32, R = 1.
  EXPECT_NEAR(m.e, 2.0 * (2.0 / 32) / (2.0 / 32 + 1.0), 1e-12);
  // DCG = 0 + 1/log2(2) + 0 + 1/log2(4) = 1.5; ideal = 1 + 1 = 2.
  EXPECT_NEAR(m.dcg, 0.75, 1e-12);
  // AP = (1/2 + 2/4) / 2.
  EXPECT_NEAR(m.map, 0.5, 1e-12);
  for (double p : m.pr) EXPECT_NEAR(p, 0.5, 1e-12);
}

TEST(MetricsTest, PerfectRankingScoresOne) {
  Query q{3, {{4, 0.0}, {0, 1.0}, {1, 2.0}, {2, 3.0}}};
  const Metrics m = Evaluate(kLabels, {q}).overall;
  EXPECT_DOUBLE_EQ(m.nn, 1.0);
  EXPECT_DOUBLE_EQ(m.ft, 1.0);
  EXPECT_DOUBLE_EQ(m.st, 1.0);
  EXPECT_DOUBLE_EQ(m.dcg, 1.0);
  EXPECT_DOUBLE_EQ(m.map, 1.0);
  // One relevant of C-1 = 1 in the top 32: P = 1/32, R = 1.
  EXPECT_NEAR(m.e, 2.0 * (1.0 / 32) / (1.0 / 32 + 1.0), 1e-12);
}

TEST(MetricsTest, TiesGiveTheExpectationOverOrders) {
  // Models 1 (A) and 3 (B) tie at rank 1: half the orders put A first.
  Query tied{0, {{1, 0.1}, {3, 0.1}, {2, 0.5}, {4, 0.6}}};
  Query a_first{0, {{1, 0.1}, {3, 0.2}, {2, 0.5}, {4, 0.6}}};
  Query b_first{0, {{3, 0.1}, {1, 0.2}, {2, 0.5}, {4, 0.6}}};
  const Metrics t = Evaluate(kLabels, {tied}).overall;
  const Metrics both = Evaluate(kLabels, {a_first, b_first}).overall;
  EXPECT_DOUBLE_EQ(t.nn, 0.5);
  EXPECT_NEAR(t.nn, both.nn, 1e-12);
  EXPECT_NEAR(t.ft, both.ft, 1e-12);
  EXPECT_NEAR(t.st, both.st, 1e-12);
  EXPECT_NEAR(t.e, both.e, 1e-12);
  EXPECT_NEAR(t.dcg, both.dcg, 1e-12);
}

TEST(MetricsTest, ClassOfOneIsExcluded) {
  const std::vector<std::string> labels = {"A", "A", "B"};
  Query lonely{2, {{0, 0.1}, {1, 0.2}}};
  Query normal{0, {{1, 0.1}, {2, 0.2}}};
  const Scores s = Evaluate(labels, {lonely, normal});
  EXPECT_EQ(s.excluded_singletons, 1);
  EXPECT_EQ(s.overall.queries, 1);
  EXPECT_EQ(s.per_class.count("B"), 0u);
  EXPECT_DOUBLE_EQ(s.per_class.at("A").nn, 1.0);
}

TEST(MetricsTest, MissingModelsRankLast) {
  // Only one model ranked: the others tie at the end.
  Query q{0, {{3, 0.1}}};
  const Metrics m = Evaluate(kLabels, {q}).overall;
  EXPECT_DOUBLE_EQ(m.nn, 0.0);
  // Positions 2..4 hold 2 relevant among 3 tied: top 2 has 2/3 expected.
  EXPECT_NEAR(m.ft, (2.0 / 3.0) / 2.0, 1e-12);
}

TEST(MetricsTest, PerClassAveragesItsQueries) {
  Query q0{0, {{1, 0.1}, {2, 0.2}, {3, 0.3}, {4, 0.4}}};  // perfect
  Query q3{3, {{0, 0.1}, {1, 0.2}, {2, 0.3}, {4, 0.4}}};  // worst for B
  const Scores s = Evaluate(kLabels, {q0, q3});
  EXPECT_DOUBLE_EQ(s.per_class.at("A").ft, 1.0);
  EXPECT_DOUBLE_EQ(s.per_class.at("B").ft, 0.0);
  EXPECT_DOUBLE_EQ(s.overall.ft, 0.5);
}

TEST(MetricsTest, SimilarityMatrixNormalizesPerRow) {
  Query q0{0, {{1, 1.0}, {2, 1.0}, {3, 5.0}, {4, 3.0}}};
  Query q3{3, {{0, 4.0}, {1, 4.0}, {2, 4.0}, {4, 2.0}}};
  const SimilarityMatrix sm = MeanSimilarity(kLabels, {q0, q3});
  ASSERT_EQ(sm.classes.size(), 2u);
  EXPECT_DOUBLE_EQ(sm.mean_distance[0][0], 1.0);
  EXPECT_DOUBLE_EQ(sm.mean_distance[0][1], 4.0);
  EXPECT_DOUBLE_EQ(sm.mean_distance[1][0], 4.0);
  EXPECT_DOUBLE_EQ(sm.mean_distance[1][1], 2.0);
  EXPECT_DOUBLE_EQ(sm.similarity[0][0], 1.0);
  EXPECT_DOUBLE_EQ(sm.similarity[0][1], 0.0);
  EXPECT_DOUBLE_EQ(sm.similarity[1][1], 1.0);
}

}  // namespace
}  // namespace tpr::eval
