// D2 shape distribution (Osada, Funkhouser, Chazelle, Dobkin 2001), the
// rigid baseline the paper compares against (section 7.2): a histogram of
// Euclidean distances between random surface points.
//
//   D2Options options;                                  // 2^20 pairs, 64 bins
//   std::vector<double> h = D2Histogram(mesh, options);
//   double d = D2Distance(h, other);                    // L1
#ifndef TPR_EVAL_LIB_D2_H_
#define TPR_EVAL_LIB_D2_H_

#include <cstdint>
#include <vector>

#include "extractor/lib/mesh.h"

namespace tpr::eval {

// D2Options: the parameters of the reference D2 used in ../shared/data's
// README (2^20 pairs, 64 bins, L1).
struct D2Options {
  // Random point pairs, sampled uniformly by area. Default 2^20.
  int64_t pairs = int64_t{1} << 20;
  // Histogram bins. Default 64.
  int bins = 64;
  // Distances are divided by their mean (scale invariance) and binned over
  // [0, range). Values beyond go to the last bin. Default 4 (no pair on a
  // convex body exceeds about 3 mean distances).
  double range = 4.0;
  // Seed of the sampler; the same seed gives the same histogram.
  uint64_t seed = 1;
};

// D2Histogram returns `bins` frequencies summing to 1. Empty for a mesh of
// zero area. Cost O(pairs log F). Thread-safe.
std::vector<double> D2Histogram(const extract::Mesh& mesh,
                                const D2Options& options);

// D2Distance is the L1 distance of two histograms of equal length, in [0, 2].
double D2Distance(const std::vector<double>& a, const std::vector<double>& b);

}  // namespace tpr::eval

#endif  // TPR_EVAL_LIB_D2_H_
