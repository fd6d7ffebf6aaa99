// The stream's usual step's input check (collres_ros/core/validation.py, check_inputs) and the
// world's usual check of detection's contacts (collres_ros/core/world.py, _finite): one pass
// over a step's rows instead of numpy's few whole-array passes, each a Python call, on the
// path of every answer.
#pragma once

#include <cstddef>

namespace collres {

// The width of an input row: position (m, world frame), orientation (x, y, z, w), linear
// velocity (m/s) and angular velocity (rad/s), both world frame.
constexpr std::size_t kInputWidth = 13;

// Whether each of the `count` rows of `in` (count x kInputWidth, row by row) holds every
// number within its magnitude limit (|in[k][j]| <= limits[j]; NaN is not within any) and a
// quaternion whose norm is within `tolerance` of 1. Then `out` (same shape; may not alias
// `in`) holds the rows with each quaternion divided by its norm, the norm summed x, y, z, w
// in that order as numpy's `norm(q, axis=1)` sums it (the same bits); else what `out`
// holds is unspecified and the caller's per-reason checks say what each refused row lacks.
bool usual_inputs(const double* in, std::size_t count, const double* limits, double tolerance,
                  double* out);

// Whether each of the `count` contacts has finite numbers (point (count, 3) m, normal
// (count, 3), separation (count,) m, toi (count,); their sum is, which refuses an overflow
// of finite ones too) and a normal whose length, summed ((x^2 + y^2) + z^2) as the world's
// numpy check sums it (the same bits), exceeds 0.5. Then `unit` (count, 3; may not alias
// `normal`) holds each normal divided by its length; else what it holds is unspecified and
// the caller's row-by-row check says which contacts go.
bool usual_contacts(const double* point, const double* normal, const double* separation,
                    const double* toi, std::size_t count, double* unit);

}  // namespace collres
