#include "contact_cache.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>
#include <tuple>

namespace collres {
namespace {

bool key_less(const CachedImpulse& e, int64_t a, int64_t b, int64_t f) {
  return std::tie(e.a, e.b, e.feature) < std::tie(a, b, f);
}

// Whether the m contacts' pairs (a, b) never decrease (detection lists its pairs in order).
bool pairs_in_order(int64_t m, const int64_t* a, const int64_t* b) {
  for (int64_t k = 1; k < m; ++k)
    if (std::tie(a[k], b[k]) < std::tie(a[k - 1], b[k - 1])) return false;
  return true;
}

}  // namespace

void ContactCache::store(int64_t m, const int64_t* a, const int64_t* b, const int64_t* feature,
                         const double* normal, const double* friction, const double* point) {
  order_.resize(m);
  std::iota(order_.begin(), order_.end(), 0);
  // the contacts in key order, equal keys in caller order; detection lists its pairs in
  // order, so then only each pair's run is sorted by feature (a run holds at most a
  // pair's few points: insertion sort, stable), else every contact is
  if (pairs_in_order(m, a, b)) {
    for (int64_t k = 1; k < m; ++k) {
      const int64_t i = order_[k];
      int64_t j = k;
      for (; j > 0 && a[order_[j - 1]] == a[i] && b[order_[j - 1]] == b[i] &&
             feature[order_[j - 1]] > feature[i]; --j)
        order_[j] = order_[j - 1];
      order_[j] = i;
    }
  } else {
    std::stable_sort(order_.begin(), order_.end(), [&](int64_t i, int64_t j) {
      return std::tie(a[i], b[i], feature[i]) < std::tie(a[j], b[j], feature[j]);
    });
  }
  entries_.clear();
  stored_at_.assign(m, -1);
  stored_by_.clear();
  for (int64_t k = 0; k < m; ++k) {
    int64_t i = order_[k];
    if (k + 1 < m) {            // keep the last of each run of equal keys
      int64_t j = order_[k + 1];
      if (a[i] == a[j] && b[i] == b[j] && feature[i] == feature[j]) continue;
    }
    stored_at_[i] = static_cast<int64_t>(entries_.size());
    stored_by_.push_back(i);
    CachedImpulse e;
    e.a = a[i]; e.b = b[i]; e.feature = feature[i];
    e.normal = normal[i];
    for (int d = 0; d < 3; ++d) {
      e.friction[d] = friction[3 * i + d];
      e.point[d] = point[3 * i + d];
    }
    entries_.push_back(e);
  }
}

void ContactCache::lookup(int64_t m, const int64_t* a, const int64_t* b, const int64_t* feature,
                          const double* point, double match_radius, double* normal,
                          double* friction, uint8_t* found) {
  const int64_t n = size();
  taken_.assign(n, 0);
  order_.assign(m, -1);                  // matched entry per query
  auto begin = entries_.begin(), end = entries_.end();
  const int64_t hints = static_cast<int64_t>(stored_at_.size());
  // pairs in order (as detection lists them): the entries of a query's pair start at or
  // after the last query's, so one pass over the entries finds them all
  const bool in_order = pairs_in_order(m, a, b);
  auto pair_start = begin;
  auto pair_below = [&](const CachedImpulse& e, int64_t i) {
    return std::tie(e.a, e.b) < std::tie(a[i], b[i]);
  };
  // a query's hint: the stored contact as far on in the last store's order as the last
  // match's (detection lists the same contacts in the same order each step, shifted by
  // those that came and went before them)
  int64_t shift = 0;
  for (int64_t i = 0; i < m; ++i) {      // exact matches first: the hint, else a search
    const int64_t hint = i + shift;
    if (hint >= 0 && hint < hints && stored_at_[hint] >= 0) {
      const CachedImpulse& e = entries_[stored_at_[hint]];
      if (e.a == a[i] && e.b == b[i] && e.feature == feature[i]) {
        order_[i] = stored_at_[hint];
        taken_[order_[i]] = 1;
        continue;
      }
    }
    auto it = end;                       // the first entry not below the query's key
    if (in_order) {
      // the first entry of the query's pair: galloping on from the last search's (the
      // pairs between, mostly matched by their hints, passed in logarithmic time)
      for (std::ptrdiff_t step = 1; pair_start != end && pair_below(*pair_start, i); step *= 2) {
        const auto probe = end - pair_start > step ? pair_start + step : end;
        if (probe != end && pair_below(*probe, i)) {
          pair_start = probe + 1;
        } else {
          pair_start = std::partition_point(pair_start + 1, probe, [&](const CachedImpulse& e) {
            return pair_below(e, i);
          });
        }
      }
      for (it = pair_start; it != end && key_less(*it, a[i], b[i], feature[i]); ++it) {}
    } else {
      it = std::lower_bound(begin, end, 0, [&](const CachedImpulse& e, int) {
        return key_less(e, a[i], b[i], feature[i]);
      });
    }
    if (it != end && it->a == a[i] && it->b == b[i] && it->feature == feature[i]) {
      order_[i] = it - begin;
      taken_[order_[i]] = 1;
      shift = stored_by_[order_[i]] - i;
    }
  }
  if (point != nullptr) {                // then the nearest free point of the same pair
    for (int64_t i = 0; i < m; ++i) {
      if (order_[i] >= 0) continue;
      auto it = std::lower_bound(begin, end, 0, [&](const CachedImpulse& e, int) {
        return key_less(e, a[i], b[i], std::numeric_limits<int64_t>::min());
      });
      double best = match_radius;
      int64_t chosen = -1;
      for (; it != end && it->a == a[i] && it->b == b[i]; ++it) {
        int64_t k = it - begin;
        if (taken_[k]) continue;
        double dx = it->point[0] - point[3 * i], dy = it->point[1] - point[3 * i + 1];
        double dz = it->point[2] - point[3 * i + 2];
        double dist = std::sqrt(dx * dx + dy * dy + dz * dz);
        if (dist < best) {
          best = dist;
          chosen = k;
        }
      }
      if (chosen >= 0) {
        order_[i] = chosen;
        taken_[chosen] = 1;
      }
    }
  }
  for (int64_t i = 0; i < m; ++i) {
    const int64_t k = order_[i];
    found[i] = k >= 0;
    normal[i] = k >= 0 ? entries_[k].normal : 0.0;
    for (int d = 0; d < 3; ++d) friction[3 * i + d] = k >= 0 ? entries_[k].friction[d] : 0.0;
  }
}

void ContactCache::forget(int64_t k, const int64_t* bodies) {
  auto involved = [&](const CachedImpulse& e) {
    for (int64_t j = 0; j < k; ++j)
      if (e.a == bodies[j] || e.b == bodies[j]) return true;
    return false;
  };
  entries_.erase(std::remove_if(entries_.begin(), entries_.end(), involved), entries_.end());
  stored_at_.clear();
  stored_by_.assign(entries_.size(), -1);
}

}  // namespace collres
