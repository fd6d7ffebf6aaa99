// Exact solve of one small island's contact rows (StepSolver::exact_islands).
//
// Units SI (m, s, kg, N s); every vector in the world frame; rows and bodies as the
// contact solver's (contact_solver.h): a row's impulse acts on B along +n, t1, t2 and on
// A opposite, its relative velocity u = J v is B's point less A's (normal < 0:
// approaching). The island's rows are solved as one linear complementarity problem by
// active sets, from the velocities `base` (the substep's start, with the spin rows'
// torques applied): each row is
// - apart: no impulse, its normal speed u_n >= -allowance;
// - sticking: u_n = -allowance (it approaches by its allowance), u_t = 0, the normal
//   impulse >= 0 and the friction within the cone |f| <= mu N;
// - sliding: u_n = -allowance, the friction mu N along a direction fixed when it began to
//   slide (against the slip then), the slip not along the friction.
// It starts from the set it is given (StepSolver::exact_islands: the set its rows' last
// solve found, else, or where that finds none, every row sticking, sliding without
// friction), never from the sweeps'
// answer (whose order a mirror image of the scene changes). Each round solves the active
// rows' equalities as one dense system (partial pivoting) and changes every row that breaks
// its rule by at least kTie of the worst breach (rows that a mirror image maps onto each
// other break theirs equally, up to rounding: no order picks between them): apart ->
// sticking, pulling -> apart, beyond the cone -> sliding along its friction, slipping
// along its friction -> sticking. Every equation's own unknown weighs a fraction
// `regularise` more on the diagonal, so a redundant set (a box on four coplanar points:
// four normal rows, three degrees of freedom) has one answer, near the least weighted
// norm, whatever the rows' order (SolverParams exact_regularise).
#pragma once

#include <cstdint>
#include <vector>

#include "contact_solver.h"

namespace collres {

// (SolverParams exact_rounds, exact_tolerance, exact_regularise)
struct IslandSettings {
  int max_rounds;       // most changes of the active set
  double tolerance;     // m/s: a breach at most this is none
  double regularise;    // fraction of an equation's own diagonal added to it
};

class IslandSolve {
 public:
  // what became of an island's solve: no set found within max_rounds; found, but it left
  // more kinetic energy than the sweeps' answer (kept); found and taken
  enum Outcome { kUnsolved = 0, kKept = 1, kTaken = 2 };
  // One island: `members` its rows (indices of `rows`), `bodies` its movable bodies.
  // `base` (N, 6): the velocities the impulses act on; `velocity` (N, 6): the sweeps'
  // answer, replaced (with the rows' normal and tangent impulses) by the exact one where
  // that is found within max_rounds and leaves the island's bodies no more kinetic energy
  // (`inertia` (N,): their world inertias, kg m^2).
  // `set` (R,) and `along` (R, 2): the active set to start from, each row's State and a
  // sliding row's friction direction (unit, along t1, t2; a row without friction slides,
  // one sliding along no direction sticks); on return the set found (unsolved: the last
  // round's)
  Outcome solve(std::vector<ContactRow>& rows, const std::vector<int32_t>& members,
             const std::vector<int32_t>& bodies, const SolverBodies& solver,
             const Mat3* inertia, const double* base, double* velocity,
             const IslandSettings& settings, uint8_t* set, double* along);
  enum State : uint8_t { kApart = 0, kStick = 1, kSlide = 2 };

 private:
  std::vector<int32_t> local_;       // (N,) a body's index among the island's, -1: other
  std::vector<double> a_;            // (3R, 3R) 1/kg: J M^-1 J^T of the rows' directions
  std::vector<double> b_;            // (3R) m/s: J base
  std::vector<double> lambda_, u_;   // (3R) N s, m/s: the round's impulses and speeds
  std::vector<uint8_t> state_;       // (R) State
  std::vector<double> along_;        // (R, 2) a sliding row's friction direction (t1, t2)
  std::vector<double> breach_;       // (R) m/s
  std::vector<int32_t> unknown_;     // the round's unknowns: 3 i + k
  std::vector<double> answer_;       // (B, 6) the exact answer's velocities
};

}  // namespace collres
