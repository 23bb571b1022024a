// tpr::common::Mutex (common/mutex.h): absl::Mutex in normal builds,
// std::shared_mutex + std::condition_variable_any under ThreadSanitizer.
// The same tests run in both (this binary is labelled concurrency, so
// scripts/test --sanitize runs it under TSan too): mutual exclusion, Await
// woken by another thread's release, no lost wakeup when the releasing
// thread itself goes on to Await (absl re-evaluates waiters then; the std
// form must notify), AwaitWithTimeout's result, and shared reader locks.
// Every wait is bounded, so a lost wakeup fails a check instead of hanging.
#include "common/mutex.h"

#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <thread>
#include <vector>

#include "tests/sanitizers/sanitizer_build.h"

namespace tpr::common {
namespace {

using ::tpr::testing::kSanitizerSlowdown;
using ::tpr::testing::kThreadSanitizer;

// What a wait that must succeed may take at most (never reached when right).
absl::Duration Patience() { return absl::Seconds(20 * kSanitizerSlowdown); }

TEST(MutexTest, StandardLocksExactlyInThreadSanitizerBuilds) {
  EXPECT_EQ(kStdSync, kThreadSanitizer);
}

TEST(MutexTest, MutexLockExcludesOtherWriters) {
  Mutex mu;
  int64_t counter = 0;  // guarded by mu; a plain int, so a race would show
  std::vector<std::thread> threads;
  for (int t = 0; t < 4; ++t) {
    threads.emplace_back([&] {
      for (int i = 0; i < 20000; ++i) {
        MutexLock lock(&mu);
        ++counter;
      }
    });
  }
  for (std::thread& t : threads) t.join();
  MutexLock lock(&mu);
  EXPECT_EQ(counter, 4 * 20000);
}

TEST(MutexTest, AwaitReturnsOnceAnotherThreadMakesThePredicateTrue) {
  Mutex mu;
  int produced = 0;
  std::thread producer([&] {
    for (int i = 0; i < 100; ++i) {
      MutexLock lock(&mu);
      ++produced;
    }
  });
  {
    MutexLock lock(&mu);
    EXPECT_TRUE(
        mu.AwaitWithTimeout([&] { return produced == 100; }, Patience()));
    EXPECT_EQ(produced, 100);
  }
  producer.join();
  MutexLock lock(&mu);
  mu.Await([&] { return produced == 100; });  // already true: returns at once
}

// Two threads hand a turn back and forth: each, holding the lock, gives the
// turn to the other and Awaits its own. The only release the other waiter
// can be woken by is the one inside this thread's Await; without that
// wake-up every hand-over would last a whole wait timeout (the predicate is
// true by then), so the game is bounded in time: 500 rounds take
// milliseconds, the bound is seconds. (Checked: without the std form's
// notify in AwaitWithTimeout this fails after 20 s under TSan.)
TEST(MutexTest, AWaiterIsWokenByTheReleaseInsideAnotherThreadsAwait) {
  Mutex mu;
  int turn = 0;  // whose turn: 0 or 1
  int rounds = 0;
  bool gave_up = false;  // the time bound passed: both stop
  constexpr int kRounds = 500;
  const auto deadline = std::chrono::steady_clock::now() +
                        std::chrono::seconds(4 * kSanitizerSlowdown);
  auto player = [&](int me) {
    MutexLock lock(&mu);
    while (rounds < kRounds && !gave_up) {
      mu.AwaitWithTimeout(
          [&] { return turn == me || rounds >= kRounds || gave_up; },
          absl::Seconds(kSanitizerSlowdown));
      if (std::chrono::steady_clock::now() > deadline) gave_up = true;
      if (rounds >= kRounds || gave_up) return;
      if (turn != me) continue;
      ++rounds;
      turn = 1 - me;
    }
  };
  std::thread a(player, 0);
  std::thread b(player, 1);
  a.join();
  b.join();
  MutexLock lock(&mu);
  EXPECT_FALSE(gave_up) << "hand-overs waited out their timeouts (" << rounds
                        << " rounds in the time bound)";
  EXPECT_EQ(rounds, kRounds);
}

TEST(MutexTest, AwaitWithTimeoutReportsAPredicateThatStaysFalse) {
  Mutex mu;
  MutexLock lock(&mu);
  const auto start = std::chrono::steady_clock::now();
  EXPECT_FALSE(
      mu.AwaitWithTimeout([] { return false; }, absl::Milliseconds(30)));
  EXPECT_GE(std::chrono::steady_clock::now() - start,
            std::chrono::milliseconds(25));
  EXPECT_TRUE(mu.AwaitWithTimeout([] { return true; }, absl::ZeroDuration()));
}

// Readers share the lock: the first reader holds it until the second has
// taken it too (bounded), while a writer waits for both.
TEST(MutexTest, ReaderLocksAreSharedAndExcludeWriters) {
  Mutex mu;
  int value = 7;
  std::atomic<int> readers{0};
  std::atomic<bool> both{false};
  auto reader = [&] {
    ReaderMutexLock lock(&mu);
    EXPECT_EQ(value, 7);
    ++readers;
    const auto until = std::chrono::steady_clock::now() +
                       std::chrono::seconds(20 * kSanitizerSlowdown);
    while (readers.load() < 2 && std::chrono::steady_clock::now() < until)
      std::this_thread::yield();
    if (readers.load() == 2) both = true;
  };
  std::thread r1(reader);
  std::thread r2(reader);
  r1.join();
  r2.join();
  EXPECT_TRUE(both.load()) << "the second reader never got the lock";
  {
    MutexLock lock(&mu);
    value = 8;
  }
  ReaderMutexLock lock(&mu);
  EXPECT_EQ(value, 8);
}

}  // namespace
}  // namespace tpr::common
