// Test and benchmark helpers: realistic random TPR signatures for the
// indexer (Tam & Lau 2007, section 5), clustered like classes of models.
//
//   SignatureGenerator gen(SignatureGeneratorOptions{/*seed=*/7});
//   Signature s = gen.Next();                  // a member of a random class
//   PreparedSignature p = *Prepare(s, GroundDistanceOptions{});
//
// The values mimic what the extractor produces: weights like effective
// areas (Eq. 6; a few large, many small, summing to 1), G'_norm in [0, 1]
// (Eq. 5), and smooth band profiles (5.3) for K (area-weighted Gaussian
// curvature x total area, mostly positive, larger near tips), A (band area
// fractions summing to 1) and H (thickness / sqrt(area), order 0.1). A class
// is a prototype signature; its members jitter every value, and may drop a
// small feature or split one in two, as poses and meshing of one model do.
// Header-only; deterministic for a given seed on one standard library.
#ifndef TPR_TESTS_INDEXER_SIGNATURE_TESTING_H_
#define TPR_TESTS_INDEXER_SIGNATURE_TESTING_H_

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <random>
#include <utility>
#include <vector>

#include "indexer/lib/signature.h"

namespace tpr::index::testing {

// SignatureGeneratorOptions: shape of the generated data.
struct SignatureGeneratorOptions {
  // Seed of every random choice. Default 1.
  uint64_t seed = 1;
  // Features per prototype; members may differ by feature_change. Default
  // 30 (the paper's average, 7.3).
  int features = 30;
  // Band count of K, A, H (Fig. 8). Default 20.
  int bands = 20;
  // Number of classes (prototypes). Default 20.
  int classes = 20;
  // Relative jitter of a member's values around its prototype. Default 0.05.
  double jitter = 0.05;
  // Probability that a member drops a small feature, and (independently)
  // that it splits one feature in two; 0 keeps the count exact. Default 0.2.
  double feature_change = 0.2;
  // Length of the Laplace-Beltrami spectrum (values lambda_i A / (4 pi),
  // which grow like i by Weyl's law); 0 leaves it empty. Drawn from a
  // separate random stream, so the features do not depend on it. Default 0.
  int spectrum = 0;
};

// SignatureGenerator draws prototypes once, then members on demand.
class SignatureGenerator {
 public:
  explicit SignatureGenerator(const SignatureGeneratorOptions& options)
      : options_(options),
        rng_(options.seed),
        spectrum_rng_(options.seed ^ 0x5eed5eedULL) {
    for (int c = 0; c < options_.classes; ++c) {
      prototypes_.push_back(Prototype(options_.features));
    }
  }

  // SignatureGenerator with given prototypes (e.g. signatures extracted
  // from generated shapes) instead of drawn ones; options.classes and
  // options.features are ignored.
  SignatureGenerator(const SignatureGeneratorOptions& options,
                     std::vector<Signature> prototypes)
      : options_(options),
        rng_(options.seed),
        spectrum_rng_(options.seed ^ 0x5eed5eedULL),
        prototypes_(std::move(prototypes)) {
    options_.classes = static_cast<int>(prototypes_.size());
  }

  // Next returns a member of a uniformly chosen class.
  Signature Next() {
    std::uniform_int_distribution<int> pick(0, options_.classes - 1);
    return Member(pick(rng_));
  }

  // Member returns a jittered copy of prototype `c`, 0 <= c < classes.
  Signature Member(int c) {
    Signature s = prototypes_[static_cast<size_t>(c)];
    std::normal_distribution<double> noise(0.0, options_.jitter);
    std::uniform_real_distribution<double> unit(0.0, 1.0);
    for (Feature& f : s.features) {
      f.weight *= std::exp(noise(rng_));
      f.integral_geodesic =
          std::clamp(f.integral_geodesic + noise(rng_) * 0.5, 0.0, 1.0);
      for (double& x : f.curvature) x *= 1.0 + noise(rng_);
      for (double& x : f.area) x *= std::exp(noise(rng_));
      for (double& x : f.distance) x *= std::exp(noise(rng_));
      Normalize(&f.area);
    }
    if (!s.spectrum.empty()) {
      // Eigenvalues move a little with pose and meshing; keep them sorted.
      std::normal_distribution<double> spectral_noise(0.0,
                                                      0.2 * options_.jitter);
      for (double& x : s.spectrum) x *= std::exp(spectral_noise(spectrum_rng_));
      std::sort(s.spectrum.begin(), s.spectrum.end());
    }
    if (s.features.size() > 1 && unit(rng_) < options_.feature_change) {
      // Drop the lightest feature: a small protrusion not detected.
      auto it = std::min_element(s.features.begin(), s.features.end(),
                                 [](const Feature& x, const Feature& y) {
                                   return x.weight < y.weight;
                                 });
      s.features.erase(it);
    }
    if (unit(rng_) < options_.feature_change) {
      // Split a feature: one ring found as two close ones.
      std::uniform_int_distribution<size_t> pick(0, s.features.size() - 1);
      Feature& f = s.features[pick(rng_)];
      f.weight *= 0.5;
      Feature twin = f;
      twin.integral_geodesic =
          std::clamp(twin.integral_geodesic + 0.02, 0.0, 1.0);
      s.features.push_back(twin);
    }
    NormalizeWeights(&s);
    return s;
  }

