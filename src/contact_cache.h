// Warm-start cache: last step's impulses keyed by (body_a, body_b, feature).
//
// Units: impulses in N s, points in m, world frame. The friction impulse is kept as a
// world vector (applied to B, opposite on A) so that it projects onto next step's
// tangents whatever they are. A contact whose feature id changed (e.g. a rolling
// sphere) falls back to the stored point of the same pair nearest to it within
// `match_radius`, each stored entry used at most once per lookup.
#pragma once

#include <cstdint>
#include <vector>

namespace collres {

struct CachedImpulse {
  int64_t a = 0, b = 0, feature = 0;    // pair (a < b by convention) and feature id
  double normal = 0.0;                   // N s, >= 0, along the normal, on B
  double friction[3] = {0, 0, 0};        // N s, world, on B
  double point[3] = {0, 0, 0};           // m, world, where it acted
};

class ContactCache {
 public:
  // Replace the content with these m contacts (later duplicates of a key win).
  void store(int64_t m, const int64_t* a, const int64_t* b, const int64_t* feature,
             const double* normal, const double* friction, const double* point);

  // For each of m contacts: normal (m,), friction (m, 3), found (m,) 0/1; zeros when absent.
  void lookup(int64_t m, const int64_t* a, const int64_t* b, const int64_t* feature,
              const double* point, double match_radius, double* normal, double* friction,
              uint8_t* found);

  // Drop every entry that involves one of these k body indices.
  void forget(int64_t k, const int64_t* bodies);
  void clear() {
    entries_.clear();
    stored_at_.clear();
    stored_by_.clear();
  }
  int64_t size() const { return static_cast<int64_t>(entries_.size()); }

 private:
  std::vector<CachedImpulse> entries_;   // sorted by (a, b, feature), keys unique
  std::vector<int64_t> stored_at_;       // entry of each contact of the last store, caller
                                         // order (-1: a duplicate): detection tends to list
                                         // the same contacts in the same order each step
  std::vector<int64_t> stored_by_;       // the contact of the last store each entry holds
                                         // (-1: unknown, after forget)
  std::vector<CachedImpulse> scratch_;
  std::vector<int64_t> order_;
  std::vector<uint8_t> taken_;
};

}  // namespace collres
