// Contact solver: the combine rules of two bodies' materials (more stages follow).
//
// Units SI (m, s, kg, N s); every vector in the world frame.
#pragma once

namespace collres {

// How two bodies' coefficients give one per contact (config.RESTITUTION_RULES /
// FRICTION_RULES name them; the values are part of the binding).
enum class CombineRule : int {
  kAverage = 0,    // (a + b) / 2
  kMin = 1,
  kMax = 2,
  kMultiply = 3,   // a b
  kGeometric = 4,  // sqrt(a b), as Box2D and Jolt combine friction
};

// One coefficient (dimensionless) from the two bodies' ones.
double combine(double a, double b, CombineRule rule);

}  // namespace collres
