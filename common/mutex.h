// Mutex, MutexLock, ReaderMutexLock: the lock the indexer service's own
// state uses (IndexerCore, its batch writer, model table and tree
// persister). In normal builds it IS absl::Mutex (a thin inline wrapper);
// in ThreadSanitizer builds (cmake -DTPR_SANITIZE=thread, which defines
// TPR_SYNC_STD) it is std::shared_mutex plus std::condition_variable_any.
//
//   tpr::common::Mutex mu_;
//   bool ready_ ABSL_GUARDED_BY(mu_) = false;
//   tpr::common::MutexLock lock(&mu_);
//   mu_.Await([this]() ABSL_EXCLUSIVE_LOCKS_REQUIRED(mu_) { return ready_; });
//
// Why: Debian's libabsl is not built with -fsanitize=thread, so absl::Mutex's
// Lock and Unlock (and the Condition::Eval calls bound inside the library)
// are invisible to TSan, which then reports every access the mutex guards.
// The standard library's locks are pthread calls that TSan intercepts. The
// wrapper keeps absl::Mutex's interface (the subset used here) and its
// semantics, so the code reads the same in both builds:
//   - Await(pred) blocks until pred() holds, re-evaluated whenever another
//     thread releases the lock (absl::Mutex evaluates waiters' conditions
//     on every release; the std form notifies a condition variable on every
//     exclusive release, including the release inside Await itself);
//   - reader locks are shared in both builds (std::shared_mutex), so a
//     "reader" that writes is still a race TSan can see.
// The std form is for checking only: it wakes every waiter on every release.
//
// Header-only, no gRPC: any library may include it.
#ifndef TPR_COMMON_MUTEX_H_
#define TPR_COMMON_MUTEX_H_

#include "absl/base/thread_annotations.h"
#include "absl/time/time.h"

#if defined(__SANITIZE_THREAD__) && !defined(TPR_SYNC_STD)
// A TSan build that did not come through TPR_SANITIZE=thread: never hand TSan
// an absl::Mutex it cannot see.
#define TPR_SYNC_STD 1
#endif

#if defined(TPR_SYNC_STD)
#include <algorithm>
#include <chrono>
#include <condition_variable>
#include <shared_mutex>
#else
#include "absl/synchronization/mutex.h"
#endif

namespace tpr::common {

// kStdSync is true when Mutex is built on the standard library (TSan builds).
#if defined(TPR_SYNC_STD)
inline constexpr bool kStdSync = true;
#else
inline constexpr bool kStdSync = false;
#endif

// Mutex: a reader-writer lock with conditional waits; see the file comment.
// Thread-safe. Not recursive. Cost: absl::Mutex's in normal builds.
class ABSL_LOCKABLE Mutex {
 public:
  Mutex() = default;
  Mutex(const Mutex&) = delete;
  Mutex& operator=(const Mutex&) = delete;

  // Lock blocks until this thread holds the lock exclusively.
  void Lock() ABSL_EXCLUSIVE_LOCK_FUNCTION() {
#if defined(TPR_SYNC_STD)
    mu_.lock();
#else
    mu_.Lock();
#endif
  }

  // Unlock releases an exclusive lock; waiters in Await re-check their
  // predicates.
  void Unlock() ABSL_UNLOCK_FUNCTION() {
#if defined(TPR_SYNC_STD)
    // Notified before the release: a waiter that returns from Await may
    // destroy this mutex, so nothing may touch it after the unlock.
    changed_.notify_all();
    mu_.unlock();
#else
    mu_.Unlock();
#endif
  }

  // ReaderLock blocks until this thread holds the lock shared (other
  // readers may hold it too, no writer does).
  void ReaderLock() ABSL_SHARED_LOCK_FUNCTION() {
#if defined(TPR_SYNC_STD)
    mu_.lock_shared();
#else
    mu_.ReaderLock();
#endif
  }

  // ReaderUnlock releases a shared lock.
  void ReaderUnlock() ABSL_UNLOCK_FUNCTION() {
#if defined(TPR_SYNC_STD)
    mu_.unlock_shared();
#else
    mu_.ReaderUnlock();
#endif
  }

  // Await blocks until pred() returns true. Precondition: this thread holds
  // the lock exclusively; it is released while waiting and held again when
  // Await returns. pred is called with the lock held (possibly on another
  // thread in normal builds, as absl::Mutex does), must not lock this mutex
  // and must be `bool operator()() const`.
  template <typename Pred>
  void Await(const Pred& pred) ABSL_EXCLUSIVE_LOCKS_REQUIRED(this) {
#if defined(TPR_SYNC_STD)
    if (pred()) return;
    // This thread may have changed what another waiter waits for; absl's
    // Await re-evaluates the others' conditions as it releases the lock.
    changed_.notify_all();
    changed_.wait(mu_, pred);
#else
    mu_.Await(absl::Condition(&pred));
#endif
  }

  // AwaitWithTimeout is Await, giving up after `timeout`. Returns pred()'s
  // value when it returns (true: the condition holds). Same preconditions.
  template <typename Pred>
  bool AwaitWithTimeout(const Pred& pred, absl::Duration timeout)
      ABSL_EXCLUSIVE_LOCKS_REQUIRED(this) {
#if defined(TPR_SYNC_STD)
    if (pred()) return true;
    changed_.notify_all();
    // A day stands for "no bound" (absl::InfiniteDuration) without
    // overflowing the clock's arithmetic.
    const absl::Duration bounded = std::min(timeout, absl::Hours(24));
    return changed_.wait_for(mu_, absl::ToChronoNanoseconds(bounded), pred);
#else
    return mu_.AwaitWithTimeout(absl::Condition(&pred), timeout);
#endif
  }

 private:
#if defined(TPR_SYNC_STD)
  std::shared_mutex mu_;
  std::condition_variable_any changed_;
#else
  absl::Mutex mu_;
#endif
};

// MutexLock holds `mu` exclusively for its scope (absl::MutexLock's form).
class ABSL_SCOPED_LOCKABLE MutexLock {
 public:
  explicit MutexLock(Mutex* mu) ABSL_EXCLUSIVE_LOCK_FUNCTION(mu) : mu_(mu) {
    mu_->Lock();
  }
  MutexLock(const MutexLock&) = delete;
  MutexLock& operator=(const MutexLock&) = delete;
  ~MutexLock() ABSL_UNLOCK_FUNCTION() { mu_->Unlock(); }

 private:
  Mutex* const mu_;
};

// ReaderMutexLock holds `mu` shared for its scope.
class ABSL_SCOPED_LOCKABLE ReaderMutexLock {
 public:
  explicit ReaderMutexLock(Mutex* mu) ABSL_SHARED_LOCK_FUNCTION(mu) : mu_(mu) {
    mu_->ReaderLock();
  }
  ReaderMutexLock(const ReaderMutexLock&) = delete;
  ReaderMutexLock& operator=(const ReaderMutexLock&) = delete;
  ~ReaderMutexLock() ABSL_UNLOCK_FUNCTION() { mu_->ReaderUnlock(); }

 private:
  Mutex* const mu_;
};

}  // namespace tpr::common

#endif  // TPR_COMMON_MUTEX_H_
