#include "broad_phase.h"

#include <algorithm>
#include <numeric>
#include <stdexcept>
#include <string>

namespace collres {

Aabb world_box(const Mat3& rotation, const Vec3& position, const Vec3& local_lo,
               const Vec3& local_hi) {
  const Vec3 centre = rotation * (0.5 * (local_lo + local_hi)) + position;
  const Vec3 half = rotation.cwiseAbs() * (0.5 * (local_hi - local_lo));
  return {centre - half, centre + half};
}

BoxTree::BoxTree(std::vector<Aabb> boxes) : boxes_(std::move(boxes)) {
  order_.resize(boxes_.size());
  for (std::size_t k = 0; k < order_.size(); ++k) order_[k] = static_cast<int>(k);
  if (!boxes_.empty()) {
    nodes_.reserve(2 * boxes_.size());
    nodes_.emplace_back();
    build(0, 0, static_cast<int>(boxes_.size()));
  }
}

void BoxTree::build(int at, int first, int count) {
  Aabb bound = boxes_[order_[first]];
  for (int k = first + 1; k < first + count; ++k) {
    bound.lo = bound.lo.cwiseMin(boxes_[order_[k]].lo);
    bound.hi = bound.hi.cwiseMax(boxes_[order_[k]].hi);
  }
  nodes_[at].box = bound;
  if (count <= 4) {
    nodes_[at].first = first;
    nodes_[at].count = count;
    return;
  }
  int axis = 0;
  (bound.hi - bound.lo).maxCoeff(&axis);
  const int half = count / 2;   // the boxes of the smaller centres go left (ties by index)
  std::nth_element(order_.begin() + first, order_.begin() + first + half,
                   order_.begin() + first + count, [this, axis](int a, int b) {
                     const double ca = boxes_[a].lo[axis] + boxes_[a].hi[axis];
                     const double cb = boxes_[b].lo[axis] + boxes_[b].hi[axis];
                     return ca < cb || (ca == cb && a < b);
                   });
  const int children = static_cast<int>(nodes_.size());
  nodes_.emplace_back();
  nodes_.emplace_back();
  nodes_[at].first = children;
  nodes_[at].count = 0;
  build(children, first, half);
  build(children + 1, first + half, count - half);
}

void overlapping_pairs(const std::vector<Aabb>& boxes,
                       std::vector<std::pair<int, int>>& pairs) {
  const int count = static_cast<int>(boxes.size());
  if (count < 2) return;
  // sweep along the axis where the box centres spread most
  Vec3 mean = Vec3::Zero(), square = Vec3::Zero();
  for (const Aabb& box : boxes) {
    const Vec3 centre = box.lo + box.hi;
    mean += centre;
    square += centre.cwiseProduct(centre);
  }
  mean /= count;
  int axis = 0;
  (square / count - mean.cwiseProduct(mean)).maxCoeff(&axis);
  const int u = (axis + 1) % 3, v = (axis + 2) % 3;
  std::vector<int> order(count);
  std::iota(order.begin(), order.end(), 0);
  std::sort(order.begin(), order.end(), [&boxes, axis](int i, int j) {
    return boxes[i].lo[axis] < boxes[j].lo[axis] ||
           (boxes[i].lo[axis] == boxes[j].lo[axis] && i < j);
  });
  // the boxes in sweep order, contiguous: the inner loop reads memory in sequence
  struct Swept {
    double lo, hi, lo_u, hi_u, lo_v, hi_v;
  };
  std::vector<Swept> sorted(count);
  for (int k = 0; k < count; ++k) {
    const Aabb& box = boxes[order[k]];
    sorted[k] = {box.lo[axis], box.hi[axis], box.lo[u], box.hi[u], box.lo[v], box.hi[v]};
  }
  for (int k = 0; k < count; ++k) {
    const Swept first = sorted[k];
    for (int m = k + 1; m < count && sorted[m].lo <= first.hi; ++m) {
      const Swept& second = sorted[m];
      if (first.lo_u <= second.hi_u && second.lo_u <= first.hi_u && first.lo_v <= second.hi_v &&
          second.lo_v <= first.hi_v) {
        pairs.emplace_back(std::min(order[k], order[m]), std::max(order[k], order[m]));
      }
    }
  }
}

void CoherentPairs::pairs(const std::vector<Aabb>& boxes,
                          std::vector<std::pair<int, int>>& pairs) {
  const std::size_t fat = refit(boxes, inside(boxes, 0, boxes.size()));
  const std::size_t kept = pairs.size();
  // into room for every fat pair, cut to those kept
  pairs.resize(kept + fat);
  pairs.resize(kept + test(0, fat, pairs.data() + kept));
}

bool CoherentPairs::inside(const std::vector<Aabb>& boxes, std::size_t lo,
                           std::size_t hi) const {
  if (fat_.size() != boxes.size()) return false;
  for (std::size_t k = lo; k < hi; ++k) {
    if (!((boxes[k].lo.array() >= fat_[k].lo.array()).all() &&
          (boxes[k].hi.array() <= fat_[k].hi.array()).all())) {
      return false;
    }
  }
  return true;
}

std::size_t CoherentPairs::refit(const std::vector<Aabb>& boxes, bool inside) {
  if (!inside) {
    fat_.resize(boxes.size());
    const Vec3 skin = Vec3::Constant(skin_);
    for (std::size_t k = 0; k < boxes.size(); ++k) {
      fat_[k] = {boxes[k].lo - skin, boxes[k].hi + skin};
    }
    fat_pairs_.clear();
    overlapping_pairs(fat_, fat_pairs_);
    sort_fat_pairs(static_cast<int>(boxes.size()));
  }
  keys_.resize(boxes.size());
  for (std::size_t k = 0; k < boxes.size(); ++k) {
    const Vec3& lo = boxes[k].lo;
    const Vec3& hi = boxes[k].hi;
    Key& key = keys_[k];
    key.low[0] = Two{lo.x(), lo.y()};
    key.low[1] = Two{lo.z(), -hi.x()};
    key.low[2] = Two{-hi.y(), -hi.z()};
    key.high[0] = Two{hi.x(), hi.y()};
    key.high[1] = Two{hi.z(), -lo.x()};
    key.high[2] = Two{-lo.y(), -lo.z()};
  }
  return fat_pairs_.size();
}

std::size_t CoherentPairs::test(std::size_t from, std::size_t to,
                                std::pair<int, int>* out) const {
  // the exact test without branches (whether a fat pair overlaps is a coin toss to the
  // branch predictor): each fat pair is written to the next place, which only a kept one
  // keeps
  std::size_t kept = 0;
  for (std::size_t k = from; k < to; ++k) {
    const auto [i, j] = fat_pairs_[k];
    const Key& p = keys_[i];
    const Key& q = keys_[j];
    // each entry -1 (all bits) where its comparison holds, else 0: both -1, one more kept
    const auto holds = (p.low[0] <= q.high[0]) & (p.low[1] <= q.high[1]) &
                       (p.low[2] <= q.high[2]);
    out[kept] = {i, j};
    kept += static_cast<std::size_t>(-(holds[0] & holds[1]));
  }
  return kept;
}

void CoherentPairs::sort_fat_pairs(int count) {
  // `from` into `to` by key(pair) in [0, count), pairs of one key in their order
  auto by = [this, count](auto key, const std::vector<std::pair<int, int>>& from,
                          std::vector<std::pair<int, int>>& to) {
    start_.assign(count + 1, 0);
    for (const auto& pair : from) ++start_[key(pair) + 1];
    for (int k = 0; k < count; ++k) start_[k + 1] += start_[k];
    for (const auto& pair : from) to[start_[key(pair)]++] = pair;
  };
  sorted_.resize(fat_pairs_.size());
  by([](const std::pair<int, int>& pair) { return pair.second; }, fat_pairs_, sorted_);
  by([](const std::pair<int, int>& pair) { return pair.first; }, sorted_, fat_pairs_);
}

PairFilter::PairFilter(int count, std::vector<std::uint64_t> group,
                       std::vector<std::uint64_t> mask,
                       const std::vector<std::pair<int, int>>& ignored)
    : group_(std::move(group)), mask_(std::move(mask)) {
  if (count < 0 || group_.size() != static_cast<std::size_t>(count) ||
      mask_.size() != group_.size()) {
    throw std::invalid_argument("collision filter: one group and one mask per body (" +
                                std::to_string(count) + ")");
  }
  for (const auto& [a, b] : ignored) {
    if (a < 0 || b < 0 || a >= count || b >= count || a == b) {
      throw std::invalid_argument("collision filter: ignored pair (" + std::to_string(a) +
                                  ", " + std::to_string(b) + ") is not two distinct bodies of " +
                                  std::to_string(count));
    }
    ignored_.push_back(key(a, b));
  }
  std::sort(ignored_.begin(), ignored_.end());
  ignored_.erase(std::unique(ignored_.begin(), ignored_.end()), ignored_.end());
}

}  // namespace collres
