// Small fixed-size vector, quaternion and matrix helpers for the solver stages.
//
// Plain values, no allocation. Quaternions are x, y, z, w (ROS order), unit length,
// rotating body-frame vectors into the world frame. Matrices are row-major 3x3.
#pragma once

#include <cmath>

namespace collres {

struct Vec3 {
  double x = 0.0, y = 0.0, z = 0.0;
};

inline Vec3 operator+(Vec3 a, Vec3 b) { return {a.x + b.x, a.y + b.y, a.z + b.z}; }
inline Vec3 operator-(Vec3 a, Vec3 b) { return {a.x - b.x, a.y - b.y, a.z - b.z}; }
inline Vec3 operator-(Vec3 a) { return {-a.x, -a.y, -a.z}; }
inline Vec3 operator*(double s, Vec3 a) { return {s * a.x, s * a.y, s * a.z}; }
inline Vec3& operator+=(Vec3& a, Vec3 b) { a = a + b; return a; }
inline Vec3& operator-=(Vec3& a, Vec3 b) { a = a - b; return a; }
inline double dot(Vec3 a, Vec3 b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
inline Vec3 cross(Vec3 a, Vec3 b) {
  return {a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x};
}
inline double length(Vec3 a) { return std::sqrt(dot(a, a)); }
// |(x, y)| without std::hypot's overflow care (slow, and not needed at these magnitudes)
inline double norm2(double x, double y) { return std::sqrt(x * x + y * y); }
inline bool finite(Vec3 a) {
  return std::isfinite(a.x) && std::isfinite(a.y) && std::isfinite(a.z);
}

// Read / write three consecutive doubles (a row of an (N, 3) array).
inline Vec3 load3(const double* p) { return {p[0], p[1], p[2]}; }
inline void store3(double* p, Vec3 v) { p[0] = v.x; p[1] = v.y; p[2] = v.z; }

struct Mat3 {
  double m[9] = {0, 0, 0, 0, 0, 0, 0, 0, 0};
};

inline Vec3 operator*(const Mat3& a, Vec3 v) {
  return {a.m[0] * v.x + a.m[1] * v.y + a.m[2] * v.z,
          a.m[3] * v.x + a.m[4] * v.y + a.m[5] * v.z,
          a.m[6] * v.x + a.m[7] * v.y + a.m[8] * v.z};
}

struct Quat {
  double x = 0.0, y = 0.0, z = 0.0, w = 1.0;
};

inline Quat load4(const double* p) { return {p[0], p[1], p[2], p[3]}; }
inline void store4(double* p, Quat q) { p[0] = q.x; p[1] = q.y; p[2] = q.z; p[3] = q.w; }

// Hamilton product a * b (apply b first, then a).
inline Quat multiply(Quat a, Quat b) {
  return {a.w * b.x + a.x * b.w + a.y * b.z - a.z * b.y,
          a.w * b.y - a.x * b.z + a.y * b.w + a.z * b.x,
          a.w * b.z + a.x * b.y - a.y * b.x + a.z * b.w,
          a.w * b.w - a.x * b.x - a.y * b.y - a.z * b.z};
}

// Unit quaternion with w >= 0 (the same rotation); q must be non-zero.
inline Quat normalize(Quat q) {
  double n = std::sqrt(q.x * q.x + q.y * q.y + q.z * q.z + q.w * q.w);
  double s = (q.w < 0.0 ? -1.0 : 1.0) / n;
  return {q.x * s, q.y * s, q.z * s, q.w * s};
}

// Quaternion of a rotation vector (axis * angle, rad); exact, safe at zero.
inline Quat from_rotation_vector(Vec3 v) {
  double angle = length(v);
  double scale = angle > 1e-12 ? std::sin(0.5 * angle) / angle : 0.5 - angle * angle / 48.0;
  return {v.x * scale, v.y * scale, v.z * scale, std::cos(0.5 * angle)};
}

// Orientation after rotating at constant world-frame angular velocity w (rad/s) for dt s.
inline Quat integrate(Quat q, Vec3 w, double dt) {
  return normalize(multiply(from_rotation_vector(dt * w), q));
}

// Spherical interpolation from q0 (s = 0) to q1 (s = 1) along the shorter arc.
inline Quat slerp(Quat q0, Quat q1, double s) {
  double d = q0.x * q1.x + q0.y * q1.y + q0.z * q1.z + q0.w * q1.w;
  if (d < 0.0) q1 = {-q1.x, -q1.y, -q1.z, -q1.w};
  d = std::fmin(std::fabs(d), 1.0);
  double theta = std::acos(d);
  double sin_theta = std::sin(theta);
  double w0 = 1.0 - s, w1 = s;
  if (sin_theta >= 1e-9) {
    w0 = std::sin((1.0 - s) * theta) / sin_theta;
    w1 = std::sin(s * theta) / sin_theta;
  }
  return normalize({w0 * q0.x + w1 * q1.x, w0 * q0.y + w1 * q1.y, w0 * q0.z + w1 * q1.z,
                    w0 * q0.w + w1 * q1.w});
}

// Rotation matrix of a unit quaternion.
inline Mat3 to_matrix(Quat q) {
  double xx = q.x * q.x, yy = q.y * q.y, zz = q.z * q.z;
  double xy = q.x * q.y, xz = q.x * q.z, yz = q.y * q.z;
  double wx = q.w * q.x, wy = q.w * q.y, wz = q.w * q.z;
  Mat3 r;
  r.m[0] = 1.0 - 2.0 * (yy + zz); r.m[1] = 2.0 * (xy - wz); r.m[2] = 2.0 * (xz + wy);
  r.m[3] = 2.0 * (xy + wz); r.m[4] = 1.0 - 2.0 * (xx + zz); r.m[5] = 2.0 * (yz - wx);
  r.m[6] = 2.0 * (xz - wy); r.m[7] = 2.0 * (yz + wx); r.m[8] = 1.0 - 2.0 * (xx + yy);
  return r;
}

// R B R^T: a body-frame tensor B (row-major 3x3) expressed in the world frame.
inline Mat3 rotate_tensor(Quat q, const double* body) {
  Mat3 r = to_matrix(q), rb, out;
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j)
      rb.m[3 * i + j] = r.m[3 * i] * body[j] + r.m[3 * i + 1] * body[3 + j] +
                        r.m[3 * i + 2] * body[6 + j];
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j)
      out.m[3 * i + j] = rb.m[3 * i] * r.m[3 * j] + rb.m[3 * i + 1] * r.m[3 * j + 1] +
                         rb.m[3 * i + 2] * r.m[3 * j + 2];
  return out;
}

// Unit tangents t1, t2 with (n, t1, t2) right-handed, defined for every unit n: t1 is
// n x (the world axis least aligned with n).
inline void tangent_basis(Vec3 n, Vec3& t1, Vec3& t2) {
  double ax = std::fabs(n.x), ay = std::fabs(n.y), az = std::fabs(n.z);
  Vec3 axis = (ax <= ay && ax <= az) ? Vec3{1, 0, 0} : (ay <= az ? Vec3{0, 1, 0} : Vec3{0, 0, 1});
  t1 = cross(n, axis);
  t1 = (1.0 / length(t1)) * t1;   // >= sqrt(2/3) for a unit normal
  t2 = cross(n, t1);
}

}  // namespace collres
