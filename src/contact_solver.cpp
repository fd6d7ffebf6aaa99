#include "contact_solver.h"

#include <algorithm>
#include <cmath>

namespace collres {

double combine(double a, double b, CombineRule rule) {
  switch (rule) {
    case CombineRule::kAverage: return 0.5 * (a + b);
    case CombineRule::kMin: return std::min(a, b);
    case CombineRule::kMax: return std::max(a, b);
    case CombineRule::kMultiply: return a * b;
    case CombineRule::kGeometric: return std::sqrt(a * b);
  }
  return 0.5 * (a + b);
}

}  // namespace collres
