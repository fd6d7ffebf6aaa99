// Broad phase: the pairs of bodies whose bounds, swept over the step, overlap.
//
// Bounds are world-frame axis-aligned boxes (m) that cover a body at its previous and its
// current pose and along the interpolated motion in between, padded by half the
// speculative margin, so two bodies closer than the margin always form a pair. Finite
// bodies go through a sort and sweep along the axis of largest spread; half-spaces have
// infinite bounds and are tested against every finite box directly (never sorted).
// A collision filter (PairFilter) then drops the pairs that may never collide.
#pragma once

#include <algorithm>
#include <cstdint>
#include <utility>
#include <vector>

#include "detection_types.h"

namespace collres {

struct Aabb {
  Vec3 lo, hi;  // m, world, min and max corners
};

// The world box of a body-frame box [local_lo, local_hi] under the pose (R, p).
Aabb world_box(const Mat3& rotation, const Vec3& position, const Vec3& local_lo,
               const Vec3& local_hi);

// Index pairs (i < j, into `boxes`) of boxes that overlap or touch, appended to `pairs`
// in no particular order. Sort and sweep: cost grows with the near pairs along one axis.
void overlapping_pairs(const std::vector<Aabb>& boxes,
                       std::vector<std::pair<int, int>>& pairs);

// Temporal coherence for `overlapping_pairs`: the pairs of boxes grown by a skin (m) are
// kept, sorted by (i, j), while every box stays inside its grown ("fat") box, and each step
// only filters them with the exact test; when a box leaves its fat box, all fat boxes are
// rebuilt, swept and their pairs sorted. The answer is always exactly the pairs of
// `overlapping_pairs` of the given boxes, appended to `pairs` in increasing (i, j) order.
class CoherentPairs {
 public:
  explicit CoherentPairs(double skin) : skin_(skin) {}
  void pairs(const std::vector<Aabb>& boxes, std::vector<std::pair<int, int>>& pairs);
  // `pairs` in steps, so that two threads may share them: `inside`, whether boxes [lo, hi)
  // are all inside their fat boxes (false when the boxes are not as many as the fat ones);
  // `refit` to `boxes`, rebuilt unless `inside` held for all of them, returns the number of
  // fat pairs; `test` writes the fat pairs [from, to) (of that number, in order) whose boxes
  // (refit's) overlap exactly to `out` on, in increasing (i, j) order, and returns how many.
  // Several `inside`s, or several `test`s of one refit, may run at once.
  bool inside(const std::vector<Aabb>& boxes, std::size_t lo, std::size_t hi) const;
  std::size_t refit(const std::vector<Aabb>& boxes, bool inside);
  std::size_t test(std::size_t from, std::size_t to, std::pair<int, int>* out) const;

 private:
  // A box as the two rows of the exact test: box p overlaps box q when each entry of p's
  // `low` is at most the same entry of q's `high`: p.lo <= q.hi, and -p.hi <= -q.lo for
  // q.lo <= p.hi (negation is exact: the same six comparisons, NaN failing them as before);
  // in rows of two entries, compared two at a time.
  typedef double Two __attribute__((vector_size(16)));
  struct Key {
    Two low[3], high[3];   // m: (lo.x, lo.y), (lo.z, -hi.x), (-hi.y, -hi.z); the same of
                           // (hi, -lo)
  };

  // fat_pairs_ sorted by (i, j) in linear time: a counting sort by j, then one by i that
  // keeps the order of equal i (`count` boxes)
  void sort_fat_pairs(int count);

