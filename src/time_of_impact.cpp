#include "time_of_impact.h"

namespace collres {

Motion::Motion(const Vec3& p0, const Vec3& p1, const Quat& q0, const Quat& q1,
               const Vec3& offset, const Mat3& turn)
    : p0_(p0), p1_(p1), offset_(offset), turn_(turn), q0_(q0), q1_(q1) {
  if (q0_.dot(q1_) < 0.0) q1_.coeffs() = -q1_.coeffs();  // the shorter arc
}

Mat3 Motion::rotation_at(double s) const {
  if (s <= 0.0) return q0_.toRotationMatrix();
  if (s >= 1.0) return q1_.toRotationMatrix();
  return slerp(q0_, q1_, s).toRotationMatrix();
}

Vec3 Motion::position_at(double s) const { return p0_ + s * (p1_ - p0_); }

coal::Transform3s Motion::at(double s) const {
  const Mat3 rotation = rotation_at(s);
  return coal::Transform3s(rotation * turn_, position_at(s) + rotation * offset_);
}

}  // namespace collres