  // Random returns an unclustered signature of exactly `features` features.
  Signature Random(int features) {
    Signature s = Prototype(features);
    return s;
  }

  std::mt19937_64& rng() { return rng_; }

 private:
  static void Normalize(std::vector<double>* v) {
    double sum = 0.0;
    for (double x : *v) sum += x;
    if (sum > 0.0) {
      for (double& x : *v) x /= sum;
    }
  }

  static void NormalizeWeights(Signature* s) {
    double sum = 0.0;
    for (const Feature& f : s->features) sum += f.weight;
    for (Feature& f : s->features) f.weight /= sum;
  }

  // A smooth positive profile over the bands: a sum of 1 to 3 bumps.
  std::vector<double> Profile(double base, double amplitude) {
    std::uniform_real_distribution<double> unit(0.0, 1.0);
    const int bands = options_.bands;
    std::vector<double> v(static_cast<size_t>(bands), base);
    const int bumps = 1 + static_cast<int>(unit(rng_) * 3.0);
    for (int k = 0; k < bumps; ++k) {
      const double center = unit(rng_) * bands;
      const double width = 1.0 + unit(rng_) * bands * 0.3;
      const double height = amplitude * (0.3 + unit(rng_));
      for (int b = 0; b < bands; ++b) {
        const double t = (b - center) / width;
        v[static_cast<size_t>(b)] += height * std::exp(-t * t);
      }
    }
    return v;
  }

  Signature Prototype(int features) {
    std::uniform_real_distribution<double> unit(0.0, 1.0);
    std::normal_distribution<double> normal(0.0, 1.0);
    constexpr double kFourPi = 12.566370614359172;
    Signature s;
    for (int i = 0; i < features; ++i) {
      Feature f;
      // Effective areas are heavy-tailed: a torso ring outweighs a finger
      // tip by two orders of magnitude.
      f.weight = std::exp(1.2 * normal(rng_));
      // Tips sit far from the surface centre, rings in between.
      const bool tip = unit(rng_) < 0.4;
      f.integral_geodesic = tip ? 0.6 + 0.4 * unit(rng_) : unit(rng_) * 0.8;
      f.curvature = Profile(0.2 * kFourPi, (tip ? 3.0 : 1.0) * kFourPi);
      // Some saddle bands: negative curvature.
      for (double& x : f.curvature) {
        if (unit(rng_) < 0.1) x = -0.5 * x;
      }
      f.area = Profile(0.05, 1.0);
      Normalize(&f.area);
      f.distance = Profile(0.03, 0.2);
      s.features.push_back(std::move(f));
    }
    NormalizeWeights(&s);
    // A class's spectrum: Weyl's s_i = i times a smooth class-specific
    // factor (clustered spectra of similar sizes, like real shapes).
    std::uniform_real_distribution<double> spectral_unit(0.0, 1.0);
    const double tilt = 0.6 + 0.8 * spectral_unit(spectrum_rng_);
    const double wave = 0.2 * spectral_unit(spectrum_rng_);
    const double phase = 6.0 * spectral_unit(spectrum_rng_);
    for (int i = 1; i <= options_.spectrum; ++i) {
      s.spectrum.push_back(i * tilt * (1.0 + wave * std::sin(0.3 * i + phase)));
    }
    std::sort(s.spectrum.begin(), s.spectrum.end());
    return s;
  }

  SignatureGeneratorOptions options_;
  std::mt19937_64 rng_;
  std::mt19937_64 spectrum_rng_;
  std::vector<Signature> prototypes_;
};

}  // namespace tpr::index::testing

#endif  // TPR_TESTS_INDEXER_SIGNATURE_TESTING_H_
