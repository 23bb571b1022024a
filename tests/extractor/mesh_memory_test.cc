// Peak heap use of mesh intake against the size of its input (a 60 MB OBJ
// declaring one 30M-vertex polygon peaked at 863 MB before it was refused).
// This binary replaces operator new/delete with a byte counter (live bytes via
// malloc_usable_size, and their peak), so it measures what intake itself
// allocates, beside the input it is handed.
#include <malloc.h>

#include <atomic>
#include <cstdint>
#include <cstdlib>
#include <new>
#include <string>

#include "absl/status/status.h"
#include "absl/strings/str_cat.h"
#include "extractor/lib/mesh_io.h"
#include "gmock/gmock.h"
#include "gtest/gtest.h"

namespace {
std::atomic<int64_t> g_live{0};
std::atomic<int64_t> g_peak{0};

void Count(void* p) {
  const int64_t live =
      g_live.fetch_add(static_cast<int64_t>(malloc_usable_size(p))) +
      static_cast<int64_t>(malloc_usable_size(p));
  int64_t peak = g_peak.load();
  while (live > peak && !g_peak.compare_exchange_weak(peak, live)) {
  }
}
}  // namespace

void* operator new(std::size_t size) {
  void* p = std::malloc(size == 0 ? 1 : size);
  if (p == nullptr) throw std::bad_alloc();
  Count(p);
  return p;
}
void operator delete(void* p) noexcept {
  if (p == nullptr) return;
  g_live.fetch_sub(static_cast<int64_t>(malloc_usable_size(p)));
  std::free(p);
}
void operator delete(void* p, std::size_t) noexcept { operator delete(p); }

namespace tpr::extract {
namespace {

using ::testing::HasSubstr;

// PeakDuring returns the most heap bytes `fn` held at once beyond what was
// live when it started.
template <typename Fn>
int64_t PeakDuring(Fn fn) {
  const int64_t base = g_live.load();
  g_peak.store(base);
  fn();
  return g_peak.load() - base;
}

// The stated bound, checked below: intake never holds more than this many
// times its input's bytes (plus 1 MiB for small fixed costs).
constexpr int64_t kMultiple = 12;
constexpr int64_t kSlack = 1 << 20;

TEST(MeshMemoryTest, HugeDeclaredPolygonIsRefusedBeforeAllocating) {
  // The report's input, scaled down: one OBJ face listing 6M corners
  // (12 MB), above the 4M-triangle default limit.
  std::string obj = "v 0 0 0\nv 1 0 0\nv 0 1 0\nf";
  obj.reserve(obj.size() + 2 * 6'000'000 + 1);
  for (int i = 0; i < 6'000'000; ++i) obj += " 1";
  obj += "\n";
  absl::Status status;
  const int64_t peak = PeakDuring([&] {
    status = LoadMeshFromBuffer(obj, MeshFormat::kObj, "", {}).status();
  });
  EXPECT_EQ(status.code(), absl::StatusCode::kResourceExhausted) << status;
  EXPECT_THAT(status.message(), HasSubstr("max_faces"));
  // Refused while counting: almost nothing allocated.
  EXPECT_LT(peak, kSlack) << peak << " bytes for " << obj.size();

  // The same in OFF and ASCII PLY.
  std::string off = "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n6000000";
  for (int i = 0; i < 6'000'000; ++i) off += " 0";
  off += "\n";
  const int64_t off_peak = PeakDuring([&] {
    status = LoadMeshFromBuffer(off, MeshFormat::kOff, "", {}).status();
  });
  EXPECT_EQ(status.code(), absl::StatusCode::kResourceExhausted) << status;
  EXPECT_LT(off_peak, kSlack);
  std::string ply =
      "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\n"
      "property float y\nproperty float z\nelement face 1\n"
      "property list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n"
      "0 1 0\n6000000";
  for (int i = 0; i < 6'000'000; ++i) ply += " 0";
  ply += "\n";
  const int64_t ply_peak = PeakDuring([&] {
    status = LoadMeshFromBuffer(ply, MeshFormat::kPly, "", {}).status();
  });
  EXPECT_EQ(status.code(), absl::StatusCode::kResourceExhausted) << status;
  EXPECT_LT(ply_peak, kSlack);
}

// A valid mesh written as tersely as the format allows (a grid of
// triangles with one-digit-ish indices) is the worst case of memory per
// input byte; intake stays within kMultiple of it.
std::string TerseGridObj(int n) {
  std::string obj;
  for (int y = 0; y <= n; ++y) {
    for (int x = 0; x <= n; ++x) absl::StrAppend(&obj, "v ", x, " ", y, " 0\n");
  }
  for (int y = 0; y < n; ++y) {
    for (int x = 0; x < n; ++x) {
      const int a = 1 + y * (n + 1) + x, b = a + 1, c = a + n + 1, d = c + 1;
      absl::StrAppend(&obj, "f ", a, " ", b, " ", d, "\nf ", a, " ", d, " ", c,
                      "\n");
    }
  }
  return obj;
}

TEST(MeshMemoryTest, PeakStaysWithinAStatedMultipleOfTheInput) {
  for (int n : {100, 400}) {
    const std::string obj = TerseGridObj(n);
    int64_t faces = 0;
    const int64_t peak = PeakDuring([&] {
      absl::StatusOr<LoadedMesh> m =
          LoadMeshFromBuffer(obj, MeshFormat::kObj, "", {});
      ASSERT_TRUE(m.ok()) << m.status();
      faces = m->stats.faces;
    });
    EXPECT_EQ(faces, 2 * n * n);
    const int64_t bound = kMultiple * static_cast<int64_t>(obj.size()) + kSlack;
    EXPECT_LE(peak, bound) << "n=" << n << ": " << peak << " bytes for "
                           << obj.size() << " input bytes ("
                           << static_cast<double>(peak) / obj.size() << "x)";
    RecordProperty(absl::StrCat("peak_per_input_byte_n", n),
                   absl::StrCat(static_cast<double>(peak) / obj.size()));
  }
}

}  // namespace
}  // namespace tpr::extract
