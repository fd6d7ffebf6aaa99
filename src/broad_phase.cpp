#include "broad_phase.h"

#include <algorithm>
#include <numeric>

namespace collres {

Aabb world_box(const Mat3& rotation, const Vec3& position, const Vec3& local_lo,
               const Vec3& local_hi) {
  const Vec3 centre = rotation * (0.5 * (local_lo + local_hi)) + position;
  const Vec3 half = rotation.cwiseAbs() * (0.5 * (local_hi - local_lo));
  return {centre - half, centre + half};
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
  for (int k = 0; k < count; ++k) {
    const Aabb& first = boxes[order[k]];
    for (int m = k + 1; m < count; ++m) {
      const Aabb& second = boxes[order[m]];
      if (second.lo[axis] > first.hi[axis]) break;
      if (first.lo[u] <= second.hi[u] && second.lo[u] <= first.hi[u] &&
          first.lo[v] <= second.hi[v] && second.lo[v] <= first.hi[v]) {
        pairs.emplace_back(std::min(order[k], order[m]), std::max(order[k], order[m]));
      }
    }
  }
}

bool box_reaches_plane(const Aabb& box, const Vec3& normal, double offset, double pad) {
  const Vec3 centre = 0.5 * (box.lo + box.hi);
  const Vec3 half = 0.5 * (box.hi - box.lo);
  return centre.dot(normal) - half.dot(normal.cwiseAbs()) <= offset + pad;
}

}  // namespace collres
