// tpr-web's small parts on their own: the gRPC code -> HTTP status table
// (google.api's mapping, written out here independently), JSON error bodies
// read back with protobuf's parser, and the recent-search window against
// a brute-force count and nearest-rank quantiles.
#include <gtest/gtest.h>

#include <algorithm>
#include <random>
#include <vector>

#include "tests/web/web_test_util.h"
#include "web/http_errors.h"
#include "web/recent_searches.h"

namespace tpr::web {
namespace {

TEST(HttpErrorsTest, EveryCodeHasItsHttpStatusAndName) {
  const std::vector<std::tuple<absl::StatusCode, int, const char*>> table = {
      {absl::StatusCode::kOk, 200, "OK"},
      {absl::StatusCode::kCancelled, 499, "CANCELLED"},
      {absl::StatusCode::kUnknown, 500, "UNKNOWN"},
      {absl::StatusCode::kInvalidArgument, 400, "INVALID_ARGUMENT"},
      {absl::StatusCode::kDeadlineExceeded, 504, "DEADLINE_EXCEEDED"},
      {absl::StatusCode::kNotFound, 404, "NOT_FOUND"},
      {absl::StatusCode::kAlreadyExists, 409, "ALREADY_EXISTS"},
      {absl::StatusCode::kPermissionDenied, 403, "PERMISSION_DENIED"},
      {absl::StatusCode::kResourceExhausted, 429, "RESOURCE_EXHAUSTED"},
      {absl::StatusCode::kFailedPrecondition, 400, "FAILED_PRECONDITION"},
      {absl::StatusCode::kAborted, 409, "ABORTED"},
      {absl::StatusCode::kOutOfRange, 400, "OUT_OF_RANGE"},
      {absl::StatusCode::kUnimplemented, 501, "UNIMPLEMENTED"},
      {absl::StatusCode::kInternal, 500, "INTERNAL"},
      {absl::StatusCode::kUnavailable, 503, "UNAVAILABLE"},
      {absl::StatusCode::kDataLoss, 500, "DATA_LOSS"},
      {absl::StatusCode::kUnauthenticated, 401, "UNAUTHENTICATED"},
  };
  for (const auto& [code, http, name] : table) {
    EXPECT_EQ(HttpStatusOf(code), http) << name;
    EXPECT_EQ(CodeName(code), name);
    // Abseil's own name for the code agrees.
    EXPECT_EQ(CodeName(code), absl::StatusCodeToString(code));
  }
  EXPECT_EQ(CodeName(static_cast<absl::StatusCode>(99)), "UNKNOWN");
  EXPECT_EQ(HttpStatusOf(static_cast<absl::StatusCode>(99)), 500);
}

TEST(HttpErrorsTest, ErrorJsonEscapesAndParsesBack) {
  const std::string message = "bad \"id\"\\ line\nnext\ttab \x01 caf\xC3\xA9";
  const std::string body = ErrorJson(absl::NotFoundError(message), "req-1");
  const google::protobuf::Struct parsed = testing::ParseJson(body);
  EXPECT_EQ(testing::Field(parsed, "code").string_value(), "NOT_FOUND");
  EXPECT_EQ(testing::Field(parsed, "message").string_value(), message);
  EXPECT_EQ(testing::Field(parsed, "requestId").string_value(), "req-1");
  EXPECT_EQ(
      testing::ParseJson(ErrorJson(absl::InternalError("x"), "")).fields_size(),
      2);
}

TEST(RecentSearchesTest, WindowAndQuantilesMatchBruteForce) {
  using Clock = RecentSearches::Clock;
  RecentSearches recent(60);
  const Clock::time_point t0 = Clock::now();
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> ms(0.1, 50);
  struct Entry {
    double at_s, total, indexer;
  };
  std::vector<Entry> all;
  for (int i = 0; i < 500; ++i) {
    const Entry e{i * 0.25, ms(rng), ms(rng)};  // 125 s of searches.
    all.push_back(e);
    recent.Add(t0 + std::chrono::duration_cast<Clock::duration>(
                        std::chrono::duration<double>(e.at_s)),
               e.total, e.indexer);
  }
  const double now_s = 130;
  const RecentSearches::Summary s =
      recent.Summarize(t0 + std::chrono::duration_cast<Clock::duration>(
                                std::chrono::duration<double>(now_s)));
  std::vector<float> total, indexer;
  for (const Entry& e : all) {
    if (e.at_s >= now_s - 60) {
      total.push_back(static_cast<float>(e.total));
      indexer.push_back(static_cast<float>(e.indexer));
    }
  }
  std::sort(total.begin(), total.end());
  std::sort(indexer.begin(), indexer.end());
  EXPECT_EQ(s.total, 500);
  ASSERT_EQ(s.in_window, static_cast<int64_t>(total.size()));
  EXPECT_DOUBLE_EQ(s.per_second, total.size() / 60.0);
  EXPECT_FLOAT_EQ(s.total_p50_ms, total[total.size() / 2]);
  EXPECT_FLOAT_EQ(s.total_p95_ms, total[total.size() * 95 / 100]);
  EXPECT_FLOAT_EQ(s.indexer_p50_ms, indexer[indexer.size() / 2]);
  // Nothing in the window: zeros.
  const RecentSearches::Summary empty =
      recent.Summarize(t0 + std::chrono::duration_cast<Clock::duration>(
                                std::chrono::duration<double>(1000.0)));
  EXPECT_EQ(empty.in_window, 0);
  EXPECT_EQ(empty.total_p50_ms, 0);
}

}  // namespace
}  // namespace tpr::web
