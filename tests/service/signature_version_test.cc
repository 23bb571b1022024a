// Compatibility across signature versions: a data dir holding models of
// older signature versions (1: no spectrum; 2: a spectrum of 20) opens, loses
// nothing (every model is listed, counted and returned byte for byte),
// refuses searches with FAILED_PRECONDITION naming `tpr add --update`, and
// serves exact answers again once those models are re-extracted
// (overwritten), also after a restart. An old-version signature is never
// stored.
#include <gtest/gtest.h>

#include <algorithm>
#include <memory>
#include <string>
#include <vector>

#include "indexer/service/convert.h"
#include "indexer/service/indexer_core.h"
#include "indexer/service/storage.h"
#include "tests/service/extsvc_test_util.h"
#include "tests/service/indexer_testing.h"

namespace tpr::indexer::testing {
namespace {

using ::tpr::testing::TempDir;

// Models with spectra (the current version).
std::vector<TestModel> Models(int n) {
  tpr::index::testing::SignatureGeneratorOptions o;
  o.seed = 31;
  o.features = 10;
  o.bands = 6;
  o.classes = 4;
  o.spectrum = 50;
  tpr::index::testing::SignatureGenerator gen(o);
  std::vector<TestModel> out;
  for (int i = 0; i < n; ++i) {
    char id[16];
    std::snprintf(id, sizeof id, "m%03d", i);
    out.push_back({id, "class" + std::to_string(i % 4), gen.Member(i % 4)});
  }
  return out;
}

// What an older extractor wrote: version 1, no spectrum and no
// signature_version; version 2, a spectrum of 20.
tpr::v1::Model OldModel(const TestModel& m, int version) {
  tpr::v1::Model model;
  model.set_id(m.id);
  model.set_label(m.label);
  tpr::index::Signature old = m.signature;
  old.spectrum.resize(version == 1 ? 0 : 20);
  *model.mutable_signature() = ToWire(old);
  if (version == 1) {
    model.mutable_signature()->clear_signature_version();
    model.mutable_signature()->mutable_options()->clear_spectrum_eigenvalues();
  } else {
    model.mutable_signature()->set_signature_version(version);
    model.mutable_signature()->mutable_options()->set_spectrum_eigenvalues(20);
  }
  return model;
}

std::unique_ptr<IndexerCore> OpenCore(const std::string& dir) {
  CoreOptions options;
  options.data_dir = dir;
  options.persist_interval_ms = 0;
  absl::StatusOr<std::unique_ptr<IndexerCore>> core =
      IndexerCore::Open(options);
  EXPECT_TRUE(core.ok()) << core.status();
  return core.ok() ? std::move(*core) : nullptr;
}

absl::StatusOr<std::vector<std::string>> SearchIds(
    const IndexerCore& core, const tpr::v1::SearchRequest& request) {
  absl::StatusOr<std::unique_ptr<SearchSession>> s =
      core.StartSearch(request, nullptr);
  if (!s.ok()) return s.status();
  std::vector<std::string> ids;
  while (std::optional<tpr::v1::Neighbor> n = (*s)->Next())
    ids.push_back(n->id());
  return ids;
}

TEST(SignatureVersionTest, OldModelsAreKeptAndSearchSaysToUpdate) {
  TempDir dir;
  const std::vector<TestModel> models = Models(24);
  std::vector<tpr::v1::Model> old;
  {
    // A data dir written by the previous version: 16 current models, 8 old.
    absl::StatusOr<std::unique_ptr<Storage>> db = Storage::Open(dir.path());
    ASSERT_TRUE(db.ok()) << db.status();
    std::vector<tpr::v1::Model> stored;
    for (size_t i = 0; i < models.size(); ++i) {
      if (i % 3 == 2) {
        stored.push_back(OldModel(models[i], old.size() % 2 == 0 ? 1 : 2));
        old.push_back(stored.back());
      } else {
        tpr::v1::Model m;
        m.set_id(models[i].id);
        m.set_label(models[i].label);
        *m.mutable_signature() = ToWire(models[i].signature);
        stored.push_back(m);
      }
    }
    std::vector<ModelWrite> writes;
    for (const tpr::v1::Model& m : stored) writes.push_back({m.id(), &m});
    ASSERT_TRUE((*db)->Write(writes).ok());
  }

  std::unique_ptr<IndexerCore> core = OpenCore(dir.path());
  ASSERT_NE(core, nullptr);
  // Nothing lost: every model counted, listed and returned as stored.
  const tpr::v1::StatsResponse stats = core->Stats();
  EXPECT_EQ(stats.models(), 24);
  EXPECT_EQ(stats.indexed() + stats.buffered(), 16);
  absl::StatusOr<tpr::v1::ListResponse> list =
      core->List(tpr::v1::ListRequest());
  ASSERT_TRUE(list.ok());
  EXPECT_EQ(list->models_size(), 24);
  for (const tpr::v1::Model& m : old) {
    absl::StatusOr<tpr::v1::Model> got = core->Get(m.id());
    ASSERT_TRUE(got.ok()) << got.status();
    EXPECT_EQ(got->signature().SerializeAsString(),
              m.signature().SerializeAsString());
  }

  // Searches say what to do.
  tpr::v1::SearchRequest by_signature;
  *by_signature.mutable_signature() = ToWire(models[0].signature);
  by_signature.set_k(5);
  tpr::v1::SearchRequest by_v1_id;
  by_v1_id.set_id(old[0].id());
  by_v1_id.set_k(5);
  tpr::v1::SearchRequest by_v2_id = by_v1_id;
  by_v2_id.set_id(old[1].id());
  ASSERT_EQ(old[1].signature().signature_version(), 2);
  for (const tpr::v1::SearchRequest& r : {by_signature, by_v1_id, by_v2_id}) {
    absl::StatusOr<std::vector<std::string>> ids = SearchIds(*core, r);
    EXPECT_EQ(ids.status().code(), absl::StatusCode::kFailedPrecondition)
        << ids.status();
    EXPECT_NE(ids.status().message().find("tpr add --update"),
              std::string::npos)
        << ids.status();
  }
  // An old-version signature is never stored, nor searched with.
  for (const tpr::v1::Model& m : {old[0], old[1]}) {
    tpr::v1::UpsertRequest stale;
    *stale.mutable_model() = m;
    stale.set_overwrite(true);
    absl::StatusOr<bool> refused = core->Upsert(stale);
    EXPECT_EQ(refused.status().code(), absl::StatusCode::kFailedPrecondition);
    EXPECT_NE(refused.status().message().find("tpr add --update"),
              std::string::npos);
  }

  // Re-extracting (overwriting) the old ones makes searching work again;
  // Delete of an old one counts too.
  for (size_t i = 0; i < models.size(); ++i) {
    if (i % 3 != 2 || i == 23) continue;
    EXPECT_TRUE(SearchIds(*core, by_signature).status().code() ==
                absl::StatusCode::kFailedPrecondition);
    ASSERT_TRUE(core->Upsert(ToRequest(models[i], /*overwrite=*/true)).ok());
  }
  ASSERT_TRUE(core->Delete(models[23].id).ok());
  absl::StatusOr<std::vector<std::string>> ids = SearchIds(*core, by_signature);
  ASSERT_TRUE(ids.ok()) << ids.status();

  // The answer is exact against brute force over the 23 current models.
  std::vector<std::pair<std::string, tpr::v1::Signature>> live;
  for (size_t i = 0; i < 23; ++i)
    live.push_back({models[i].id, ToWire(models[i].signature)});
  absl::StatusOr<std::vector<tpr::testing::Ranked>> want =
      tpr::testing::BruteForceRanking(by_signature.signature(), live);
  ASSERT_TRUE(want.ok()) << want.status();
  ASSERT_EQ(ids->size(), 5u);
  for (size_t i = 0; i < 5; ++i) EXPECT_EQ((*ids)[i], (*want)[i].id) << i;

  // And after a restart.
  core->Close();
  core.reset();
  core = OpenCore(dir.path());
  ASSERT_NE(core, nullptr);
  EXPECT_EQ(core->Stats().models(), 23);
  absl::StatusOr<std::vector<std::string>> again =
      SearchIds(*core, by_signature);
  ASSERT_TRUE(again.ok()) << again.status();
  EXPECT_EQ(*again, *ids);
}

}  // namespace
}  // namespace tpr::indexer::testing
