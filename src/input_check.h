// The stream's usual step's input check (collres_ros/core/validation.py, check_inputs): one
// pass over a step's input rows instead of numpy's few whole-array passes, each a Python
// call, on the path of every answer.
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

}  // namespace collres
