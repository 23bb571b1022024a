// tpr-synth: writes a labelled set of synthetic articulated shapes.
//
//   tpr-synth --out DIR [--classes N] [--poses N] [--vertices N] [--seed S]
//             [--format off|ply|ply-ascii] [--rigid] [--pose-amount A]
//
// Output: DIR/<class>/<class>_<pose>.<ext> and DIR/MANIFEST.txt with one line
// "<relative path> <class>" per mesh. The same flags give byte-identical
// files.
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>
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
  const std::vector<std::string> names = tpr::synth::ClassNames();
  app.add_option("--out", out_dir, "output directory (created)")->required();
  app.add_option("--classes", classes,
                 absl::StrCat("number of classes, the first N of ",
                              names.size()))
      ->check(CLI::Range(1, static_cast<int>(names.size())));
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
  CLI11_PARSE(app, argc, argv);

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

  namespace fs = std::filesystem;
  std::error_code ec;
  fs::create_directories(out_dir, ec);
  if (ec) {
    std::fprintf(stderr, "tpr-synth: cannot create %s: %s\n", out_dir.c_str(),
                 ec.message().c_str());
    return 1;
  }
  std::string manifest;
  const auto start = std::chrono::steady_clock::now();
  int64_t total = 0;
  for (int c = 0; c < classes; ++c) {
    const std::string& name = names[c];
    fs::create_directories(fs::path(out_dir) / name, ec);
    if (ec) {
      std::fprintf(stderr, "tpr-synth: cannot create %s/%s: %s\n",
                   out_dir.c_str(), name.c_str(), ec.message().c_str());
      return 1;
    }
    const auto class_start = std::chrono::steady_clock::now();
    int64_t class_vertices = 0;
    for (int p = 0; p < poses; ++p) {
      absl::StatusOr<tpr::extract::Mesh> mesh =
          tpr::synth::GenerateShape(name, p, options);
      if (!mesh.ok()) {
        std::fprintf(stderr, "tpr-synth: %s pose %d: %s\n", name.c_str(), p,
                     std::string(mesh.status().message()).c_str());
        return 1;
      }
      const std::string relative = absl::StrCat(name, "/", name, "_", p, ".", ext);
      absl::Status written = tpr::extract::WriteMeshToFile(
          *mesh, write, (fs::path(out_dir) / relative).string());
      if (!written.ok()) {
        std::fprintf(stderr, "tpr-synth: %s\n",
                     std::string(written.message()).c_str());
        return 1;
      }
      absl::StrAppend(&manifest, relative, " ", name, "\n");
      class_vertices += static_cast<int64_t>(mesh->positions.size());
      ++total;
    }
    const double seconds = std::chrono::duration<double>(
                               std::chrono::steady_clock::now() - class_start)
                               .count();
    std::printf("%-18s %d meshes, %.0f vertices on average, %.2f s\n",
                name.c_str(), poses,
                static_cast<double>(class_vertices) / poses, seconds);
  }
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
  std::printf("tpr-synth: %lld meshes in %.2f s (%.2f meshes/s) -> %s\n",
              static_cast<long long>(total), seconds,
              seconds > 0 ? total / seconds : 0.0, out_dir.c_str());
  return 0;
}
