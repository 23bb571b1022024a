#include "extractor/lib/vertex_links.h"

namespace tpr::extract {

VertexLinks VertexLinks::Build(const Mesh& mesh) {
  VertexLinks links;
  const int32_t n = static_cast<int32_t>(mesh.positions.size());
  // Link edges, grouped per vertex by a counting sort (triangle order kept).
  links.link_offsets_.assign(static_cast<size_t>(n) + 1, 0);
  for (const auto& t : mesh.triangles) {
    for (int32_t c : t) ++links.link_offsets_[c + 1];
  }
  for (int32_t v = 0; v < n; ++v)
    links.link_offsets_[v + 1] += links.link_offsets_[v];
  links.link_.resize(2 * links.link_offsets_[n]);
  {
    std::vector<int64_t> fill(links.link_offsets_.begin(),
                              links.link_offsets_.end() - 1);
    for (const auto& t : mesh.triangles) {
      for (int k = 0; k < 3; ++k) {
        const int64_t slot = fill[t[k]]++;
        links.link_[2 * slot] = t[(k + 1) % 3];
        links.link_[2 * slot + 1] = t[(k + 2) % 3];
      }
    }
  }

  // Fans: each link edge (a, b) of v says that around v, b follows a;
  // chaining them walks the fan. Fans are small (about 6), so the per-vertex
  // work is a quadratic scan over a few link edges. The sorted neighbours
  // are the fan's vertices (each once already) sorted in place by an
  // insertion sort, plus v itself where a degenerate triangle (v, v, b)
  // puts it in its own link: no second pass over the link edges, no
  // deduplication (a sort of each link, about 12 entries with repeats, cost
  // as much as the rest of MeshGraph::Build together).
  const size_t reserve = links.link_.size() / 2 + 16;
  links.fan_offsets_.assign(static_cast<size_t>(n) + 1, 0);
  links.fan_.reserve(reserve);
  links.nbr_offsets_.assign(static_cast<size_t>(n) + 1, 0);
  links.nbr_.reserve(reserve);
  std::vector<char> used;
  std::vector<int32_t>& fan = links.fan_;
  std::vector<int32_t>& nbr = links.nbr_;
  for (int32_t v = 0; v < n; ++v) {
    const int32_t* pairs = links.link_begin(v);
    const int64_t count = links.link_offsets_[v + 1] - links.link_offsets_[v];
    auto from = [pairs](int64_t i) { return pairs[2 * i]; };
    auto to = [pairs](int64_t i) { return pairs[2 * i + 1]; };
    used.assign(count, 0);
    const size_t out_begin = fan.size();
    bool in_own_link = false;
    auto emit = [&](int32_t u) {
      if (u == v) {
        in_own_link = true;
        return;
      }
      for (size_t i = out_begin; i < fan.size(); ++i) {
        if (fan[i] == u) return;
      }
      fan.push_back(u);
    };
    int64_t remaining = count;
    while (remaining > 0) {
      // Start at a link edge whose `from` is no unused edge's `to` (a
      // boundary edge), else at the first unused one.
      int64_t start = -1;
      for (int64_t i = 0; i < count && start < 0; ++i) {
        if (used[i]) continue;
        bool is_target = false;
        for (int64_t j = 0; j < count; ++j) {
          if (!used[j] && to(j) == from(i)) {
            is_target = true;
            break;
          }
        }
        if (!is_target) start = i;
      }
      if (start < 0) {
        for (int64_t i = 0; i < count; ++i) {
          if (!used[i]) {
            start = i;
            break;
          }
        }
      }
      int64_t cur = start;
      emit(from(cur));
      while (cur >= 0) {
        used[cur] = 1;
        --remaining;
        const int32_t next = to(cur);
        emit(next);
        cur = -1;
        for (int64_t j = 0; j < count; ++j) {
          if (!used[j] && from(j) == next) {
            cur = j;
            break;
          }
        }
      }
    }
    links.fan_offsets_[v + 1] = static_cast<int64_t>(fan.size());

    const size_t nbr_begin = nbr.size();
    nbr.insert(nbr.end(), fan.begin() + out_begin, fan.end());
    if (in_own_link) nbr.push_back(v);
    for (size_t i = nbr_begin + 1; i < nbr.size(); ++i) {
      const int32_t value = nbr[i];
      size_t j = i;
      while (j > nbr_begin && value < nbr[j - 1]) {
        nbr[j] = nbr[j - 1];
        --j;
      }
      nbr[j] = value;
    }
    links.nbr_offsets_[v + 1] = static_cast<int64_t>(nbr.size());
  }
  return links;
}

}  // namespace tpr::extract
