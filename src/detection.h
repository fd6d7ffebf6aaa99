// Detection of one step: the contacts the solver resolves (the stage driver).
//
// One step, previous poses (s = 0) -> current poses (s = 1):
// 1. Motion: each body moves by lerp of its position and slerp of its orientation; a
//    frozen (inactive) body is held at its current pose; `moved` bounds how far any of
//    its points travels.
// 2. Broad phase (broad_phase.h): swept boxes padded by half the speculative margin give
//    the candidate pairs; half-spaces are tested against every finite box, and each
//    triangle mesh's tree of triangles is asked for those near every finite box. Pairs of two
//    fixed bodies (static or frozen), pairs with a non-finite pose and pairs the collision
//    filter drops (PairFilter: groups, masks, ignored pairs) are skipped, so they never
//    reach the narrow phase, the stored manifolds or the contact rows; a pair is (a, b)
//    with a < b.
// 3. Stored manifolds (manifold.h): a pair of flat-faced bodies that was in contact last
//    step keeps its contact points, stored in the two body frames, while the pair has
//    shifted relative to each other along its contact plane since they were measured by
//    less than reuse_shift (DetectionSettings) times the thinner body's smallest half
//    extent (a stored point is about that far from where a fresh query finds it: the same
//    share of any body's size; a shift along the manifold's normal moves no point along
//    either face, only the gaps) and turned by less than kReuseRotation; only their gaps
//    are recomputed (no coal query), as long as the narrow phase would call the pair
//    persistent (step 4: its least gap plus how much the step may have changed it within
//    the margin, no hit fast enough to bounce, no deep overlap; with a half-space only the
//    motion along its normal changes the gap). Motion the two bodies share does not count:
//    a pile that its source integrated one 30 Hz period under gravity keeps its points. A
//    curved body's points are never reused (nor stored): on a rolling surface they would
//    turn with the body. A pair the narrow phase measured apart (beyond the margin) keeps that distance
//    with its relative pose; while the distance less how far a point of either body has
//    since moved relative to the other stays beyond the margin and the step's relative
//    motion, the narrow phase would give it no rows and it is not queried.
// 4. Narrow phase of the other pairs at the current state (coal), then per pair:
//    PERSISTENT when within the margin at the previous state too (or within it now and
//    apart before without a hit: a speculative contact); IMPACT when apart before and
//    overlapping now, also from within the margin when the pair closes faster than the
//    restitution threshold: bisection for the time of impact (time_of_impact.h);
//    TUNNELLED when apart at both ends but conservative advancement finds a hit, then the
//    same bisection. A pair touching at the previous state (within the slop) is never an
//    impact or a tunnelling: it is in contact from the start; one that the step carried
//    past each other (a step of several periods after dropped inputs, which its source
//    integrated under gravity through the floor) keeps the contact of the previous state,
//    carried along with each body (deep_persistent).
// 5. Manifolds: coal contact patches where faces touch, at most four points, each with a
//    feature id (the same every step for the same corner, edge or face of both bodies).
// 6. Speculative corners of an impact (speculate): the impact stops the corner that hits,
//    and the rest of the step may turn the body's other corners into a flat-faced partner
//    (a cube falling on one corner at 30 Hz). With the impact manifold comes a second
//    manifold of the same pair, at the time of impact: up to four corners of each movable
//    body (shapes.h lowest_points) above the partner's contact plane by less than their
//    reach over the rest of the step, each a row on that plane with its height as a
//    positive separation, so the solver keeps them from closing by more than that.
//
// The margin of a pair (pair_margin; "the margin" above and below, but the broad phase's
// padding, the budget's and the stages an impact starts: speculate's reach after a time
// of impact, deep_persistent): while neither body moves over the step, the larger of
// kRestingMargin of the speculative margin and margin_speed (DetectionSettings) times the
// step's dt (StepPoses::dt; a gap a pair at rest closes within the step at that speed),
// grown by how far each of the two moves (Body::moved, as Rapier's soft CCD prediction
// grows with each body's own motion), up to the speculative margin. A body that moves
// stops its partner within the step only where the pair has a row: a column falling as
// one, whose lowest cube the floor stops, keeps its rows between cubes (a margin grown by
// the relative motion alone, none for bodies falling together, let a 30 Hz column sink
// 94 mm into itself); a settled pile at 120 Hz moves by g dt^2 (0.7 mm a step) and keeps
// its points within about 11.4 mm: at the full margin its farther points never became
// rows, yet were detected, framed, cached and reported every step. At 60 Hz the floor of
// margin_speed (1.2 m/s: 20 mm) keeps the whole margin: with the quarter alone a settled
// pile's balls rolled on longer.
//
// Compound bodies (as Box2D v3 and Jolt): the detector works on shapes, each with its body
// and its pose in the body frame; a body of one shape has one. Every stage above runs on
// pairs of shapes (two shapes of one body never pair; the filter is the bodies'), and each
// row names its bodies and their pieces; the feature id carries the piece pair. Rows are
// then grouped by pair of bodies in (a, b) order, and a pair of bodies keeps at most
// max_contacts_per_pair rows (the deepest, in their order).
//
// Triangle meshes (static scenery, shapes.h): each triangle is a piece. Before the cap, the
// manifolds of a pair with a mesh that share one normal (the triangles of one flat part of
// the mesh under one face of the other body) become one manifold of at most four rows,
// the deepest and those that span the most area (reduce_manifold), as one face would give
// (Jolt reduces mesh contacts alike): a box on a floor of many triangles rests on its four
// corners.
//
// Budget (DetectionSettings max_pairs, max_contacts; as MuJoCo's nconmax and PhysX's contact
// buffer): a step with more pairs to query (broad-phase pairs whose bounding spheres come
// within the margin or the relative motion; the others need no coal query) queries only
// the max_pairs whose bounding spheres overlap deepest (for a half-space, the sphere's depth
// below it), and a step of more rows keeps the max_contacts deepest (least separation);
// rows stay grouped by pair in (a, b) order. Work and memory per step are then bounded
// whatever the poses; budget() says what the last step dropped.
//
// Threads (set_threads): the pairs after the broad phase are independent (each reads the
// step's bodies and the stored manifolds, writes its own rows and manifold): with two
// threads the caller takes the first half and a worker the second, each into its own lane
// (coal queries, scratch, rows, manifolds to store), rows joined in pair order: the same
// bits; the manifolds are stored as the two lanes' parts and looked up in either. The
// second half's chunks that the caller runs before the worker takes one go on in the
// caller's lane, so a step the worker did not help with copies nothing.
//
// Rows (ContactRows): PERSISTENT rows are at the current state (toi 0, separation > 0 for
// a speculative gap, < 0 for a penetration). IMPACT rows have point and normal at the
// time of impact and separation min(separation there, signed distance now) < 0;
// TUNNELLED rows have point, normal and separation (about 0) at the time of impact. The
// speculative corners of an impact are rows of its kind and time of impact with a positive
// separation: the gap at the time of impact.
#pragma once

