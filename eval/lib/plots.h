// Pictures of an evaluation as standalone SVG files a person opens in any
// browser: precision-recall curves (paper Figs. 10, 12) and the mean
// class-similarity matrix (Fig. 11).
//
//   std::string svg = PrecisionRecallSvg({{"TPR", tpr.overall.pr},
//                                         {"D2", d2.overall.pr}});
//   WriteFile("pr.svg", svg);
#ifndef TPR_EVAL_LIB_PLOTS_H_
#define TPR_EVAL_LIB_PLOTS_H_

#include <array>
#include <string>
#include <vector>

#include "eval/lib/metrics.h"

namespace tpr::eval {

// Curve is one named precision-recall series.
struct Curve {
  std::string name;
  std::array<double, kRecallLevels> precision{};
};

// PrecisionRecallSvg draws the curves over recall 0..1 (x) and precision
// 0..1 (y) with a legend. Thread-safe.
std::string PrecisionRecallSvg(const std::vector<Curve>& curves,
                               const std::string& title);

// SimilaritySvg draws the matrix as a grey-level grid, darker = more
// similar, as the paper's Fig. 11, with class names and values.
std::string SimilaritySvg(const SimilarityMatrix& matrix,
                          const std::string& title);

}  // namespace tpr::eval

#endif  // TPR_EVAL_LIB_PLOTS_H_
