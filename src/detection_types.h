// Plain data of the detection half: vectors, poses, settings and the contact rows.
//
// Conventions (as collres_ros.core.types): world frame, SI units (m, s); quaternions are
// x, y, z, w (ROS order, unit); normals are unit and point from body A to body B, with
// A < B (body indices in the order of the body specs).
#pragma once

#include <cstdint>
#include <vector>

#include "vec_math.h"

namespace collres {

// How a contact's pair was classified (values of collres_ros.core.types.ContactKind); the
// solver reports a persistent contact that closes fast within the step as an impact.
enum class ContactKind : std::int8_t { persistent = 0, impact = 1, tunnelled = 2 };

// One manifold: the rows [first, first + count) of one body pair (a < b), 1 to 4 points
// (more only in hand-made sets) that detection found together, solved as one constraint.
// Manifolds tile the rows in order; one pair may have several (e.g. the pieces of
// compound bodies), each its own constraint.
constexpr int kManifoldFields = 4;   // a, b, first, count: one (K, 4) int64 row each

// The parameters detection reads (collres_ros.core.config.SolverSettings, same names).
struct DetectionSettings {
  double speculative_margin = 0.02;    // m: pairs closer than this are in contact
  double toi_tolerance = 1e-4;         // fraction of the step: bisection stops below it
  int toi_max_iterations = 30;         // cap on bisection / advancement iterations
  bool ccd = true;                     // sweep pairs apart at both ends of the step
  double linear_slop = 0.0001;         // m: bounds the advancement's distance tolerance
                                       // (the solver's slop: config.SOLVER_PARAMS)
  double restitution_threshold = 0.5;   // m/s: least resting speed of a pair the step's
                                        // external change acts on: slower approaches rest,
                                        // faster ones may impact (free bodies: none)
  double resting_factor = 1.5;         // ... and those slower than this times the approach
                                       // the step's external change brought the pair
                                       // (SolverParams::resting_factor)
  double reuse_shift = 0.02;           // fraction of the thinner body's smallest half
                                       // extent: a stored manifold is reused while its
                                       // pair shifted less than this times it relative
                                       // to each other along its contact plane
                                       // (SOLVER_TUNING)
  double margin_speed = 1.2;           // m/s: a pair of bodies that do not move over the
                                       // step keeps at least this times dt of the margin
                                       // (Detector::pair_margin; SOLVER_TUNING)
  int max_pairs = 20000;               // budget: broad-phase pairs queried per step
  int max_contacts = 40000;            // budget: contact rows per step
  int max_contacts_per_pair = 8;       // rows kept per pair of bodies (the deepest; a pair
                                       // of compound bodies has a manifold per piece pair)
};

// Whether the step's external change acts on a body, the rule of the resting floor
// (restitution_threshold applies to a pair only where it does; free bodies rest at no
// approach of their own): its twist changed between the previous and the current state
// (a load, as gravity), or it is unknown: a body whose pose stayed while its twist moves
// it has no previous state of its own (a fresh start gives previous = current).
inline bool external_change_acts(bool twist_changed, bool moving, bool pose_moved) {
  return twist_changed || (moving && !pose_moved);
}

// What the budget of the last step dropped (zero when the step was within it).
struct StepBudget {
  std::size_t pairs_dropped = 0;  // broad-phase pairs never queried
  std::size_t rows_dropped = 0;   // contact rows beyond max_contacts
};

// The poses of all N bodies at both ends of a step; arrays are C-contiguous, row-major.
// Twists are the current ones (the velocity over the step, world frame).
struct StepPoses {
  int count = 0;
  const double* p0 = nullptr;       // (N, 3) m, previous centre of mass
  const double* q0 = nullptr;       // (N, 4) previous orientation x, y, z, w
  const double* p1 = nullptr;       // (N, 3) m, current centre of mass
  const double* q1 = nullptr;       // (N, 4) current orientation
  const double* linear = nullptr;   // (N, 3) m/s, current linear velocity
  const double* angular = nullptr;  // (N, 3) rad/s, current angular velocity
  const double* linear0 = nullptr;  // (N, 3) m/s, previous linear velocity (null: as current)
  const double* angular0 = nullptr; // (N, 3) rad/s, previous angular velocity (null: as current)
  const std::uint8_t* active = nullptr;  // (N,) or null: 0 = frozen, held at its current pose
  double dt = 0.0;                  // s, the step's period (0: unknown; the margin of a
                                    // pair at rest is then kRestingMargin's alone)
};

struct BodyShape;   // shapes.h

// Contact rows of one step, M = size() of them, grouped by pair in increasing (a, b) order,
// and their K manifolds (collres_ros.core.types.ContactSet, field by field). While rows are
// added, the row columns may be longer than M: room that `add` fills one row at a time
// without growing every column per row; `trim` cuts them to M (Detector::detect returns
// trimmed rows).
struct ContactRows {
  std::vector<std::int64_t> body_a, body_b;  // (M,)
  std::vector<double> point;       // (M, 3) m, world, at the contact configuration
  std::vector<double> normal;      // (M, 3) unit, world, from A to B
  std::vector<double> separation;  // (M,) m, signed, < 0 when penetrating
  std::vector<double> toi;         // (M,) fraction of the step in [0, 1]
  std::vector<std::int8_t> kind;   // (M,) ContactKind
  std::vector<std::int64_t> feature;  // (M,) same corner / face of A and B, same id
  std::vector<std::int32_t> piece_a, piece_b;  // (M,) the piece of A and of B (0: one shape)
  std::vector<std::int64_t> manifolds;  // (K, 4) a, b, first row, row count