#include <cstdint>
#include <memory>
#include <utility>
#include <vector>

#include "broad_phase.h"
#include "detection_types.h"
#include "manifold.h"
#include "shapes.h"
#include "time_of_impact.h"
#include "worker.h"

namespace collres {

constexpr double kDeepFraction = 0.25;     // EPA's normal is not trusted deeper than this
                                           // part of the thinner body
constexpr double kReuseRotation = 1e-2;    // rad: a manifold is reused while its pair has
                                           // turned less than this relative to each other
                                           // (and shifted less than reuse_shift along
                                           // its contact plane)
constexpr double kApartSlack = 1e-5;      // m: a stored distance counts this much less (GJK's
                                           // tolerance and the retry step on either measure)
constexpr double kRestingMargin = 0.25;   // of the speculative margin: the margin of a
                                           // pair of bodies that do not move over the step
                                           // (pair_margin)
constexpr double kSkin = 0.05;             // m: the broad phase keeps the pairs of boxes
                                           // grown by this while no box leaves its own
constexpr int kParallelShapes = 64;        // a detector of fewer shapes runs on one thread
constexpr int kPairChunks = 8;             // chunks of the pairs' second part
constexpr double kShareWeight = 0.25;      // of a step's even share in the first part's
constexpr double kLeastShare = 0.25;       // share of the pairs (Detector::detect_paired),
                                           // which keeps within [least, 1 - least]

class Detector {
 public:
  // `shapes` in body order (BodyShape::body non-decreasing, from 0 to bodies - 1, each
  // body at least one shape; std::invalid_argument otherwise).
  Detector(std::vector<BodyShape> shapes, int bodies);

