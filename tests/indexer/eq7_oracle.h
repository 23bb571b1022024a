// Eq. 7 (Tam & Lau 2007) computed straight from raw features in double, as
// an oracle independent of PreparedSignature's float32 storage and SIMD
// kernels.
#ifndef TPR_TESTS_INDEXER_EQ7_ORACLE_H_
#define TPR_TESTS_INDEXER_EQ7_ORACLE_H_

#include <algorithm>
#include <cmath>
#include <vector>

#include "indexer/lib/ground_distance.h"
#include "indexer/lib/signature.h"

namespace tpr::index::testing {

// DirectEq7 returns Dist(x, y) of Eq. 7 with L2norm as documented in
// ground_distance.h: c_X ||X1 - X2||_2, the shorter vector padded with zeros.
inline double DirectEq7(const Feature& x, const Feature& y,
                        const GroundDistanceOptions& o) {
  auto l2 = [](const std::vector<double>& p, const std::vector<double>& q) {
    const size_t n = std::max(p.size(), q.size());
    double s = 0.0;
    for (size_t i = 0; i < n; ++i) {
      const double d =
          (i < p.size() ? p[i] : 0.0) - (i < q.size() ? q[i] : 0.0);
      s += d * d;
    }
    return std::sqrt(s);
  };
  return o.w1 * std::abs(x.integral_geodesic - y.integral_geodesic) +
         o.w2 * o.k_scale * l2(x.curvature, y.curvature) +
         o.w3 * o.a_scale * l2(x.area, y.area) +
         o.w4 * o.h_scale * l2(x.distance, y.distance);
}

// Float32Slack returns the documented bound (ground_distance.h) on how far
// a ground distance between x and y on PreparedSignature's float32
// coordinates may lie from DirectEq7(x, y): 2^-24 (N(phi(x)) + N(phi(y))),
// N(phi(x)) being the distance of x to the zero feature.
inline double Float32Slack(const Feature& x, const Feature& y,
                           const GroundDistanceOptions& o) {
  const Feature zero;
  return std::ldexp(DirectEq7(x, zero, o) + DirectEq7(y, zero, o), -24);
}

// Float32EmdSlack returns the bound on |EMD on float32 storage - EMD on
// double coordinates| of ground_distance.h: 2^-24 (max_i N(phi(a_i)) +
// max_j N(phi(b_j))).
inline double Float32EmdSlack(const Signature& a, const Signature& b,
                              const GroundDistanceOptions& o) {
  const Feature zero;
  double ma = 0.0;
  double mb = 0.0;
  for (const Feature& f : a.features) ma = std::max(ma, DirectEq7(f, zero, o));
  for (const Feature& f : b.features) mb = std::max(mb, DirectEq7(f, zero, o));
  return std::ldexp(ma + mb, -24);
}

}  // namespace tpr::index::testing

#endif  // TPR_TESTS_INDEXER_EQ7_ORACLE_H_
