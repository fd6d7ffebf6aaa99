// Warm-start cache: last step's impulses keyed by (body_a, body_b, feature).
//
// Units: impulses in N s, points in m, world frame. The friction impulse is kept as a
// world vector (applied to B, opposite on A) so that it projects onto next step's
// tangents whatever they are. A contact whose feature id changed (e.g. a rolling
// sphere) falls back to the stored point of the same pair nearest to it within
// `match_radius` (ties: the smallest feature id), each stored entry used at most once per
// lookup.
#pragma once

#include <cstdint>
#include <vector>

namespace collres {

struct CachedImpulse {
  int64_t a = 0, b = 0, feature = 0;    // pair (a < b by convention) and feature id
  double normal = 0.0;                   // N s, >= 0, along the normal, on B
  double friction[3] = {0, 0, 0};        // N s, world, on B
  double point[3] = {0, 0, 0};           // m, world, where it acted
  bool live = true;                      // false: a later contact has its key, or forgotten
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
    store(0, nullptr, nullptr, nullptr, nullptr, nullptr, nullptr);
  }
  int64_t size() const { return live_count_; }

 private:
  // The stored contact at place p of the pair order (pairs (a, b) never decrease along it).
  int64_t at(int64_t p) const { return by_key_ ? sorted_[p] : p; }
  int64_t places() const {
    return static_cast<int64_t>(by_key_ ? sorted_.size() : entries_.size());
  }
  // The first place whose pair is not below (a, b), searched in [from, places()).
  int64_t pair_start(int64_t from, int64_t a, int64_t b) const;

  // the last store's contacts in its order, as given (detection lists its pairs in order
  // and the same contacts in the same order each step: a contact's entry is found at its
  // place in that order, shifted by those that came and went before it)
  std::vector<CachedImpulse> entries_;
  int64_t live_count_ = 0;
  // false: the stored pairs never decrease and none has more than a few contacts (a pair's
  // contacts one short run, its features in any order); true: else (hand-made sets), and
  // sorted_ lists the live contacts by key
  bool by_key_ = false;
  std::vector<int64_t> sorted_;
  std::vector<uint8_t> taken_;     // lookup: per stored contact
};

}  // namespace collres
