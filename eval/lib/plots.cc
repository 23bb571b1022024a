#include "eval/lib/plots.h"

#include <algorithm>
#include <cmath>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"

namespace tpr::eval {
namespace {

std::string Escape(const std::string& text) {
  std::string out;
  for (char c : text) {
    switch (c) {
      case '<':
        out += "&lt;";
        break;
      case '>':
        out += "&gt;";
        break;
      case '&':
        out += "&amp;";
        break;
      case '"':
        out += "&quot;";
        break;
      default:
        out += c;
    }
  }
  return out;
}

constexpr const char* kPalette[] = {"#1f77b4", "#d62728", "#2ca02c",
                                    "#ff7f0e", "#9467bd", "#8c564b"};

}  // namespace

std::string PrecisionRecallSvg(const std::vector<Curve>& curves,
                               const std::string& title) {
  const double left = 60, top = 40, width = 400, height = 300;
  std::string svg = absl::StrFormat(
      "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"%d\" height=\"%d\" "
      "font-family=\"sans-serif\" font-size=\"12\">\n"
      "<rect width=\"100%%\" height=\"100%%\" fill=\"white\"/>\n"
      "<text x=\"%g\" y=\"20\" font-size=\"14\">%s</text>\n",
      static_cast<int>(left + width + 160), static_cast<int>(top + height + 50),
      left, Escape(title));
  // Axes and grid at 0.1 steps.
  for (int i = 0; i <= 10; ++i) {
    const double x = left + width * i / 10.0, y = top + height * i / 10.0;
    absl::StrAppendFormat(
        &svg,
        "<line x1=\"%g\" y1=\"%g\" x2=\"%g\" y2=\"%g\" stroke=\"#ddd\"/>\n"
        "<line x1=\"%g\" y1=\"%g\" x2=\"%g\" y2=\"%g\" stroke=\"#ddd\"/>\n"
        "<text x=\"%g\" y=\"%g\" text-anchor=\"middle\">%.1f</text>\n"
        "<text x=\"%g\" y=\"%g\" text-anchor=\"end\">%.1f</text>\n",
        x, top, x, top + height, left, y, left + width, y, x, top + height + 16,
        i / 10.0, left - 6, y + 4, 1.0 - i / 10.0);
  }
  absl::StrAppendFormat(
      &svg,
      "<rect x=\"%g\" y=\"%g\" width=\"%g\" height=\"%g\" fill=\"none\" "
      "stroke=\"black\"/>\n"
      "<text x=\"%g\" y=\"%g\" text-anchor=\"middle\">recall</text>\n"
      "<text x=\"14\" y=\"%g\" transform=\"rotate(-90 14 %g)\" "
      "text-anchor=\"middle\">precision</text>\n",
      left, top, width, height, left + width / 2, top + height + 36,
      top + height / 2, top + height / 2);
  for (size_t c = 0; c < curves.size(); ++c) {
    const char* colour = kPalette[c % (sizeof(kPalette) / sizeof(*kPalette))];
    std::string points;
    for (int i = 0; i < kRecallLevels; ++i) {
      absl::StrAppendFormat(
          &points, "%.2f,%.2f ", left + width * i / (kRecallLevels - 1.0),
          top + height * (1.0 - std::clamp(curves[c].precision[i], 0.0, 1.0)));
    }
    absl::StrAppendFormat(
        &svg,
        "<polyline points=\"%s\" fill=\"none\" stroke=\"%s\" "
        "stroke-width=\"2\"/>\n"
        "<rect x=\"%g\" y=\"%g\" width=\"14\" height=\"4\" fill=\"%s\"/>\n"
        "<text x=\"%g\" y=\"%g\">%s</text>\n",
        points, colour, left + width + 16, top + 20.0 * c + 4, colour,
        left + width + 36, top + 20.0 * c + 10, Escape(curves[c].name));
  }
  svg += "</svg>\n";
  return svg;
}

std::string SimilaritySvg(const SimilarityMatrix& matrix,
                          const std::string& title) {
  const int n = static_cast<int>(matrix.classes.size());
  const double cell = 36, left = 100, top = 110;
  std::string svg = absl::StrFormat(
      "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"%d\" height=\"%d\" "
      "font-family=\"sans-serif\" font-size=\"11\">\n"
      "<rect width=\"100%%\" height=\"100%%\" fill=\"white\"/>\n"
      "<text x=\"10\" y=\"20\" font-size=\"14\">%s</text>\n",
      static_cast<int>(left + cell * n + 20),
      static_cast<int>(top + cell * n + 20), Escape(title));
  for (int i = 0; i < n; ++i) {
    absl::StrAppendFormat(
        &svg,
        "<text x=\"%g\" y=\"%g\" text-anchor=\"end\">%s</text>\n"
        "<text x=\"%g\" y=\"%g\" transform=\"rotate(-60 %g %g)\">%s</text>\n",
        left - 6, top + cell * i + cell / 2 + 4, Escape(matrix.classes[i]),
        left + cell * i + cell / 2, top - 6, left + cell * i + cell / 2,
        top - 6, Escape(matrix.classes[i]));
    for (int j = 0; j < n; ++j) {
      const double s = std::clamp(matrix.similarity[i][j], 0.0, 1.0);
      const int grey = static_cast<int>(std::lround(255 * (1.0 - s)));
      absl::StrAppendFormat(
          &svg,
          "<rect x=\"%g\" y=\"%g\" width=\"%g\" height=\"%g\" "
          "fill=\"rgb(%d,%d,%d)\" stroke=\"#888\"/>\n"
          "<text x=\"%g\" y=\"%g\" text-anchor=\"middle\" fill=\"%s\" "
          "font-size=\"9\">%.2f</text>\n",
          left + cell * j, top + cell * i, cell, cell, grey, grey, grey,
          left + cell * j + cell / 2, top + cell * i + cell / 2 + 3,
          s > 0.5 ? "white" : "black", s);
    }
  }
  svg += "</svg>\n";
  return svg;
}

}  // namespace tpr::eval
