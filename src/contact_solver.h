// Contact solver: sequential impulses over the contact points of one step.
//
// Units SI (m, s, kg, N s); every vector in the world frame. A body's velocity is six
// doubles, linear velocity of the centre of mass (m/s) then angular velocity (rad/s).
// Each solver row is one contact point with three directions: the normal n (unit, from
// body A towards body B) and two unit tangents t1, t2 ((n, t1, t2) right-handed). An
// impulse P is applied to B at the point and -P to A, so momentum is conserved by
// construction. Relative velocity of a row along a direction d:
//   (v_B + w_B x r_B - v_A - w_A x r_A) . d        (normal component < 0: approaching)
// with r the contact point minus the body's centre of mass. Immovable bodies (static,
// or held for the step) have zero inverse mass and inertia: no branch for them.
//
// Stages, as in Box2D v3's contact solver: prepare, warm start, solve (iterate),
// restitution, store impulses; then a split-impulse position stage (pseudo velocities
// applied to the poses only, never to the velocities: no energy gain) and the contact
// states. Rows live in one flat array of plain structs (each Gauss-Seidel update reads
// all fields of one row together); each manifold is one constraint (Manifold: its rows
// as a span of that array, as detection found them, never regrouped by pair); body data
// are the caller's flat arrays.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <vector>

#include "vec_math.h"
#include "worker.h"

