#include "contact_cache.h"

#include <algorithm>
#include <cmath>
#include <numeric>
#include <tuple>

namespace collres {
namespace {

// A stored pair's run longer than this is sorted by key (hand-made sets): a run is scanned
// point by point, which a pile's few points a pair keep cheap
constexpr int64_t kLongestRun = 32;

// Whether the m contacts' pairs (a, b) never decrease (detection lists its pairs in order).
bool pairs_in_order(int64_t m, const int64_t* a, const int64_t* b) {
  for (int64_t k = 1; k < m; ++k)
    if (std::tie(a[k], b[k]) < std::tie(a[k - 1], b[k - 1])) return false;
  return true;
}

}  // namespace

void ContactCache::store(int64_t m, const int64_t* a, const int64_t* b, const int64_t* feature,
                         const double* normal, const double* friction, const double* point) {
  entries_.resize(static_cast<size_t>(m));   // (kept from store to store: rewritten here)
  for (int64_t k = 0; k < m; ++k) {
    CachedImpulse& e = entries_[static_cast<size_t>(k)];
    e.a = a[k];
    e.b = b[k];
    e.feature = feature[k];
    e.normal = normal[k];
    for (int d = 0; d < 3; ++d) {
      e.friction[d] = friction[3 * k + d];
      e.point[d] = point[3 * k + d];
    }
    e.live = true;
  }
  live_count_ = m;
  sorted_.clear();
  // the pairs' runs: a contact is dead where a later one of its run has its feature
  by_key_ = false;
  for (int64_t lo = 0; lo < m && !by_key_;) {
    int64_t hi = lo + 1;
    while (hi < m && a[hi] == a[lo] && b[hi] == b[lo]) ++hi;
    by_key_ = hi - lo > kLongestRun ||
              (hi < m && std::tie(a[hi], b[hi]) < std::tie(a[lo], b[lo]));
    for (int64_t k = lo; k + 1 < hi; ++k)
      for (int64_t j = k + 1; j < hi; ++j)
        if (feature[j] == feature[k]) {
          entries_[k].live = false;
          --live_count_;
          break;
        }
    lo = hi;
  }
  if (!by_key_) return;
  // every contact in key order, equal keys in caller order: the last of each run lives
  for (CachedImpulse& e : entries_) e.live = true;
  live_count_ = m;
  sorted_.resize(m);
  std::iota(sorted_.begin(), sorted_.end(), 0);
  std::stable_sort(sorted_.begin(), sorted_.end(), [&](int64_t i, int64_t j) {
    return std::tie(a[i], b[i], feature[i]) < std::tie(a[j], b[j], feature[j]);
  });
  int64_t kept = 0;
  for (int64_t k = 0; k < m; ++k) {
    const int64_t i = sorted_[k];
    if (k + 1 < m) {
      const int64_t j = sorted_[k + 1];
      if (a[i] == a[j] && b[i] == b[j] && feature[i] == feature[j]) {
        entries_[i].live = false;
        --live_count_;
        continue;
      }
    }
    sorted_[kept++] = i;
  }
  sorted_.resize(kept);
}

int64_t ContactCache::pair_start(int64_t from, int64_t a, int64_t b) const {
  auto below = [&](int64_t p) {
    const CachedImpulse& e = entries_[at(p)];
    return std::tie(e.a, e.b) < std::tie(a, b);
  };
  // galloping from `from` (the pairs between, mostly matched by their hints, passed in
  // logarithmic time), then a binary search in the last stride
  const int64_t end = places();
  int64_t lo = from;
  for (int64_t step = 1; lo < end && below(lo); step *= 2) {
    const int64_t probe = std::min(lo + step, end);
    if (probe < end && below(probe)) {
      lo = probe + 1;
    } else {
      int64_t l = lo + 1, h = probe;
      while (l < h) {
        const int64_t mid = l + (h - l) / 2;
        if (below(mid)) l = mid + 1; else h = mid;
      }
      lo = l;
    }
  }
  return lo;
}

void ContactCache::lookup(int64_t m, const int64_t* a, const int64_t* b, const int64_t* feature,
                          const double* point, double match_radius, double* normal,
                          double* friction, uint8_t* found) {
  const int64_t count = static_cast<int64_t>(entries_.size()), end = places();
  taken_.assign(count, 0);
  // a query's impulse from stored contact c (-1: none)
  auto give = [&](int64_t i, int64_t c) {
    found[i] = c >= 0;
    normal[i] = c >= 0 ? entries_[c].normal : 0.0;
    for (int d = 0; d < 3; ++d) friction[3 * i + d] = c >= 0 ? entries_[c].friction[d] : 0.0;
    if (c >= 0) taken_[c] = 1;
  };
  // pairs in order (as detection lists them): a query's pair starts at or after the last
  // query's, so one pass over the stored pairs finds them all
  const bool in_order = pairs_in_order(m, a, b);
  int64_t start = 0;
  // a query's hint: the stored contact as far on in the last store's order as the last
  // match's (detection lists the same contacts in the same order each step, shifted by
  // those that came and went before them)
  int64_t shift = 0;
  for (int64_t i = 0; i < m; ++i) {      // exact matches first: the hint, else a search
    const int64_t hint = i + shift;
    if (hint >= 0 && hint < count) {
      const CachedImpulse& e = entries_[hint];
      if (e.live && e.a == a[i] && e.b == b[i] && e.feature == feature[i]) {
        give(i, hint);
        continue;
      }
    }
    int64_t chosen = -1;
    if (by_key_) {
      auto it = std::lower_bound(sorted_.begin(), sorted_.end(), 0, [&](int64_t c, int) {
        const CachedImpulse& e = entries_[c];
        return std::tie(e.a, e.b, e.feature) < std::tie(a[i], b[i], feature[i]);
      });
      if (it != sorted_.end() && entries_[*it].a == a[i] && entries_[*it].b == b[i] &&
          entries_[*it].feature == feature[i])
        chosen = *it;
    } else {
      start = pair_start(in_order ? start : 0, a[i], b[i]);
      for (int64_t c = start; c < end && entries_[c].a == a[i] && entries_[c].b == b[i]; ++c)
        if (entries_[c].live && entries_[c].feature == feature[i]) {
          chosen = c;
          break;
        }
    }
    if (chosen >= 0) shift = chosen - i;
    give(i, chosen);
  }
  if (point == nullptr) return;
  for (int64_t i = 0; i < m; ++i) {      // then the nearest free point of the same pair
    if (found[i]) continue;
    double best = match_radius;
    int64_t chosen = -1;
    for (int64_t p = pair_start(0, a[i], b[i]); p < end; ++p) {
      const int64_t c = at(p);
      const CachedImpulse& e = entries_[c];
      if (e.a != a[i] || e.b != b[i]) break;
      if (!e.live || taken_[c]) continue;
      double dx = e.point[0] - point[3 * i], dy = e.point[1] - point[3 * i + 1];
      double dz = e.point[2] - point[3 * i + 2];
      double dist = std::sqrt(dx * dx + dy * dy + dz * dz);
      if (dist < best || (dist == best && chosen >= 0 && e.feature < entries_[chosen].feature)) {
        best = dist;
        chosen = c;
      }
    }
    if (chosen >= 0) give(i, chosen);
  }
}

void ContactCache::forget(int64_t k, const int64_t* bodies) {
  for (CachedImpulse& e : entries_) {
    if (!e.live) continue;
    for (int64_t j = 0; j < k; ++j)
      if (e.a == bodies[j] || e.b == bodies[j]) {
        e.live = false;
        --live_count_;
        break;
      }
  }
  if (by_key_)
    sorted_.erase(std::remove_if(sorted_.begin(), sorted_.end(),
                                 [&](int64_t c) { return !entries_[c].live; }),
                  sorted_.end());
}

}  // namespace collres
