// The stream's usual step's input check (input_check.h).
#include "input_check.h"

#include <cmath>

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

}  // namespace collres