namespace collres {

// How two bodies' coefficients give one per contact (config.RESTITUTION_RULES /
// FRICTION_RULES name them; the values are part of the binding).
enum class CombineRule : int {
  kAverage = 0,    // (a + b) / 2
  kMin = 1,
  kMax = 2,
  kMultiply = 3,   // a b
  kGeometric = 4,  // sqrt(a b), as Box2D and Jolt combine friction
  kPerObject = 5,  // restitution only: A's impulse uses e_A, B's uses e_B (textbook;
                   // momentum is NOT conserved when e_A != e_B)
};

// One coefficient (dimensionless) from the two bodies' ones (kPerObject: the mean).
// (inline: prepare combines five per manifold)
inline double combine(double a, double b, CombineRule rule) {
  switch (rule) {
    case CombineRule::kMin: return std::min(a, b);
    case CombineRule::kMax: return std::max(a, b);
    case CombineRule::kMultiply: return a * b;
    case CombineRule::kGeometric: return std::sqrt(a * b);
    case CombineRule::kAverage:
    case CombineRule::kPerObject: break;
  }
  return 0.5 * (a + b);
}

// What a contact did this step (values equal the Contact.msg constants).
enum ContactStateCode : uint8_t { kImpact = 1, kResting = 2, kSliding = 3, kSticking = 4 };

// The solver's settings (see collres_ros/core/config.py for defaults, ranges, reasons:
// SOLVER_PARAMS and SOLVER_TUNING, each handed over by name by world.solver_params).
struct SolverParams {
  int velocity_iterations = 10;         // sequential-impulse sweeps (more when cold)
  int impact_stages = 64;               // most impact stages per step (resolve_impacts)
  int impact_sweeps = 100;              // most sweeps per impact stage
  double impact_converged = 1e-10;      // relative impulse change that ends an impact stage
  int position_iterations = 1;          // split-impulse sweeps
  int fixed_sweeps = 4;                 // push-out sweeps of the rows on immovable bodies
  int deep_sweeps = 16;                 // push-out sweeps of the deep rows between movables
  double deep_overlap = 1e-3;           // m: ... those overlapping beyond the slop by more
  double support_cosine = 0.5;          // a fixed body is a level's root where the external
                                        // change presses a body into it this squarely
  int shock_sweeps = 2;                 // shock-propagation sweeps per level
  double shock_ratio = 4.0;             // ... only under a body this many times heavier
  double depth_sweeps = 1.5;            // least velocity sweeps per level of the deepest stack
  double restitution_threshold = 0.5;   // m/s: least resting speed of a pair the step's
                                        // external change acts on: slower approaches do
                                        // not bounce (free bodies: none)
  double resting_factor = 1.5;          // ... nor those slower than this times the approach
                                        // the step's external change brought the contact
  double sticking_speed = 0.01;         // m/s: slower tangential motion may stick
  double linear_slop = 0.0001;          // m: penetration left alone by the position pass
  double position_correction = 0.4;     // fraction of the penetration beyond the slop removed
  double max_correction = 0.2;          // m: largest push-out per step
  double converged = 1e-6;              // a sweep changing every impulse by less than this
                                        // times the largest normal impulse ends iterating
  double activation_margin = 0.1;       // m/s: a manifold idle and separating faster than
                                        // its allowance by more than this is left out of
                                        // the sweeps until the answer reaches it
                                        // (StepSolver::admit)
  double row_bound = 0.5;               // a speculative contact separating faster than this
                                        // times (1 + e) the step's fastest approach is no
                                        // row (StepStats::redone: the net under it)
  double cold_extra = 1.0;              // extra sweeps (x velocity_iterations) when every
                                        // persistent contact is new (nothing to warm start)
  double balanced_friction = 1e-3;      // net friction / net normal impulse of a pair below
                                        // which a sticking pair is reported RESTING
  double warm_start_ratio = 10.0;       // stored impulses are scaled by dt / last dt only
                                        // while it lies in [1 / this, this]; else cold
  double match_radius = 0.02;           // m: a contact whose feature id changed warm starts
                                        // from its pair's nearest stored point this close
  int threads = 2;                      // threads of the velocity sweeps (1 or 2)
  int parallel_wave = 16;               // a wave of at least twice this many manifolds is
                                        // shared by the two threads, in parts of at least
                                        // this many (SweepPlan)
  bool wide_rows = true;                // wide groups solved in lanes (SweepPlan)
  double max_substep = 0.0067;          // s: the resting solve's substeps are at most this
                                        // long (StepSolver::soft_step) ...
  int max_substeps = 32;                // ... and at most this many per step
  int landing_substeps = 5;             // from this many substeps on, the landing's sweeps
  int landing_sweeps = 3;               // are the last substep's last this many (land)
  double later_impact = 1e-3;           // fraction of the step: a detected impact this much
                                        // later than its body's earliest ...
  double behind_cosine = 0.7;           // ... and behind it (normals out of the body within
                                        // acos of this) waits for it
  int exact_rows = 32;                  // an island of two or more movable bodies and at
                                        // most this many rows is solved exactly ...
  int exact_rounds = 16;                // ... in at most this many changes of its active set
  double exact_work = 3e-4;             // J: ... where its contacts gave it more mechanical
                                        // energy than this in a substep, and from then on
  double exact_hold = 0.2;              // s: until its sweeps have given it no more ...
  double exact_quiet = 1e-7;            // J: ... than this a substep for so long, or its set
                                        // is not found (StepSolver::exact_islands)
  double exact_tolerance = 1e-9;        // m/s: a breach of a row's rule at most this is none
  double exact_regularise = 1e-8;       // fraction of an exact solve's unknown's own diagonal
                                        // added to it (IslandSolve)
  double aim_turn = 1e-3;               // rad: an aimed row's frame is turned only where the
                                        // centres' line leans from its normal more (aim)
  double substep_sink = 0.02;           // ... and so short that a substep's external change
                                        // sinks a body by at most this fraction of its
                                        // contact reach (a h^2 <= this * reach)
  double stack_sink = 0.5;              // ... and a h^2 <= this * reach / D^2 (D: levels of
                                        // the deepest stack; 0: off)
  CombineRule restitution_rule = CombineRule::kMax;
  CombineRule friction_rule = CombineRule::kGeometric;
};

// One contact point as the solver sees it (prepared once per step). Hot fields first:
// what every velocity sweep reads and writes (solve_block, solve_friction, solve_normal),
// 448 bytes, seven whole cache lines (the struct is aligned to a line); the rest, read by
// the stages around the sweeps, after them.
struct alignas(64) ContactRow {
  // hot: the sweeps
  Vec3 n = Vec3::Zero(), t1 = Vec3::Zero(), t2 = Vec3::Zero();  // unit, world; n A to B
  Vec3 ang_a[3] = {Vec3::Zero(), Vec3::Zero(), Vec3::Zero()};  // r_A x d, r_B x d for
  Vec3 ang_b[3] = {Vec3::Zero(), Vec3::Zero(), Vec3::Zero()};  // d = n, t1, t2 (m)
  Vec3 dw_a[3] = {Vec3::Zero(), Vec3::Zero(), Vec3::Zero()};   // I_A^-1 (r_A x d),
  Vec3 dw_b[3] = {Vec3::Zero(), Vec3::Zero(), Vec3::Zero()};   // I_B^-1 (r_B x d): rad/s per N s
  double ma = 0.0, mb = 0.0;     // inverse masses, 1/kg
  double normal_mass = 0.0;      // kg, 1 / (J_n M^-1 J_n^T), 0 when both immovable
  double kt[3] = {0, 0, 0};      // 1/kg: tangential block K_11, K_12 + K_21, K_22
  double allowance = 0.0;        // m/s >= 0: approach speed allowed without impulse
  double mu = 0.0;               // friction coefficient of the cone this step
  double normal = 0.0;           // N s >= 0, accumulated (what is warm started)
  double tangent[2] = {0, 0};    // N s along t1, t2; |.| <= mu * normal
  // cold: prepare, impacts, shock propagation, landing, position pass, report
  int32_t a = 0, b = 0;          // body indices
  int32_t contact = 0;           // index in the caller's contact arrays
  int32_t manifold = 0;          // index of its Manifold
  bool bounce = false;           // took part in an impact stage (resolve_impacts)
  bool sticking = false;         // slow enough to stick: mu is the static coefficient
  Vec3 ra = Vec3::Zero(), rb = Vec3::Zero();  // m, contact point minus each centre of mass
  double e_a = 0.0, e_b = 0.0;   // restitution applied to A's / B's impulse
  double impact = 0.0;           // N s >= 0, normal impulse of the impact stages (their
                                 // compression and restitution; reported, not warm started)
  double impact_tangent[2] = {0, 0};  // N s, friction impulse of the impact stages, t1, t2
  double landing = 0.0;          // N s, normal impulse that stopped the approach left at the
                                 // touch of a contact closing within the step (reported,
                                 // not warm started; StepSolver::land)
  double push = 0.0;             // m/s: pseudo normal speed the position pass asks for
  double pseudo = 0.0;           // N s (pseudo), accumulated by the position pass
};

// The matrices of a block of 2 to 4 normal rows (prepare_block, once per step, only for the
// blocks a solve takes: kept apart from Manifold, which the sweeps' plans copy in their
// order, so those copies move no matrices): the rows' Delassus matrix J_i M^-1 J_j^T
// (1/kg), as is and with its diagonal a fraction 1e-8 heavier (the block solve's
// regularisation), and the all-active answer's matrix: the first's inverse on all but the
// block's free direction (none along it: the answer of least norm); the sweeps read the
// first two and `residual`, `delassus` only when the all-active answer does not fit. Of k
// rows, the entries [0, k) are set; `inverse` only when Manifold::invertible (the others
// are never read).
struct BlockMatrices {
  double plain[4][4];
  double inverse[4][4];   // kg, when `invertible`
  double residual[4];     // (when `redundant`) |residual . q|: the largest approach (m/s)
                          // the all-active answer leaves its rows along the block's free
                          // direction, q their velocities (else 0)
  double delassus[4][4];
};

// One manifold's constraint: its rows [first, first + count) of the row array, all of
// body pair (a, b); the normal rows of 2 to 4 points are solved together as one block.
struct Manifold {
  int32_t a = 0, b = 0;          // body indices
  int32_t first = 0, count = 0;  // its rows
  int32_t spin = -1;             // index of its SpinRow in the solve's spins, -1: none
  bool invertible = false;       // its matrices' `inverse` holds the all-active answer's
                                 // matrix (at most one free direction)
  bool redundant = false;        // ... and the block has a free direction (their
                                 // `residual` is not all zero)
  bool coupled = false;          // its normal rows and friction solved as one block each
                                 // sweep (every block of an impact stage; a manifold one
                                 // of whose bodies had an impact this step, or one of
                                 // whose points slipped faster than the sticking speed
                                 // as the step began), else the normal block, then the
                                 // friction block
  bool search = false;           // should its coupled solve's moves find no answer,
                                 // every state is searched (solve_coupled): an impact
                                 // stage's block, and in the resting sweeps a coupled
                                 // block that is the only manifold of each of its
                                 // movable bodies (StepSolver::prepare); else it is
                                 // solved split
  const BlockMatrices* matrices = nullptr;   // its block's (prepare_block: every manifold
                                             // a solve takes has them), its owner's store
};

// Gives `store` an entry for each manifold `blocks` has room for (Manifold::matrices point
// into it): grown as `blocks` grows, cleared first so that nothing is copied (no entry
// outlives its step).
inline void fit_matrices(std::vector<BlockMatrices>& store,
                         const std::vector<Manifold>& blocks) {
  if (store.size() >= blocks.capacity()) return;
  store.clear();
  store.resize(blocks.capacity());
}

// The matrices of a manifold of 2 to 4 prepared rows (`rows`: its first row; one row: the
// entries [0][0] alone; more than 4: none, its flags only) into `matrices`, which the
// manifold then points to (Manifold::matrices).
void prepare_block(Manifold& block, const ContactRow* rows, BlockMatrices& matrices);

// Rolling resistance and torsional friction of one manifold (its rows):
// an angular impulse (N m s) on B, opposite on A, against the bodies' relative angular
// velocity w = w_B - w_A: its part across the normal n (rolling) within roll * N, its
// part along n (spin about the normal) within twist * N, N (N s) the pair's normal
// impulse and roll, twist (m) the combined coefficients times the lever of the contact
// (from the centre of mass of the movable body nearer to it: a ball's radius). A ball
// rolling on a floor then decelerates at (5/7) mu_r g, holds on a slope while
// tan(theta) <= mu_r, and its spin about the normal slows at mu_t r m g / I.
struct SpinRow {
  int32_t a = 0, b = 0;            // body indices
  Vec3 n = Vec3::Zero();           // unit, world, A to B (the first row's normal)
  Mat3 inv_a = Mat3::Zero(), inv_b = Mat3::Zero();  // I_A^-1, I_B^-1, world, 1/(kg m^2)
  Mat3 inv_ab = Mat3::Zero();      // I_A^-1 + I_B^-1
  double k_n = 0.0;                // 1/(kg m^2): n (I_A^-1 + I_B^-1) n
  double lever = 0.0;              // m, > 0
  double roll = 0.0, twist = 0.0;  // m: coefficient times lever
  Vec3 torque = Vec3::Zero();      // N m s, accumulated angular impulse on B (-on A)
  double load = 0.0;               // N s, the manifold's normal impulse N, as its rows'
                                   // last update in this sweep left it (solve_velocities)
};

// Per-body solver data: velocities (N, 6) and inverse mass properties.
struct SolverBodies {
  int64_t count = 0;
  const double* inv_mass = nullptr;   // (N,) 1/kg, 0 for immovable bodies
  const Mat3* inv_inertia = nullptr;  // (N,) 1/(kg m^2), world frame, 0 for immovable
  double* velocity = nullptr;         // (N, 6) m/s, rad/s: updated in place
};

// A row's frame from its normal n and levers ra, rb: the tangents, the levers' cross
// products and their images under the inverse inertias, the effective masses. `framed`: a
// row framed before, or null; where its normal has row's bits (a manifold's rows share
// one), row takes its tangents (tangent_basis of the same normal).
void frame_row(ContactRow& row, const SolverBodies& bodies, const ContactRow* framed);

// Prepare one row: its frame (frame_row, `framed` as there), and the friction coefficient:
// static where `slow` (N, 6), the velocity that decides sticking (e.g. before this step's
// external forces), slips slower than sticking_speed, else kinetic.
void prepare_row(ContactRow& row, const ContactRow* framed, const SolverBodies& bodies,
                 const double* slow, double sticking_speed, double mu_static,
                 double mu_kinetic);

// Apply the accumulated impulses of rows [0, count) (warm start) to the velocities. A run
// of one pair's rows cut between two calls gives the same bits as whole.
void warm_start(ContactRow* rows, size_t count, SolverBodies& bodies);

// Lanes of a wide row: four doubles, one per manifold of a wide group, solved together
// (GCC / Clang vector extensions: two SSE2 or NEON registers, one ymm register where the
// kernel's AVX2 or AVX-512 clone runs, of 16 or 32; no -march flag). Aligned to 32 bytes
// whatever the target, so the clones agree on the layout.
constexpr int kLanes = 4;
typedef double Lanes __attribute__((vector_size(32), aligned(32)));

// One row index of a wide group's four manifolds as a structure of arrays (lane l: row
// `first + i` of the group's manifold l): the ContactRow fields the velocity sweeps read
// and write but the frame (n, t1, t2: one per manifold, in its WideGroup), same units and
// signs. Vectors are [x, y, z]; [k][.] for d = n, t1, t2.
struct WideRow {
  Lanes ang_a[3][3], ang_b[3][3], dw_a[3][3], dw_b[3][3];
  Lanes normal_mass, kt[3], allowance, mu;
  Lanes normal, tangent[2];
};

// Up to four manifolds of one wave with the same number of rows (1 to 4), the rows of
// each sharing one frame (wave_manifolds), solved in lanes: their rows are WideRows [row,
// row + count); `manifold` is the first of them (consecutive in the solve's order, in
// lanes [0, lanes)). A lane past them is idle padding: its rows and frame all zero (no
// impulse, no mass, allowance 0: every update leaves it at +0 and changes no twist), its
// bodies lane 0's, read and never written. (What only the searches read: WideFace.)
struct WideGroup {
  size_t manifold = 0, row = 0;
  int count = 0;
  int lanes = 0;                 // its manifolds (1 to kLanes)
  int32_t first[kLanes] = {};    // its lanes' manifolds' first rows (Manifold::first; -1
                                 // in a padding lane)
  int64_t offset_a[kLanes] = {}, offset_b[kLanes] = {};   // 6 * body index: the first of
                                                         // its twist's numbers in velocity
  bool write_a[kLanes] = {}, write_b[kLanes] = {};   // movable: its twist is stored
  Lanes ma, mb;                  // 1/kg
  Lanes invertible;              // 1 where Manifold::invertible and not ::coupled, else 0
                                 // (a lane without it is solved by solve_manifold)
  Lanes n[3], t1[3], t2[3];      // each manifold's frame: every row's (unit, world)
  Lanes plain[4][4], inverse[4][4];   // Manifold::plain, ::inverse (2 to 4 rows)
  Lanes residual[4];                  // Manifold::residual
  bool redundant = false;             // a lane's manifold is Manifold::redundant (else
                                      // `residual` is all zero: its test is skipped)
};

// What a wide group of 2 to 4 rows reads only where the all-active answer does not fit
// (solve_groups): its Delassus matrices, and for a face group (3 or 4 rows) its lanes'
// carrying sets' elimination, kept from one sweep to the next: its pivots, multipliers
// and eliminated diagonal depend only on each lane's set and the group's Delassus
// matrices (the same for the whole plan), so while every lane that needs it asks for the
// set kept, the right-hand side alone is eliminated with them: the same operations on
// it, the same bits.
struct WideFace {
  alignas(32) int64_t set[kLanes] = {-1, -1, -1, -1};   // per lane the carrying set kept
                                                      // (bit i: row i), -1: none
  Lanes delassus[4][4];                 // Manifold::delassus (the active-set search)
  Lanes pivot[4];                       // column c: the row swapped into place (as double)
  Lanes factor[4][4];                   // [c][r]: row c's multiple taken from row r != c
  Lanes diagonal[4];                    // the eliminated matrix's diagonal
  Lanes usable;                         // all bits set where every pivot passed its test
};

// The spin rows (SpinRow) of a wide group's four manifolds in lanes: the fields
// solve_spin reads and writes, same units and signs; `spin` the SpinRows they stand for,
// -1 in a lane without one (a padding lane, a manifold without a spin row: its fields all
// zero, so that its update changes nothing and writes no twist). `wide`: at least one lane
// has one (else the group has no spin rows). `load` is kept here, not in the SpinRows (the
// group's row update writes it, its spin update reads it).
struct WideSpin {
  int32_t spin[kLanes] = {-1, -1, -1, -1};
  bool wide = false;
  Lanes n[3], inv_a[3][3], inv_b[3][3], inv_ab[3][3];
  Lanes k_n, lever, roll, twist, torque[3];
  Lanes load;
};

// How the velocity sweeps visit the manifolds (sweep_waves.h builds it): wave by wave,
// no two manifolds of a wave sharing a movable body, so that a wave's manifolds may be
// solved in any order, in lanes and on two threads, with the bits of the sweep in its
// order (the solve's order, or with two sides the sides' and the seam's: sweep_waves.h);
// each wave in two parts, its sides (one on one thread), each a SweepWave. Part w is manifolds [first,
// wide_end) in wide groups of kLanes (one row count each), [wide_end, lone) the rest of
// each row count 1 to 4 left two or three in wide groups padded with idle lanes, and
// [lone, end) one by one (a row count's one left, then the manifolds of more rows). The
// spin rows come after the rows, part by part: the sweep (SweepPlan::sequence) is the
// rows of the parts before the seam's, their spin rows, then the seam's parts' rows and
// spin rows (part i's rows numbered i, its spin rows the plan's parts plus i). `after`:
// the part (so numbered) of the other side that last moved one of its bodies before its
// rows, -1: none; `spin_after`: the same for its spin rows; `seam`: a part of the seam's
// waves (manifolds joining the two sides, after both).
struct SweepWave {
  size_t first = 0, wide_end = 0, lone = 0, end = 0;
  int32_t side = 0, after = -1, spin_after = -1;
  bool seam = false;
};
// What one thread runs of a sweep in one go (Worker::run_sides): the parts
// SweepPlan::chunk_parts[begin, end), each the rows of part p (p < the plan's parts) or the
// spin rows of part p less the parts, in sweep order, all of one side.
struct SweepChunk {
  uint32_t begin = 0, end = 0;
};
struct SweepPlan {
  std::vector<SweepWave> waves;         // in sweep order
  bool wide = true;                     // wide groups solved in lanes (else one by one:
                                        // the same bits, SOLVER_TUNING wide_rows)
  size_t parallel = 0;                  // waves that average at least twice this many
                                        // manifolds are cut in two sides (sweep_waves.h;
                                        // 0: never), whatever the threads
  Worker* worker = nullptr;             // null: one thread (the sides in turn)
  bool spin_rows = false;               // a manifold has a spin row (Manifold::spin): the
                                        // sweep has spin parts
  std::vector<int32_t> sequence;        // the sweep's parts in order (SweepWave)
  std::vector<SweepChunk> chunks;       // a sweep's chunks, in order, ...
  std::vector<uint8_t> sides;           // ... each one's side (its thread's queue) ...
  std::vector<int32_t> needs;           // ... and the other side's chunks it waits for
                                        // (Worker::run_sides)
  std::vector<int32_t> chunk_parts;     // the chunks' parts (SweepChunk)
  std::vector<int32_t> places;          // scratch: a part's chunk in its side's chunks
  std::vector<int32_t> owner;           // scratch: a part's chunk (index in chunks)
  std::vector<uint8_t> awaited;         // scratch: a part the other side waits for
  // scratch of solve_velocities: the wide groups of the waves and their rows (a pool: slot)
  std::vector<WideGroup> groups;
  std::vector<WideRow> wide_rows;
  std::vector<size_t> wave_groups;      // groups of wave w: slot[wave_groups[w], [w + 1])
  std::vector<WideSpin> spin_groups;    // per entry: its manifolds' spin rows, in lanes
                                        // (spin -1 in a lane: none; WideSpin::wide)
  std::vector<WideFace> faces;          // per entry: its search's data (2 to 4 rows)
  bool packed = false;                  // groups and spin_groups hold the prepared rows'
                                        // constant fields (the first solve_velocities of
                                        // a plan packs them; wave_manifolds clears this)
  // groups, wide_rows, faces and spin_groups are a pool, slot[g] the pool entry of the
  // plan's group g (in wave order): a group of the same four manifolds in the same lanes
  // as one packed since the rows were prepared (rows_epoch, which the caller changes
  // whenever they are) keeps its entry, its constant fields and its kept elimination (the
  // same fields from the same rows: the same bits); only new groups are packed
  std::vector<int32_t> slot;
  uint64_t rows_epoch = 0;
  uint64_t packed_epoch = ~uint64_t{0};   // the rows' generation the pool holds
  size_t pool_groups = 0, pool_rows = 0;  // entries of the pool in use
  std::vector<int32_t> entry_at;          // (rows) the pool entry whose lane 0 is the
                                          // manifold starting at that row, or -1
  std::vector<uint8_t> fresh;             // (pool entries) 1: its constant fields still to
                                          // pack (the first sweep of a plan's solve packs
                                          // each part's on the thread that sweeps it)
};

// The rows whose manifolds start at a row marked in `changed` (rows) have new constant
// fields (their frames): the pool's groups holding one of them are packed anew by the next
// solve_velocities (the others keep their entries).
void repack(SweepPlan& plan, const uint8_t* changed);

// Sequential impulses over the manifolds: normal clamped >= 0 against the speculative
// allowance (a manifold's rows, 2 to 4 of them, solved exactly as one small LCP; one
// row, or more than 4, row by row), friction along minus the slip velocity clamped to the
// circular cone mu * normal. Stops early when a sweep changes no impulse by more than
// params.converged times the largest normal impulse. `spins` (rolling resistance and
// torsional friction, may be null; a manifold's Manifold::spin names its own) are solved
// after the rows in each sweep. Without `plan`, the manifolds in their order on one thread,
// then the spin rows in theirs; with it (`manifolds` in the plan's waves), part by part in
// the plan's sequence (above): the bits of the order the plan stands for, on one thread or
// two. A coupled manifold
// (Manifold::coupled) of 2 to 4 rows is solved as one block with its friction (normal
// impulses, sticking friction, sliding friction mu times its normal). Immovable bodies'
// velocities are read, never written. Returns the sweeps done.
int solve_velocities(std::vector<ContactRow>& rows, const std::vector<Manifold>& manifolds,
                     SolverBodies& bodies, int iterations, double converged,
                     std::vector<SpinRow>* spins = nullptr, SweepPlan* plan = nullptr);

// propagate_shock's blocks (shock_rows): a manifold's rows on an immovable body together,
// any other row alone, by the level of their lower body; the blocks of each such level
// in the order its sweeps visit them (wave_manifolds: wave by wave, wide groups in lanes
// where `wide`, the same bits as in their order) and its SweepPlan (one thread).
struct ShockBlocks {
  std::vector<Manifold> blocks;               // all of them, by lower level
  std::vector<BlockMatrices> matrices;        // blocks' (Manifold::matrices)
  std::vector<std::vector<Manifold>> levels;  // each lower level's, in waves
  std::vector<SweepPlan> plans;               // each lower level's
  std::vector<double> inv_mass;               // (N,) 1/kg of the blocks' bodies (scratch)
  std::vector<double> allowance;              // (propagate_shock's scratch)
};

// Shock propagation (Guendelman et al. 2003) on the velocities: `sweeps` sweeps of the
// normal and friction rows between each pair of levels, non-bouncing rows only, from the
// ground up, `level` (N,) the contact distance of each body
// from an immovable one (0: immovable, -1: not connected to one), in which a row between
// two levels treats its lower body as immovable. Only rows on an immovable body or under
// an upper body at least `ratio` times heavier (by inverse mass) take part: a heavy body
// on a light one is held in the same step instead of after m_heavy / m_light sweeps,
// while between equal masses the one-sided rows would disturb the converging sweeps (a
// tower of equal cubes walks). The rows' accumulated normal impulses take up the change
// (what the next step warm starts from); `blocks` (shock_rows) are solved as the sweeps
// solve a manifold (a level's in lanes, solve_velocities). `scratch`: shock_rows' copies
// of those rows
// (their masses, bounce and the levels stay as prepared for the step: built once, each
// call refreshes what changes, the allowances, friction coefficients and impulses).
void propagate_shock(std::vector<ContactRow>& rows, SolverBodies& bodies,
                     const std::vector<int32_t>& level, std::vector<ContactRow>& scratch,
                     ShockBlocks& blocks, int sweeps);
// propagate_shock's rows (`scratch`), in order, with their lower bodies held, and its
// blocks (ShockBlocks; `wide`: their wide groups in lanes, SweepPlan::wide); `order` and
// `holding` are scratch space.
void shock_rows(const std::vector<ContactRow>& rows, const std::vector<int32_t>& level,
                std::vector<int32_t>& order, std::vector<ContactRow>& scratch,
                ShockBlocks& blocks, std::vector<uint8_t>& holding, double ratio, bool wide);

// Impacts as successive stages, before the resting contacts are solved. A stage takes
// every row that approaches faster than its contact's `threshold` (and faster than its speculative
// allowance: it touches within the step) at the current velocities, and resolves them
// simultaneously, as touching from the reference time on (no allowance): an exact
// inelastic compression with friction (sequential impulses to convergence, manifolds as
// blocks), then restitution along the normals, e times each row's compression impulse
// (Poisson; for rows that all end the compression in contact, the simultaneous Newton
// answer: each leaves at -e times its approach). The restitution is scaled down where it
// would return more energy than the compression took (friction can make Poisson's rule
// gain energy): no stage gains energy for e <= 1, and with e = 1 and no friction none is
// lost. Rows that a stage drives into approach take part in the next one, so a chain of
// touching bodies passes an impact on as successive binary impacts (Newton's cradle).
// Per-object restitution (e_A != e_B) is applied as given, without that bound. Shock
// propagation: the bodies' touching levels are found (from the immovable bodies over the
// rows without allowance: touching at the reference time); in a stage, a row whose lower
// body is supported by such a chain, whose upper body is free or on a higher level and
// at least `shock_ratio` times heavier, and whose push on the lower body lies inside the
// friction cone of one of the lower body's touching rows to the level below (what holds
// it up takes the push; a sideways hit moves it), sees the lower body as immovable and
// stops the upper body's own approach only (the lower body moving towards it does not
// push it); the energy such a row takes and returns is the upper body's alone (the held
// body's motion, which its friction may pass on, is no energy the upper body had). So a
// heavy body landing on a light one resting on the floor stops (and
// bounces) in one stage instead of passing m_light / m_heavy of its momentum down per
// pair of stages. Stops when no row approaches or after `stages` stages (the rest is
// left to the resting solve); returns the stages done. A stage's rows of one manifold
// (ContactRow::manifold, rows of a manifold consecutive) form one block. `scratch`,
// `blocks` (and their `matrices`), `members` and `work` are scratch space.
struct ImpactSettings {
  const double* threshold = nullptr;  // m/s per contact (ContactRow::contact): slower
                                      // approaches do not bounce
  int stages = 64;           // most stages per step
  int sweeps = 100;          // most sequential-impulse sweeps per stage compression
  double converged = 1e-10;  // relative impulse change that ends a stage's compression
  double shock_ratio = 4.0;  // a row's lower body is held under a body this many times
                             // heavier (shock propagation, below)
};
int resolve_impacts(std::vector<ContactRow>& rows, SolverBodies& bodies,
                    const ImpactSettings& settings, std::vector<ContactRow>& scratch,
                    std::vector<Manifold>& blocks, std::vector<BlockMatrices>& matrices,
                    std::vector<int32_t>& members, std::vector<double>& work);

// Split-impulse push-out: pseudo velocities (N, 6, zeroed here; m/s and rad/s) that give
// each row its `push` normal speed (m/s); rows with push 0 keep the pseudo motion from
// driving them deeper. A row between two contact levels (`level`: from the immovable
// bodies up, -1: none) whose upper body is at least `ratio` times heavier than the lower
// one moves the upper body only, as shock propagation: the push does not drive a light
// body into what holds it up (a fixed floor). The sweeps: `iterations` over every row,
// then `fixed_sweeps` over the rows on an immovable body (a fixed shape or a sleeper:
// what the sweep before pushed into it is pushed back out), `deep_sweeps` over the rows
// between two movable bodies that ask for a push above `deep_push` (m/s; the deep
// overlaps those left), each row between two levels moving its upper body only whatever
// the masses (the lower one was just put back on what holds it), and `fixed_sweeps` over
// the rows on immovable bodies again (when deep_sweeps > 0). Returns false (pseudo
// untouched, zero) when no row asks for a push.
bool solve_positions(std::vector<ContactRow>& rows, const SolverBodies& bodies,
                     const std::vector<int32_t>& level, double ratio, double* pseudo,
                     int iterations, int fixed_sweeps, int deep_sweeps, double deep_push);

// Velocity of B's point relative to A's along d, row direction k (0..2 = n, t1, t2), from
// the bodies' twists in v (m/s).
inline double point_velocity(const ContactRow& row, const double* v, int k, const Vec3& d) {
  const double* const a = v + 6 * row.a;
  const double* const b = v + 6 * row.b;
  return dot(load3(b) - load3(a), d) + dot(load3(b + 3), row.ang_b[k]) -
         dot(load3(a + 3), row.ang_a[k]);
}

// Relative velocity of a row along n, t1, t2 (m/s) for velocities v (N, 6).
void row_velocity(const ContactRow& row, const double* v, double out[3]);
// Its normal part alone (m/s, < 0: approaching; the same bits as row_velocity's out[0]).
// Inline: the passes over the rows (the substeps' separations, the landing, the push-out,
// the active set's checks) call it once a row each, several times a step.
inline double normal_velocity(const ContactRow& row, const double* v) {
  return point_velocity(row, v, 0, row.n);
}
// Its tangential parts alone, along t1 and t2 (m/s; the same bits as row_velocity's out[1],
// out[2]). Inline: prepare_row and contact_state (once a contact each step) inline it.
inline void slip_velocity(const ContactRow& row, const double* v, double out[2]) {
  out[0] = point_velocity(row, v, 1, row.t1);
  out[1] = point_velocity(row, v, 2, row.t2);
}

// Friction impulse of a row as a world vector (N s, on B): impact stages and resting solve.
inline Vec3 friction_world(const ContactRow& row) {
  return (row.tangent[0] + row.impact_tangent[0]) * row.t1 +
         (row.tangent[1] + row.impact_tangent[1]) * row.t2;
}

// State of a solved row, the first rule that applies: IMPACT (an impact stage pushed it),
// SLIDING (slips faster than sticking_speed after the solve, or slid before it with
// friction at the cone limit), STICKING (non-zero friction held it), RESTING (otherwise).
// Inline: the step's report (once a contact) inlines it.
inline uint8_t contact_state(const ContactRow& r, const double* velocity, double sticking_speed) {
  constexpr double kNoFriction = 1e-12;   // N s: a friction impulse at most this is none
  double slip[2];
  slip_velocity(r, velocity, slip);
  double size = norm2(r.tangent[0] + r.impact_tangent[0], r.tangent[1] + r.impact_tangent[1]);
  bool friction = size > kNoFriction;
  bool touching = r.normal + r.impact > 0.0;
  bool at_limit = size >= r.mu * (r.normal + r.impact) * (1.0 - 1e-9);
  // sliding: it slips after the solve, or friction at the cone limit could not stop a slip
  // it had before (a held point whose share of the friction reaches its cone is sticking)
  bool sliding = norm2(slip[0], slip[1]) > sticking_speed || (!r.sticking && friction && at_limit);
  if (r.bounce && touching) return kImpact;
  if (touching && sliding && (friction || r.mu == 0.0)) return kSliding;
  return friction ? kSticking : kResting;
}

}  // namespace collres
