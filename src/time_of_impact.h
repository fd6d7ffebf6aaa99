// Time of impact over one step: interpolated motion, bisection, conservative advancement.
//
// Time is the fraction s of the step in [0, 1]: s = 0 is the previous state, s = 1 the
// current one. A body moves by lerp of its position and slerp of its orientation (along
// the shorter arc). Both searches take the pair query as a function of s, so they know
// nothing of coal.
#pragma once

#include <cmath>
#include <optional>
#include <utility>

#include <coal/math/transform.h>

#include "detection_types.h"

namespace collres {

// The interpolated pose of one body over the step.
class Motion {
 public:
  Motion() = default;
  // Positions (m) and unit quaternions at s = 0 and s = 1; `offset` (m, body frame) is
  // where the coal geometry's origin sits and `turn` its axes in the body frame (a piece
  // of a compound body).
  Motion(const Vec3& p0, const Vec3& p1, const Quat& q0, const Quat& q1, const Vec3& offset,
         const Mat3& turn = Mat3::Identity());

  Mat3 rotation_at(double s) const;    // body to world at s (slerp)
  Vec3 position_at(double s) const;    // m, body origin at s (lerp)
  coal::Transform3s at(double s) const;  // pose of the coal geometry at s

 private:
  Vec3 p0_ = Vec3::Zero(), p1_ = Vec3::Zero(), offset_ = Vec3::Zero();
  Mat3 turn_ = Mat3::Identity();
  Quat q0_ = Quat::Identity(), q1_ = Quat::Identity();
};

// Shrinks [s0, s1] (apart at s0, overlapping at s1) until it is shorter than `tolerance`
// or after `max_iterations` halvings; returns the final (s0, s1).
template <class Overlaps>
std::pair<double, double> bisect(Overlaps overlaps, double s0, double s1, double tolerance,
                                 int max_iterations) {
  for (int k = 0; k < max_iterations && s1 - s0 > tolerance; ++k) {
    const double middle = 0.5 * (s0 + s1);
    if (overlaps(middle)) {
      s1 = middle;
    } else {
      s0 = middle;
    }
  }
  return {s0, s1};
}

// Conservative advancement from s = 0 for a pair apart at s = 0. `motion_bound` (m) bounds
// how far any point of one body moves relative to the other over the whole step, so the
// pair cannot touch before s + distance(s) / motion_bound. Returns a bracket (s0, s1),
// apart at s0 and overlapping at s1, or nothing when the pair stays apart over the step.
template <class Distance, class Overlaps>
std::optional<std::pair<double, double>> advance(Distance distance, Overlaps overlaps,
                                                 double motion_bound, double tolerance,
                                                 int max_iterations) {
  if (!(motion_bound > 0.0) || !std::isfinite(motion_bound)) return std::nullopt;
  double s = 0.0;
  const double probe = std::max(4.0 * tolerance / motion_bound, 1e-12);
  for (int k = 0; k < max_iterations; ++k) {
    const double gap = distance(s);
    if (gap <= tolerance) {
      // within `tolerance` of contact: a little later they overlap, or they graze
      const double s1 = std::min(1.0, s + probe);
      if (overlaps(s1)) return std::make_pair(s, s1);
      s = s1;
    } else {
      s += gap / motion_bound;
    }
    if (s >= 1.0) return std::nullopt;
  }
  return std::nullopt;
}

}  // namespace collres
