// The compiled core's one math dialect: Eigen's fixed-size vector, matrix and quaternion
// types, shared by detection and solver, and the few helpers the solver stages use.
//
// Plain values, no allocation. Units are the caller's (SI everywhere in the core).
// Quaternions are unit and rotate body-frame vectors into the world frame; in memory (an
// (N, 4) array) they are x, y, z, w (ROS order, which is also Eigen's coefficient order).
//
// The helpers below spell their arithmetic out (dot as ((x x' + y y') + z z'), the matrix
// product row by row in that order, ...) instead of using Eigen's expressions, whose
// summation order may differ: the solver's results are bit-identical across builds and
// thread counts only with one fixed order. Element-wise operations (+, -, scalar *) are
// Eigen's own (exact per element, no order to fix).
#pragma once

#include <cmath>

#include <Eigen/Core>
#include <Eigen/Geometry>

// A hot function cloned for AVX-512 (x86-64-v4: AVX-512 F, VL, BW, DQ, CD, so the 4-double
// lanes of the wide rows get 32 registers instead of 16, fewer spills) and for AVX2, the
// clone picked at load time by what the CPU has (the default one elsewhere): their VEX / EVEX
// forms take fewer instructions, and with no fused multiply-add (-ffp-contract=off, though
// x86-64-v4 has FMA) every clone does the same IEEE operations in the same order: the same
// bits. COLLRES_CLONED_FLAT also inlines every call into the clone (the callees are then
// compiled for it too). GCC on x86-64 only.
#if defined(__x86_64__) && defined(__GNUC__) && !defined(__clang__)
#define COLLRES_CLONED __attribute__((target_clones("arch=x86-64-v4", "avx2", "default")))
#define COLLRES_CLONED_FLAT \
  __attribute__((target_clones("arch=x86-64-v4", "avx2", "default"), flatten))
#else
#define COLLRES_CLONED
#define COLLRES_CLONED_FLAT
#endif
// A function compiled without GCC's code hoisting (-fcode-hoisting, on at -O2 and above),
// where it lengthens the lives of vector values beyond the registers (the function says
// where). Scheduling only: the same IEEE operations, the same bits. GCC only.
#if defined(__GNUC__) && !defined(__clang__)
#define COLLRES_NO_HOISTING __attribute__((optimize("no-code-hoisting")))
#else
#define COLLRES_NO_HOISTING
#endif