  // New settings take effect at the next step; a new margin forgets the stored manifolds.
  void set_settings(const DetectionSettings& settings);
  // A new collision filter (see PairFilter) for the next step: one group and one mask per
  // body, ignored pairs of body indices (std::invalid_argument otherwise). The manifolds
  // stored for a pair it drops are never read again (the store keeps only the pairs of the
  // last step), and as the pair gives no rows its warm-start impulses go too.
  void set_filter(std::vector<std::uint64_t> group, std::vector<std::uint64_t> mask,
                  const std::vector<std::pair<int, int>>& ignored);
  const DetectionSettings& settings() const { return settings_; }
  // Threads of detection from the next step on (1 or 2): with 2 and at least
  // kParallelShapes shapes, the step's stages run as chunks of one Worker::run_sides
  // (worker.h), this thread's and the worker's, each chunk after those it reads
  // (detect_paired): each half of the shapes' motion and swept boxes; the refit of the sweep;
  // each half of its fat pairs tested (and the half-spaces against each half of the boxes);
  // their join with the other pairs (meshes; the budget); then the pairs, a first part here
  // into the first lane and the rest in kPairChunks ordered chunks (each on the worker or
  // here) into the second lane (the leading chunks that run here: the first), whose rows
  // then follow the first's (their columns copied by both threads, ContactRows::
  // append_part): the same rows, bit for bit, with 1 or 2. The first part's share
  // of the pairs follows the time a pair took in either part, so that both end together.
  void set_threads(int threads) { threads_ = threads; }
  // chunks of the second halves run so far: by the worker, and by either thread
  std::uint64_t helped() const { return worker_ ? worker_->helped() : 0; }
  std::uint64_t chunks_run() const { return worker_ ? worker_->chunks_run() : 0; }
  // detects posted for two threads so far, and of those run paired (Worker::runs,
  // paired_runs)
  std::uint64_t runs() const { return worker_ ? worker_->runs() : 0; }
  std::uint64_t paired_runs() const { return worker_ ? worker_->paired_runs() : 0; }
  int count() const { return bodies_count_; }   // bodies
  int pieces() const { return static_cast<int>(shapes_.size()); }

  // The contacts of the step (see the file comment); `out` is cleared first.
  void detect(const StepPoses& poses, ContactRows& out);
  // After the solve (as Box2D v3's continuous step, against fixed shapes): `poses` from
  // each body's previous pose (s = 0) to its answer (s = 1). A body that turns or moves
  // far in a step takes its points along arcs that the solver's straight-line rows do not
  // follow, and its corners without rows are not held at all (a thin plate tumbling at
  // 0.8 rad a step into a floor): for every movable body that moved more than the slop,
  // against every fixed shape its swept box reaches, the motion is sampled finely enough
  // that it cannot pass the shape between samples (the shape's smallest half extent per
  // sample; one at the end for a half-space), and the first sample where the pair is
  // deeper than it was at s = 0 (or touching) by more than the slop is bisected for the
  // boundary; `fraction` (N,) gets, per body, the latest s before it (1: the answer
  // stands). Triangle meshes are left out.
  void hold_back(const StepPoses& poses, std::vector<double>& fraction);
  // The broad-phase pairs of bodies (a < b), sorted (for tests and tools).
  void candidate_pairs(const StepPoses& poses, std::vector<std::pair<int, int>>& pairs);
  // Forget the stored manifolds (e.g. after bodies were teleported).
  void reset() {
    stored_[0].clear();
    stored_[1].clear();
  }
  // What the budget dropped in the last detect() (see the file comment).
  const StepBudget& budget() const { return budget_; }