  double skin_;
  std::vector<Aabb> fat_;
  std::vector<std::pair<int, int>> fat_pairs_;
  std::vector<Key> keys_;                         // refit's boxes, for `test`
  std::vector<int> start_;                       // sort_fat_pairs: bucket starts
  std::vector<std::pair<int, int>> sorted_;      // sort_fat_pairs: sorted by j
};

// A fixed set of boxes (a triangle mesh's triangles, in its body frame) in a tree of
// median splits along the longest axis (leaves of at most four boxes), built once: the
// boxes that overlap or touch a query box in O(log K + hits). A mesh's triangles stay out
// of the sort and sweep (a dense static set of K boxes, grown by its skin, overlaps itself
// O(K^2) times); each finite box asks the tree instead, as half-spaces are tested apart.
class BoxTree {
 public:
  explicit BoxTree(std::vector<Aabb> boxes);
  // Calls `visit(k)` for each box k (index into the constructor's boxes) overlapping `box`.
  template <class Visit>
  void query(const Aabb& box, Visit&& visit) const {
    if (nodes_.empty()) return;
    stack_.assign(1, 0);
    while (!stack_.empty()) {
      const Node& node = nodes_[stack_.back()];
      stack_.pop_back();
      if ((node.box.lo.array() > box.hi.array()).any() ||
          (node.box.hi.array() < box.lo.array()).any()) {
        continue;
      }
      if (node.count > 0) {
        for (int k = node.first; k < node.first + node.count; ++k) {
          const Aabb& leaf = boxes_[order_[k]];
          if ((leaf.lo.array() <= box.hi.array()).all() &&
              (leaf.hi.array() >= box.lo.array()).all()) {
            visit(order_[k]);
          }
        }
      } else {
        stack_.push_back(node.first);
        stack_.push_back(node.first + 1);
      }
    }
  }

 private:
  struct Node {
    Aabb box;
    int first = 0;   // leaf: first index into order_; inner: its first child (two in a row)
    int count = 0;   // leaf: its boxes; inner: 0
  };
  void build(int at, int first, int count);   // node `at` over order_[first, +count)

  std::vector<Aabb> boxes_;
  std::vector<int> order_;
  std::vector<Node> nodes_;
  mutable std::vector<int> stack_;
};

// True when the box reaches the half-space n.x <= offset grown by `pad` (m), n unit.
inline bool box_reaches_plane(const Aabb& box, const Vec3& normal, double offset, double pad) {
  const Vec3 centre = 0.5 * (box.lo + box.hi);
  const Vec3 half = 0.5 * (box.hi - box.lo);
  return centre.dot(normal) - half.dot(normal.cwiseAbs()) <= offset + pad;
}

// Which pairs of bodies may collide at all: category and mask bits as Box2D's filter and
// Gazebo's collide_bitmask, plus a list of ignored pairs as MoveIt's allowed collision
// matrix. Bodies a != b collide when
//   (group[a] & mask[b]) != 0 and (group[b] & mask[a]) != 0 and (a, b) is not ignored.
// The default filter (no bodies) lets every pair collide.
class PairFilter {
 public:
  PairFilter() = default;
  // One group and one mask per body (`count` of each) and ignored pairs of body indices in
  // either order; std::invalid_argument for a wrong length or an index outside [0, count).
  PairFilter(int count, std::vector<std::uint64_t> group, std::vector<std::uint64_t> mask,
             const std::vector<std::pair<int, int>>& ignored);

  bool collides(int a, int b) const {
    return (group(a) & mask(b)) != 0 && (group(b) & mask(a)) != 0 && !ignores(a, b);
  }
  // collides' parts: body a's group and mask bits (all of them in the default filter), and
  // whether the pair a != b is an ignored one
  std::uint64_t group(int a) const { return group_.empty() ? ~std::uint64_t{0} : group_[a]; }
  std::uint64_t mask(int a) const { return mask_.empty() ? ~std::uint64_t{0} : mask_[a]; }
  bool ignores(int a, int b) const {
    return !ignored_.empty() && std::binary_search(ignored_.begin(), ignored_.end(), key(a, b));
  }

 private:
  static std::uint64_t key(int a, int b) {
    const auto lo = static_cast<std::uint64_t>(std::min(a, b));
    const auto hi = static_cast<std::uint64_t>(std::max(a, b));
    return (lo << 32) | hi;
  }

  std::vector<std::uint64_t> group_, mask_;  // empty: every body in every group
  std::vector<std::uint64_t> ignored_;       // sorted keys of the ignored pairs
};

}  // namespace collres
