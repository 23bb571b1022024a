// tpr-synth: writes a labelled set of synthetic articulated shapes.
//
//   tpr-synth --out DIR [--classes N] [--poses N] [--vertices N] [--seed S]
//             [--format off|ply|ply-ascii] [--rigid] [--pose-amount A]
//             [--jobs J] [--identity [--identity-surface S]]
//
// Output: DIR/<class>/<class>_<pose>.<ext> and DIR/MANIFEST.txt with one line
// "<relative path> <class>" per mesh. The same flags give byte-identical
// files. With --identity the classes are N bodies on the biped skeleton
// that differ in limb lengths and thickness (body_000, body_001, ...;
// synth.h, identity mode); --identity-surface skinned (default: one rest
// mesh per body, skinned to each pose) or repolygonized (each pose
// polygonized afresh, the older identity sets).
#include <atomic>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>
#include <thread>
#include <vector>

#include "CLI/CLI.hpp"
#include "absl/strings/str_cat.h"
#include "extractor/lib/mesh_writer.h"
#include "extractor/synth/synth.h"

int main(int argc, char** argv) {
  CLI::App app{"Generate labelled synthetic articulated shapes (tpr-synth)."};
  std::string out_dir;
  int classes = 8;
  int poses = 5;
  int vertices = 10000;
  uint64_t seed = 1;
  std::string format = "off";
  bool rigid = false;
  double pose_amount = 1.0;
  int jobs = 1;
  bool identity = false;
  std::string identity_surface = "skinned";
  std::vector<std::string> names = tpr::synth::ClassNames();
  app.add_option("--out", out_dir, "output directory (created)")->required();
  app.add_option(
         "--classes", classes,
         absl::StrCat("number of classes, the first N of ", names.size(),
                      "; with --identity the number of bodies (up to ",
                      tpr::synth::kMaxIdentityBodies, ")"))
      ->check(CLI::Range(1, tpr::synth::kMaxIdentityBodies));
  app.add_flag("--identity", identity,
               "bodies of one skeleton (biped) differing in limb lengths and "
               "thickness, class = body");
  app.add_option("--identity-surface", identity_surface,
                 "with --identity: skinned (one rest mesh per body, skinned to "
                 "each pose) or repolygonized (each pose polygonized afresh)")
      ->check(CLI::IsMember({"skinned", "repolygonized"}));
  app.add_option("--poses", poses, "poses per class")
      ->check(CLI::Range(1, 100000));
  app.add_option("--vertices", vertices, "target vertices per mesh")
      ->check(CLI::Range(200, 1000000));
  app.add_option("--seed", seed, "random seed");
  app.add_option("--format", format, "off, ply (binary) or ply-ascii")
      ->check(CLI::IsMember({"off", "ply", "ply-ascii"}));
  app.add_flag("--rigid", rigid,
               "random rotation, translation and scale in [1, 2] per mesh");
  app.add_option("--pose-amount", pose_amount,
                 "fraction of the joint limits poses use (0 = rest pose)")
      ->check(CLI::Range(0.0, 1.0));
  app.add_option("--jobs", jobs,
                 "meshes generated in parallel (output does not depend on it)")
      ->check(CLI::Range(1, 256));
  CLI11_PARSE(app, argc, argv);
  if (identity) {
    names.clear();
    for (int b = 0; b < classes; ++b)
      names.push_back(tpr::synth::IdentityBodyName(b));
  } else if (classes > static_cast<int>(names.size())) {
    return app.exit(CLI::ValidationError(
        "--classes",
        absl::StrCat(classes, " exceeds the ", names.size(),
                     " classes (use --identity for more bodies)")));
  }

  tpr::extract::MeshWriteOptions write;
  std::string ext = "off";
  if (format == "ply") {
    write.format = tpr::extract::MeshWriteFormat::kPlyBinary;
    ext = "ply";
  } else if (format == "ply-ascii") {
    write.format = tpr::extract::MeshWriteFormat::kPlyAscii;
    ext = "ply";
  }
  tpr::synth::ShapeOptions options;
  options.target_vertices = vertices;
  options.seed = seed;
  options.random_rigid = rigid;
  options.pose_amount = pose_amount;
  options.identity_surface = identity_surface == "repolygonized"
                                 ? tpr::synth::IdentitySurface::kRepolygonized
                                 : tpr::synth::IdentitySurface::kSkinned;

  namespace fs = std::filesystem;
  std::error_code ec;
  fs::create_directories(out_dir, ec);
  if (ec) {
    std::fprintf(stderr, "tpr-synth: cannot create %s: %s\n", out_dir.c_str(),
                 ec.message().c_str());
    return 1;
  }
  for (int c = 0; c < classes; ++c) {
    fs::create_directories(fs::path(out_dir) / names[c], ec);
    if (ec) {
      std::fprintf(stderr, "tpr-synth: cannot create %s/%s: %s\n",
                   out_dir.c_str(), names[c].c_str(), ec.message().c_str());
      return 1;
    }
  }
  // One task per (class, pose). Each mesh depends only on its own
  // arguments, so workers may take tasks in any order: the files (and the
  // manifest, written in task order) are the same for every --jobs.
  struct Task {
    int cls;
    int pose;
    std::string relative;
    std::string error;
    int64_t vertices = 0;
    double seconds = 0.0;
  };
  std::vector<Task> tasks;
  for (int c = 0; c < classes; ++c) {
    for (int p = 0; p < poses; ++p) {
      Task t;
      t.cls = c;
      t.pose = p;
      t.relative = absl::StrCat(names[c], "/", names[c], "_", p, ".", ext);
      tasks.push_back(t);
    }
  }
  std::atomic<size_t> next{0};
  std::atomic<bool> failed{false};
  auto worker = [&] {
    for (size_t i = next++; i < tasks.size() && !failed; i = next++) {
      Task& t = tasks[i];
      const auto t0 = std::chrono::steady_clock::now();
      absl::StatusOr<tpr::extract::Mesh> mesh =
          identity ? tpr::synth::GenerateIdentity(t.cls, t.pose, options)
                   : tpr::synth::GenerateShape(names[t.cls], t.pose, options);
      absl::Status status = mesh.status();
      if (status.ok()) {
        status = tpr::extract::WriteMeshToFile(
            *mesh, write, (fs::path(out_dir) / t.relative).string());
      }
      if (!status.ok()) {
        t.error = absl::StrCat(names[t.cls], " pose ", t.pose, ": ",
                               status.message());
        failed = true;
        return;
      }
      t.vertices = static_cast<int64_t>(mesh->positions.size());
      t.seconds =
          std::chrono::duration<double>(std::chrono::steady_clock::now() - t0)
              .count();
    }
  };
  const auto start = std::chrono::steady_clock::now();
  std::vector<std::thread> threads;
  for (int j = 1; j < jobs; ++j) threads.emplace_back(worker);
  worker();
  for (std::thread& t : threads) t.join();
  for (const Task& t : tasks) {
    if (!t.error.empty()) {
      std::fprintf(stderr, "tpr-synth: %s\n", t.error.c_str());
      return 1;
    }
  }
  std::string manifest;
  for (int c = 0; c < classes; ++c) {
    int64_t class_vertices = 0;
    double class_seconds = 0.0;
    for (const Task& t : tasks) {
      if (t.cls != c) continue;
      absl::StrAppend(&manifest, t.relative, " ", names[c], "\n");
      class_vertices += t.vertices;
      class_seconds += t.seconds;
    }
    std::printf("%-18s %d meshes, %.0f vertices on average, %.3f s per mesh\n",
                names[c].c_str(), poses,
                static_cast<double>(class_vertices) / poses,
                class_seconds / poses);
  }
  const int64_t total = static_cast<int64_t>(tasks.size());
  std::ofstream file(fs::path(out_dir) / "MANIFEST.txt",
                     std::ios::binary | std::ios::trunc);
  file << manifest;
  file.close();
  if (!file) {
    std::fprintf(stderr, "tpr-synth: cannot write %s/MANIFEST.txt\n",
                 out_dir.c_str());
    return 1;
  }
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start)
          .count();
  std::printf(
      "tpr-synth: %lld meshes in %.2f s (%.2f meshes/s, %d job%s) -> %s\n",
      static_cast<long long>(total), seconds,
      seconds > 0 ? total / seconds : 0.0, jobs, jobs == 1 ? "" : "s",
      out_dir.c_str());
  return 0;
}
