// The stream's usual step's input check (input_check.h).
#include "input_check.h"

#include <algorithm>
#include <cmath>
#include <limits>

namespace collres {

bool usual_inputs(const double* in, std::size_t count, const double* limits, double tolerance,
                  double* out) {
  for (std::size_t k = 0; k < count; ++k) {
    const double* row = in + k * kInputWidth;
    double* copy = out + k * kInputWidth;
    for (std::size_t j = 0; j < kInputWidth; ++j) {
      if (!(std::fabs(row[j]) <= limits[j])) return false;   // NaN fails too
      copy[j] = row[j];
    }
    const double* q = row + 3;
    double total = q[0] * q[0] + q[1] * q[1];   // numpy's order: ((x^2 + y^2) + z^2) + w^2
    total += q[2] * q[2];
    total += q[3] * q[3];
    const double norm = std::sqrt(total);
    if (!(std::fabs(norm - 1.0) <= tolerance)) return false;
    for (std::size_t j = 3; j < 7; ++j) copy[j] = row[j] / norm;
  }
  return true;
}

bool usual_contacts(const double* point, const double* normal, const double* separation,
                    const double* toi, std::size_t count, double* unit) {
  // every number summed: finite only when each is (an overflow of finite ones is refused
  // too: the caller's row-by-row check takes it)
  double total = 0.0, shortest = std::numeric_limits<double>::infinity();
  for (std::size_t k = 0; k < count; ++k) {
    const double* n = normal + 3 * k;
    const double* p = point + 3 * k;
    const double length = std::sqrt((n[0] * n[0] + n[1] * n[1]) + n[2] * n[2]);
    shortest = std::min(shortest, length);
    total += ((p[0] + p[1]) + p[2]) + ((separation[k] + toi[k]) + length);
    for (int d = 0; d < 3; ++d) unit[3 * k + d] = n[d] / length;
  }
  return std::isfinite(total) && shortest > 0.5;
}

}  // namespace collres