  void clear();
  void reserve(std::size_t rows);   // capacity of every column for this many rows
  // One row between the pieces a and b: point `at` (m, world), unit normal `n` A -> B,
  // separation `gap` (m), time of impact `fraction` (of the step), feature `id`.
  // (Inline, defined in detection.cpp, where all rows are added.)
  inline void add(const BodyShape& a, const BodyShape& b, const Vec3& at, const Vec3& n,
                  double gap, double fraction, ContactKind contact, std::int64_t id);
  // The rows of a loop that adds rows of one kind (a reused manifold's): `room` for
  // `count` more rows first, then `put` each (add's columns but the kind, no room test),
  // then `set_kind` of the rows from `first` on. With the kind's byte store (which may
  // alias any column's data pointer, loaded again after it) out of the loop, the columns'
  // pointers stay in registers through it. (Inline, defined in detection.cpp.)
  inline void room(std::size_t count);
  inline void put(const BodyShape& a, const BodyShape& b, const Vec3& at, const Vec3& n,
                  double gap, double fraction, std::int64_t id);
  void set_kind(std::size_t first, ContactKind contact);
  // Close the manifold of pair (a, b) whose rows start at `first` (the rows added since);
  // a manifold without rows is no manifold.
  void close_manifold(std::int64_t a, std::int64_t b, std::size_t first);
  // Drop the rows from `first` on (added since the last manifold was closed; first <= size);
  // their columns' room stays.
  void drop_from(std::size_t first);
  // Keep only these rows (indices in increasing order), in their order; a manifold keeps
  // its kept rows (none: it goes).
  void keep(const std::vector<std::size_t>& rows);
  // These rows (any order, each at most once) in that order, into `out` (cleared first;
  // its manifolds are the caller's to set).
  void take(const std::vector<std::size_t>& rows, ContactRows& out) const;
  // `other`'s rows and manifolds after these, in steps of which two threads may run the
  // parts at once: part 0 appends other's rows to the point and normal columns, part 1 to
  // the others (each column cut to size() rows first); then `appended` counts the rows and
  // appends other's manifolds (their first rows shifted).
  void append_part(const ContactRows& other, int part);
  void appended(const ContactRows& other);
  // The row columns cut to size() rows (the room `add` left dropped).
  void trim();
  std::size_t size() const { return rows_; }

 private:
  void make_room(std::size_t count);   // room for `count` more rows (at least 64) in every
                                       // row column (add and room, when it is short)
  void resize_columns(std::size_t rows);   // every row column to this many rows
  // f(column, values a row) for each row column (not the manifolds)
  template <class F>
  void each_row_column(F&& f) {
    f(body_a, 1);
    f(body_b, 1);
    f(point, 3);
    f(normal, 3);
    f(separation, 1);
    f(toi, 1);
    f(kind, 1);
    f(feature, 1);
    f(piece_a, 1);
    f(piece_b, 1);
  }
  std::size_t rows_ = 0;
};

}  // namespace collres