 private:
  struct Body {   // one per shape: its body's motion
    Vec3 p0, p1;        // m, centre of mass at s = 0 and s = 1
    Quat q0, q1;        // unit, w >= 0
    Mat3 r1;            // body to world at s = 1
    Vec3 linear, angular;  // current twist (zero for frozen bodies)
    Vec3 external_linear, external_angular;  // current less previous twist: the step's
                                             // external change (zero for frozen bodies)
    bool loaded = false;  // the step's external change acts on it (external_change_acts)
    double turn = 0.0;  // rad, rotation over the step
    Vec3 shift = Vec3::Zero();  // m, p1 - p0
    double swing = 0.0; // m, turn times the shape's bounding radius (0 when unbounded): how
                        // far the turn may carry a point about the centre of mass
    double moved = 0.0; // m, bound on any point's travel over the step
    bool fixed = false; // static or frozen
    bool valid = true;  // finite pose
    coal::Transform3s pose1;  // the coal geometry's pose at s = 1
  };

  // Each shape's Body from `poses`; without `queried`, only its motion (poses, turn, moved,
  // fixed, valid: what the broad phase and hold_back read), not the twists, loaded and
  // pose1 that only the pair queries read (left as they were).
  void prepare(const StepPoses& poses, bool queried);
  // ... of shapes [lo, hi) (lo the first shape of a body), bodies_ sized
  void prepare(const StepPoses& poses, bool queried, int lo, int hi);
  // The broad phase's pairs into pairs_ (sorted by (a, b)), in its stages: `bound`, the
  // swept boxes of finite_[lo, hi); `finite_pairs`, the sweep's fat pairs [from, to)
  // (CoherentPairs::refit, test) that overlap, as shape pairs written over pairs_[from, ...)
  // but the skipped ones (returns how many), and the half-spaces' pairs with the boxes
  // [lo, hi) into `others`; `merge_pairs`, the meshes' pairs added to other_pairs_, then
  // other_pairs_ but the skipped ones merged into pairs_ (pairs_ holding only the finite
  // pairs). Boxes and fat pairs of different ranges may be done at once.
  void find_pairs();
  void bound(std::size_t lo, std::size_t hi);
  std::size_t finite_pairs(std::size_t from, std::size_t to, std::size_t lo, std::size_t hi,
                           std::vector<std::pair<int, int>>& others);
  void merge_pairs();
  // pairs of two fixed bodies, of a non-finite pose, of one body, or that the filter drops
  // (from sieve_)
  bool skip(const std::pair<int, int>& pair) const;
  // sieve_'s group and mask bits from the filter
  void sieve_filter();
  // detect's stages on two threads (see set_threads)
  void detect_paired(const StepPoses& poses, ContactRows& out);
  double sphere_gap(int a, int b) const;
  double relative_motion(int a, int b) const;
  double approach_bound(int a, int b) const;
  // m, the pair's margin: pairs closer than this are in contact (kRestingMargin)
  double pair_margin(int a, int b) const;
  double resting_floor(int a, int b) const;
  bool may_bounce(int a, int b, const Vec3& normal, double speed) const;
  void limit_pairs();
  void limit_rows(ContactRows& out);
  void group_by_bodies(ContactRows& out);
  void merge_mesh_faces(ContactRows& out);
  // Internal faces of overlapping static shapes (a box's end buried in the wall it meets):
  // a moving body's row with a static shape whose witness point on that shape lies inside
  // another static shape it also has a row with (and so does the body's point at its
  // previous pose, on the face's plane), the two rows' normals opposed (they would
  // push the body against each other), is dropped; the other shape's row stands for the
  // corner. So is such a row whose point on the body lay behind its face at the body's
  // previous pose (deeper than kDeepFraction of the body's thickness): the body reached that
  // face only through the other shape. When every such row of the body is buried, the
  // least buried one stays.
  void drop_buried_faces(ContactRows& out);
  // The shape of piece `piece` of body `body`; how deep (m) the point lies inside static
  // shape k (negative: outside; boxes and planes, -inf for other kinds)
  int shape_of(std::int64_t body, std::int32_t piece) const;
  double buried_depth(int k, const Vec3& point) const;
  // One thread's part of a step's pairs: its coal queries, scratch, the persistent
  // manifolds it found (for the store, in pair order) and, for the second, its rows.
  struct Lane {
    PairQuery query;
    PairQuery previous_query;   // deep_persistent: the previous state (query keeps its own)
    std::vector<PointPair> points;
    std::vector<Vec3> corners;                    // speculate: candidate corners
    std::vector<std::pair<double, int>> heights;  // speculate: (height, corner) kept
    std::vector<std::int64_t> row_codes;
    ManifoldStore next;
    std::size_t cursor[2] = {0, 0};   // its place in either part of stored_
    ContactRows rows;           // the second lane's rows (the first writes the step's)
    std::vector<std::pair<int, int>> others;   // detect_paired: its half-spaces' pairs
  };
  // The per-pair stages: each reads the step's bodies and the stored manifolds and
  // writes only `lane` and `out` (so two lanes run at once).
  // The pair's record of last step (`record`, in `store`, under `key`): its stored points
  // or its distance; false: the narrow phase's.
  bool reuse(Lane& lane, int a, int b, std::int64_t key, const ManifoldStore& store,
             const StoredManifold& record, ContactRows& out) const;
  // pairs_[lo, hi) in turn: the stored points or the narrow phase (the bounding spheres'
  // test first)
  void run_pairs(Lane& lane, std::size_t lo, std::size_t hi, ContactRows& out) const;
  // A pair stored apart (step 3) whose distance then, less how far either body moved
  // relative to the other since, is still beyond the margin and the step's relative motion:
  // the narrow phase would give it no rows (true; the record carried to the next step).
  bool still_apart(Lane& lane, std::int64_t key, int a, int b,
                   const StoredManifold& stored) const;
  // Pairs whose distance is worth storing: neither a sphere (coal's closed forms cost
  // about as much as the check), a plane or a mesh triangle.
  bool may_store_apart(int a, int b) const;
  // `relative`: relative_motion(a, b)
  void narrow_phase(Lane& lane, int a, int b, double relative, ContactRows& out) const;
  void classify(Lane& lane, int a, int b, double distance_now, const Vec3& normal_now,
                double relative, double speed, bool near, ContactRows& out) const;
  bool time_of_impact(Lane& lane, int a, int b, const Motion& ma, const Motion& mb, double s0,
                      double s1, ContactKind kind, double cap, bool only_if_fast,
                      ContactRows& out) const;
  bool tunnelled(Lane& lane, int a, int b, const Motion& ma, const Motion& mb,
                 double relative, ContactRows& out) const;
  void current_manifold(Lane& lane, int a, int b, ContactRows& out) const;
  // the deepest of `points` along `normal`, or null
  static const PointPair* deepest(const std::vector<PointPair>& points, const Vec3& normal);
  void speculate(Lane& lane, int a, int b, const Vec3& normal, const PointPair* plane,
                 bool skip_known, double toi, ContactKind kind, double reach, const Mat3& ra,
                 const Vec3& pa, const Mat3& rb, const Vec3& pb, ContactRows& out) const;
  // The previous state's contact carried along with each body, when that state is a
  // shallow touch; with `facing` (the current contact's normal), only when the carried
  // normal turned more than 60 deg from it (the bodies passed each other). False: no rows.
  bool deep_persistent(Lane& lane, int a, int b, double deep, double reach,
                       ContactRows& out, const Vec3* facing = nullptr) const;
  void emit(Lane& lane, int a, int b, const Vec3& normal, double toi, ContactKind kind,
            double cap, const Mat3& ra, const Vec3& pa, const Mat3& rb, const Vec3& pb,
            ContactRows& out) const;
  // The feature id of a row whose points are local_a, local_b in the two pieces' body
  // frames: both corner codes, their rank among the rows since lane.row_codes was
  // cleared, the piece pair (emit's, so a corner keeps its id from step to step)
  std::int64_t feature_of(Lane& lane, int a, int b, const Vec3& local_a,
                          const Vec3& local_b) const;
  Motion motion(int body) const;
  // m/s, bound on the speed of any point of B relative to A (current twists)
  double speed_bound(int a, int b) const;
  double radius_or_zero(int body) const;