namespace collres {

using Vec3 = Eigen::Matrix<double, 3, 1>;
using Mat3 = Eigen::Matrix<double, 3, 3>;
using Quat = Eigen::Quaternion<double>;

inline double dot(const Vec3& a, const Vec3& b) {
  return a.x() * b.x() + a.y() * b.y() + a.z() * b.z();
}
inline Vec3 cross(const Vec3& a, const Vec3& b) {
  return Vec3(a.y() * b.z() - a.z() * b.y(), a.z() * b.x() - a.x() * b.z(),
              a.x() * b.y() - a.y() * b.x());
}
inline double length(const Vec3& a) { return std::sqrt(dot(a, a)); }
// |(x, y)| without std::hypot's overflow care (slow, and not needed at these magnitudes)
inline double norm2(double x, double y) { return std::sqrt(x * x + y * y); }

// Read / write three consecutive doubles (a row of an (N, 3) array).
inline Vec3 load3(const double* p) { return Vec3(p[0], p[1], p[2]); }
inline void store3(double* p, const Vec3& v) { p[0] = v.x(); p[1] = v.y(); p[2] = v.z(); }

// a v, row by row.
inline Vec3 mul(const Mat3& a, const Vec3& v) {
  return Vec3(a(0, 0) * v.x() + a(0, 1) * v.y() + a(0, 2) * v.z(),
              a(1, 0) * v.x() + a(1, 1) * v.y() + a(1, 2) * v.z(),
              a(2, 0) * v.x() + a(2, 1) * v.y() + a(2, 2) * v.z());
}

// The quaternion x, y, z, w (Eigen's constructor takes w first).
inline Quat quat(double x, double y, double z, double w) { return Quat(w, x, y, z); }
inline Quat load4(const double* p) { return quat(p[0], p[1], p[2], p[3]); }
inline void store4(double* p, const Quat& q) {
  p[0] = q.x(); p[1] = q.y(); p[2] = q.z(); p[3] = q.w();
}

// Hamilton product a * b (apply b first, then a).
inline Quat multiply(const Quat& a, const Quat& b) {
  return quat(a.w() * b.x() + a.x() * b.w() + a.y() * b.z() - a.z() * b.y(),
              a.w() * b.y() - a.x() * b.z() + a.y() * b.w() + a.z() * b.x(),
              a.w() * b.z() + a.x() * b.y() - a.y() * b.x() + a.z() * b.w(),
              a.w() * b.w() - a.x() * b.x() - a.y() * b.y() - a.z() * b.z());
}

// Unit quaternion with w >= 0 (the same rotation); q must be non-zero.
inline Quat normalize(const Quat& q) {
  double n = std::sqrt(q.x() * q.x() + q.y() * q.y() + q.z() * q.z() + q.w() * q.w());
  double s = (q.w() < 0.0 ? -1.0 : 1.0) / n;
  return quat(q.x() * s, q.y() * s, q.z() * s, q.w() * s);
}

// Quaternion of a rotation vector (axis * angle, rad); exact, safe at zero.
inline Quat from_rotation_vector(const Vec3& v) {
  double angle = length(v);
  double scale = angle > 1e-12 ? std::sin(0.5 * angle) / angle : 0.5 - angle * angle / 48.0;
  return quat(v.x() * scale, v.y() * scale, v.z() * scale, std::cos(0.5 * angle));
}

// Rotation vector (axis * angle, rad, angle in [0, pi]) of the unit quaternion q: the
// inverse of from_rotation_vector (the shorter arc).
inline Vec3 to_rotation_vector(const Quat& q) {
  const double s = q.w() < 0.0 ? -1.0 : 1.0;
  const Vec3 v(s * q.x(), s * q.y(), s * q.z());
  const double half = length(v);
  const double scale = half > 1e-12 ? 2.0 * std::atan2(half, s * q.w()) / half : 2.0;
  return scale * v;
}

// Orientation after rotating at constant world-frame angular velocity w (rad/s) for dt s.
inline Quat integrate(const Quat& q, const Vec3& w, double dt) {
  return normalize(multiply(from_rotation_vector(dt * w), q));
}

// Spherical interpolation from q0 (s = 0) to q1 (s = 1) along the shorter arc, unit,
// w >= 0; linear weights (then normalised) where the arc is too short for sin's quotient.
inline Quat slerp(const Quat& q0, const Quat& q1_in, double s) {
  Quat q1 = q1_in;
  double d = q0.x() * q1.x() + q0.y() * q1.y() + q0.z() * q1.z() + q0.w() * q1.w();
  if (d < 0.0) q1 = quat(-q1.x(), -q1.y(), -q1.z(), -q1.w());
  d = std::fmin(std::fabs(d), 1.0);
  double theta = std::acos(d);
  double sin_theta = std::sin(theta);
  double w0 = 1.0 - s, w1 = s;
  if (sin_theta >= 1e-9) {
    w0 = std::sin((1.0 - s) * theta) / sin_theta;
    w1 = std::sin(s * theta) / sin_theta;
  }
  return normalize(quat(w0 * q0.x() + w1 * q1.x(), w0 * q0.y() + w1 * q1.y(),
                        w0 * q0.z() + w1 * q1.z(), w0 * q0.w() + w1 * q1.w()));
}

// R B R^T: a body-frame tensor B (row-major 3x3 array) expressed in the world frame.
inline Mat3 rotate_tensor(const Quat& q, const double* body) {
  Mat3 r = q.toRotationMatrix(), rb, out;
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j)
      rb(i, j) = r(i, 0) * body[j] + r(i, 1) * body[3 + j] + r(i, 2) * body[6 + j];
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j)
      out(i, j) = rb(i, 0) * r(j, 0) + rb(i, 1) * r(j, 1) + rb(i, 2) * r(j, 2);
  return out;
}

// Unit tangents t1, t2 with (n, t1, t2) right-handed, defined for every unit n: t1 is
// n x (the world axis least aligned with n).
inline void tangent_basis(const Vec3& n, Vec3& t1, Vec3& t2) {
  double ax = std::fabs(n.x()), ay = std::fabs(n.y()), az = std::fabs(n.z());
  Vec3 axis = (ax <= ay && ax <= az) ? Vec3(1.0, 0.0, 0.0)
                                     : (ay <= az ? Vec3(0.0, 1.0, 0.0) : Vec3(0.0, 0.0, 1.0));
  t1 = cross(n, axis);
  t1 = (1.0 / length(t1)) * t1;   // >= sqrt(2/3) for a unit normal
  t2 = cross(n, t1);
}

}  // namespace collres
