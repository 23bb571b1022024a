#include "eval/lib/d2.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <random>

namespace tpr::eval {
namespace {

// Samples points uniformly by area: pick a triangle from the cumulative
// area table, then uniform barycentric coordinates (square-root trick).
class SurfaceSampler {
 public:
  explicit SurfaceSampler(const extract::Mesh& mesh) : mesh_(mesh) {
    cumulative_.reserve(mesh.triangles.size());
    double sum = 0.0;
    for (const auto& t : mesh.triangles) {
      const Eigen::Vector3d& a = mesh.positions[t[0]];
      sum += 0.5 *
             (mesh.positions[t[1]] - a).cross(mesh.positions[t[2]] - a).norm();
      cumulative_.push_back(sum);
    }
  }
  double area() const { return cumulative_.empty() ? 0 : cumulative_.back(); }

  Eigen::Vector3d Sample(std::mt19937_64& rng) const {
    std::uniform_real_distribution<double> u(0.0, 1.0);
    const double pick = u(rng) * area();
    const size_t f = std::min<size_t>(
        std::upper_bound(cumulative_.begin(), cumulative_.end(), pick) -
            cumulative_.begin(),
        cumulative_.size() - 1);
    const auto& t = mesh_.triangles[f];
    const double r1 = std::sqrt(u(rng)), r2 = u(rng);
    return (1 - r1) * mesh_.positions[t[0]] +
           r1 * (1 - r2) * mesh_.positions[t[1]] +
           r1 * r2 * mesh_.positions[t[2]];
  }

 private:
  const extract::Mesh& mesh_;
  std::vector<double> cumulative_;
};

}  // namespace

std::vector<double> D2Histogram(const extract::Mesh& mesh,
                                const D2Options& options) {
  SurfaceSampler sampler(mesh);
  if (!(sampler.area() > 0.0) || options.pairs <= 0 || options.bins <= 0) {
    return {};
  }
  std::mt19937_64 rng(options.seed);
  std::vector<float> distances(options.pairs);
  double sum = 0.0;
  for (float& d : distances) {
    d = static_cast<float>((sampler.Sample(rng) - sampler.Sample(rng)).norm());
    sum += d;
  }
  const double mean = sum / distances.size();
  std::vector<double> histogram(options.bins, 0.0);
  if (!(mean > 0.0)) {
    histogram[0] = 1.0;
    return histogram;
  }
  const double scale = options.bins / (options.range * mean);
  for (float d : distances) {
    const int bin = std::min(options.bins - 1, static_cast<int>(d * scale));
    histogram[bin] += 1.0;
  }
  for (double& h : histogram) h /= distances.size();
  return histogram;
}

double D2Distance(const std::vector<double>& a, const std::vector<double>& b) {
  double sum = 0.0;
  for (size_t i = 0; i < std::min(a.size(), b.size()); ++i) {
    sum += std::abs(a[i] - b[i]);
  }
  return sum;
}

}  // namespace tpr::eval