  std::vector<BodyShape> shapes_;
  int bodies_count_ = 0;
  bool compound_ = false;      // some body has several shapes
  std::vector<bool> mesh_;     // per body: a triangle mesh
  struct Mesh {                // a triangle mesh's shapes [first, first + count), one body
    int first = 0, count = 0;
    BoxTree tree;              // their body-frame boxes
  };
  std::vector<Mesh> meshes_;   // out of the sort and sweep (broad_phase.h BoxTree)
  std::vector<Vec3> merge_points_;        // merge_mesh_faces: a normal's points
  std::vector<double> merge_separations_; // ... and their separations (m)
  std::vector<std::size_t> merge_rows_;   // merge_mesh_faces: their rows
  std::vector<int> merge_keep_;           // merge_mesh_faces: the kept ones
  ContactRows grouped_;        // scratch of group_by_bodies
  std::vector<int> planes_, finite_;
  std::vector<int> first_shape_;   // per body, its first shape
  std::vector<char> sides_;        // per body: 1 its shapes are all static, 2 none, 3 some
  std::vector<char> buried_;       // drop_buried_faces: per row, dropped
  std::vector<std::int64_t> static_of_;  // drop_buried_faces: per body, a static body it
  std::vector<char> several_;            // touches; whether it touches another too
  std::vector<std::pair<std::int64_t, std::size_t>> sided_;   // drop_buried_faces: the rows
                                         // of a moving and a static shape (moving body, row)
  struct StaticSide {   // drop_buried_faces: a row between a moving body and a static shape
    std::int64_t moving;
    int shape;
    std::size_t row;
    Vec3 witness, then;      // m, the row's point on the static shape, now and where the
                             // body's point was at its previous pose (on the face's plane)
    Vec3 outward;            // unit, out of the static shape
    double depth;            // m, how deep `witness` lies in an opposed row's shape
    bool behind;             // the body's point was behind the face at its previous pose
  };
  std::vector<StaticSide> buried_sides_;
  DetectionSettings settings_;
  PairFilter filter_;   // default: every pair collides
  std::vector<Body> bodies_;
  struct Sieve {   // per shape, what `skip` reads of it, side by side
    std::uint64_t group = 0, mask = 0;   // its body's collision filter bits (PairFilter)
    int body = 0;                        // its body
    bool fixed = false, valid = true;    // its Body's (prepare)
  };
  std::vector<Sieve> sieve_;
  std::vector<Aabb> boxes_;
  CoherentPairs sweep_;
  std::vector<std::pair<int, int>> pairs_;
  std::vector<std::pair<int, int>> other_pairs_;    // find_pairs: with half-spaces and meshes
  std::vector<std::pair<int, int>> merged_pairs_;   // find_pairs: scratch
  Lane lanes_[2];              // the caller's, the second half's (hold_back: the first)
  int threads_ = 1;            // of the next detect (set_threads)
  double pair_share_ = 0.5;    // detect_paired: the first part's share of the pairs
  std::unique_ptr<Worker> worker_;   // the second half's thread, started at its first use
  std::size_t last_rows_ = 0;  // rows of the last step (reserved for the next)
  double resting_ = 0.0;       // m, the step's margin of a pair at rest (pair_margin)
  ManifoldStore stored_[2];    // the last step's persistent manifolds: the first lane's,
                               // then the second's (its keys all greater; may be empty)
  StepBudget budget_;
  std::vector<double> depth_;        // budget: per pair or row, the ranking value
  std::vector<std::size_t> order_;   // budget: pairs or rows considered, by index
  std::vector<std::size_t> rank_;    // budget: positions in order_, ranked
  std::vector<std::pair<int, int>> kept_pairs_;
};

}  // namespace collres
