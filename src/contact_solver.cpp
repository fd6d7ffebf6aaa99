#include "contact_solver.h"

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstring>
#include <limits>

#include "sweep_waves.h"

namespace collres {
namespace {

constexpr double kTiny = 1e-12;
constexpr double kRegular = 1e-8;   // relative weight added to a block's diagonal
constexpr double kSlowest = 1e-9;   // m/s: a slower approach is no impact (rounding)

inline Vec3 lin(const double* v, int32_t i) { return load3(v + 6 * i); }
inline Vec3 ang(const double* v, int32_t i) { return load3(v + 6 * i + 3); }

// The twists of a row's two bodies, held while the rows of one manifold are solved: loaded
// once, updated in place, stored once (the same arithmetic as on the (N, 6) array).
struct Twists {
  Vec3 va, wa, vb, wb;   // m/s, rad/s: A's and B's linear and angular velocity
  Twists() = default;
  Twists(const double* v, int32_t a, int32_t b)
      : va(lin(v, a)), wa(ang(v, a)), vb(lin(v, b)), wb(ang(v, b)) {}
  void store(double* v, int32_t a, int32_t b) const {
    store3(v + 6 * a, va);
    store3(v + 6 * a + 3, wa);
    store3(v + 6 * b, vb);
    store3(v + 6 * b + 3, wb);
  }
  // the movable ones only (an immovable body's twist is unchanged: nothing to write, and a
  // body shared by the two threads of a sweep is never written)
  void store(double* v, int32_t a, int32_t b, const double* inv_mass) const {
    if (inv_mass[a] > 0.0) {
      store3(v + 6 * a, va);
      store3(v + 6 * a + 3, wa);
    }
    if (inv_mass[b] > 0.0) {
      store3(v + 6 * b, vb);
      store3(v + 6 * b + 3, wb);
    }
  }
};

// Velocity of B's point relative to A's, along d (index 0..2 = n, t1, t2).
inline double relative(const ContactRow& r, const Twists& t, int k, const Vec3& d) {
  return dot(t.vb - t.va, d) + dot(t.wb, r.ang_b[k]) - dot(t.wa, r.ang_a[k]);
}
inline double relative(const ContactRow& r, const double* v, int k, const Vec3& d) {
  return relative(r, Twists(v, r.a, r.b), k, d);
}

// Add impulse s along direction k (n, t1, t2) at the row's point: +s on B, -s on A.
inline void apply(const ContactRow& r, Twists& t, int k, const Vec3& d, double s) {
  t.va = t.va - (s * r.ma) * d;
  t.wa = t.wa - s * r.dw_a[k];
  t.vb = t.vb + (s * r.mb) * d;
  t.wb = t.wb + s * r.dw_b[k];
}
inline void apply(const ContactRow& r, double* v, int k, const Vec3& d, double s) {
  Twists t(v, r.a, r.b);
  apply(r, t, k, d, s);
  t.store(v, r.a, r.b);
}

inline Vec3 direction(const ContactRow& r, int k) { return k == 0 ? r.n : (k == 1 ? r.t1 : r.t2); }

// The friction impulse of row r (N s, along t1 and t2) that opposes its slip (x, y) (m/s;
// the classic tangent, v_t / |v_t|), as much as stops it along that direction, within
// mu * normal.
inline void friction_target(const ContactRow& r, double x, double y, double& tx, double& ty) {
  const double speed2 = x * x + y * y;
  const double stiffness = r.kt[0] * x * x + r.kt[1] * x * y + r.kt[2] * y * y;
  const double slip = speed2 / std::max(stiffness, kTiny * speed2 + 1e-300);
  tx = r.tangent[0] - x * slip;
  ty = r.tangent[1] - y * slip;
  const double size = norm2(tx, ty);
  const double limit = r.mu * r.normal;
  if (size > limit) {
    const double scale = size > 0.0 ? limit / size : 0.0;
    tx *= scale;
    ty *= scale;
  }
}

// Friction of a row after its normal update: friction_target() from the current twists.
// Returns the largest impulse change (N s).
double solve_friction(ContactRow& r, Twists& v) {
  // no load and no friction held: the cone is a point, nothing changes (a speculative row
  // that did not activate; in a settled pile at 30 Hz most rows)
  if (r.normal == 0.0 && r.tangent[0] == 0.0 && r.tangent[1] == 0.0) return 0.0;
  double x = relative(r, v, 1, r.t1), y = relative(r, v, 2, r.t2);
  double tx, ty;
  friction_target(r, x, y, tx, ty);
  double d_x = tx - r.tangent[0], d_y = ty - r.tangent[1];
  r.tangent[0] = tx;
  r.tangent[1] = ty;
  if (d_x != 0.0) apply(r, v, 1, r.t1, d_x);
  if (d_y != 0.0) apply(r, v, 2, r.t2, d_y);
  return std::max(std::fabs(d_x), std::fabs(d_y));
}

// Friction of a manifold of 2 to 4 rows after its normal update, whatever the order of its
// points (a mirror-symmetric hit gets mirror-symmetric friction): first each row's
// friction is brought into its cone (its normal may have shrunk), then every row proposes
// solve_friction's update from the same twists (oppose its own slip, within its cone), and
// the proposals are taken together, scaled by the s in [0, 1] that leaves the least
// kinetic energy along them (exact: it is quadratic in the impulses). Each row's new
// impulse lies between two points of its cone, so in it; the fixed points are
// solve_friction's (each row's friction opposes its slip or stops it). Returns the largest
// impulse change (N s).
double solve_friction_block(ContactRow* r, int k, Twists& v) {
  double change = 0.0;
  for (int i = 0; i < k; ++i) {   // into the cones
    const double size = norm2(r[i].tangent[0], r[i].tangent[1]);
    const double limit = r[i].mu * r[i].normal;
    if (!(size > limit)) continue;
    const double scale = limit / size;
    const double d_x = r[i].tangent[0] * scale - r[i].tangent[0];
    const double d_y = r[i].tangent[1] * scale - r[i].tangent[1];
    r[i].tangent[0] += d_x;
    r[i].tangent[1] += d_y;
    if (d_x != 0.0) apply(r[i], v, 1, r[i].t1, d_x);
    if (d_y != 0.0) apply(r[i], v, 2, r[i].t2, d_y);
    change = std::max({change, std::fabs(d_x), std::fabs(d_y)});
  }
  double d[4][2];
  double along = 0.0;   // slip . proposal (N m/s, < 0 unless nothing changes)
  Twists moved = v;
  for (int i = 0; i < k; ++i) {
    ContactRow& c = r[i];
    const double x = relative(c, v, 1, c.t1), y = relative(c, v, 2, c.t2);
    d[i][0] = d[i][1] = 0.0;
    // no load and no friction held: the cone is a point (solve_friction)
    if (c.normal == 0.0 && c.tangent[0] == 0.0 && c.tangent[1] == 0.0) continue;
    double tx, ty;
    friction_target(c, x, y, tx, ty);
    d[i][0] = tx - c.tangent[0];
    d[i][1] = ty - c.tangent[1];
    along += d[i][0] * x + d[i][1] * y;
    if (d[i][0] != 0.0) apply(c, moved, 1, c.t1, d[i][0]);
    if (d[i][1] != 0.0) apply(c, moved, 2, c.t2, d[i][1]);
  }
  if (!(along < 0.0)) return change;
  // the twists' change the proposals make, and the change of each row's slip
  Twists delta;
  delta.va = moved.va - v.va;
  delta.wa = moved.wa - v.wa;
  delta.vb = moved.vb - v.vb;
  delta.wb = moved.wb - v.wb;
  double curve = 0.0;   // proposal . K proposal (N^2 s / kg), > 0
  for (int i = 0; i < k; ++i)
    curve += d[i][0] * relative(r[i], delta, 1, r[i].t1) + d[i][1] * relative(r[i], delta, 2, r[i].t2);
  const double s = curve > -along ? -along / curve : 1.0;
  v.va = v.va + s * delta.va;
  v.wa = v.wa + s * delta.wa;
  v.vb = v.vb + s * delta.vb;
  v.wb = v.wb + s * delta.wb;
  for (int i = 0; i < k; ++i) {
    const double d_x = s * d[i][0], d_y = s * d[i][1];
    r[i].tangent[0] += d_x;
    r[i].tangent[1] += d_y;
    change = std::max({change, std::fabs(d_x), std::fabs(d_y)});
  }
  return change;
}

// Normal update of one row: approach no faster than the speculative allowance,
// accumulated impulse >= 0. Returns the impulse change (N s).
double solve_normal(ContactRow& r, Twists& v) {
  double v_n = relative(r, v, 0, r.n);
  double new_n = std::max(r.normal - r.normal_mass * (v_n + r.allowance), 0.0);
  double d_n = new_n - r.normal;
  r.normal = new_n;
  if (d_n != 0.0) apply(r, v, 0, r.n, d_n);
  return std::fabs(d_n);
}

// One update of a pair's rolling resistance and torsional friction (SpinRow): each part
// stops the relative angular velocity as far as its limit allows. Returns the change
// of angular impulse over the lever (N s).
double solve_spin(SpinRow& s, double* v, const double* inv_mass) {
  const double normal = s.load;
  if (normal == 0.0 && s.torque.x() == 0.0 && s.torque.y() == 0.0 && s.torque.z() == 0.0)
    return 0.0;   // no load, nothing held: both limits are 0 and nothing changes
  double* wa = v + 6 * s.a + 3;
  double* wb = v + 6 * s.b + 3;
  const Vec3 w = load3(wb) - load3(wa);
  const double spin = dot(w, s.n);
  // rolling: along minus the rolling velocity, as much as stops it, within roll * N
  const Vec3 rolling = w - spin * s.n;
  const double old_twist = dot(s.torque, s.n);
  const Vec3 old_roll = s.torque - old_twist * s.n;
  Vec3 roll = old_roll;
  const double speed2 = dot(rolling, rolling);
  const double k_roll = dot(rolling, mul(s.inv_ab, rolling));
  if (speed2 > 0.0 && k_roll > kTiny * speed2) roll = old_roll - (speed2 / k_roll) * rolling;
  const double roll_size = length(roll), roll_limit = s.roll * normal;
  if (roll_size > roll_limit) roll = (roll_limit / roll_size) * roll;
  // spin about the normal, within twist * N
  double twist = s.k_n > kTiny ? old_twist - spin / s.k_n : old_twist;
  twist = std::clamp(twist, -s.twist * normal, s.twist * normal);
  const Vec3 change = (roll - old_roll) + (twist - old_twist) * s.n;
  s.torque = roll + twist * s.n;
  if (change.x() == 0.0 && change.y() == 0.0 && change.z() == 0.0) return 0.0;
  if (inv_mass[s.a] > 0.0) store3(wa, load3(wa) - mul(s.inv_a, change));
  if (inv_mass[s.b] > 0.0) store3(wb, load3(wb) + mul(s.inv_b, change));
  return length(change) / s.lever;
}

// One Gauss-Seidel update of a row; returns the largest impulse change (N s).
double solve_row(ContactRow& r, Twists& v) {
  double d_n = solve_normal(r, v);
  return std::max(d_n, solve_friction(r, v));
}

// Sets a block's k accumulated normal impulses to max(x, 0) and applies the changes;
// returns the largest change (N s).
double take_block(ContactRow* r, int k, const double* x, Twists& v) {
  double change = 0.0;
  for (int i = 0; i < k; ++i) {
    double d = std::max(x[i], 0.0) - r[i].normal;
    r[i].normal += d;
    if (d != 0.0) apply(r[i], v, 0, r[i].n, d);
    change = std::max(change, std::fabs(d));
  }
  return change;
}

// The active sets of a block of k rows (bit i: row i active) in the order solve_block
// tries them: largest first, then by decreasing bits; sets[k][0 .. (1 << k) - 1].
struct ActiveSets {
  int sets[5][16];
  ActiveSets() {
    for (int k = 0; k <= 4; ++k) {
      int next = 0;
      for (int size = k; size >= 0; --size)
        for (int set = (1 << k) - 1; set >= 0; --set) {
          int bits = 0;
          for (int b = 0; b < k; ++b) bits += (set >> b) & 1;
          if (bits == size) sets[k][next++] = set;
        }
    }
  }
};
const ActiveSets kActiveSets;

// solve_coupled: solves of a block after the first at most (bench/mirror_scan.py's 42,700
// hits solve 1.62 M coupled blocks: 98.9 % at the first solve, 1.1 % after 1 to 16 more,
// 0.2 % find no answer within 17: a block that `search`es then searches every state,
// any other is solved split); the angle (rad) within which a sliding row's friction
// opposes its slip; a slip below kStill of the block's speeds is none (a row sliding at
// its cone's edge that barely slips: aimed anew, rounding in a slip of 1e-7 m/s turned its
// friction by 1e-9 rad, which grew x2.5 a Newton step)
constexpr int kCoupledTries = 16;
constexpr double kAimed = 1e-9;
constexpr double kStill = 1e-6;
// solve_coupled's search of every state: Newton steps per state at most; answers whose
// kinetic energies are this close (relative) give the same motion (rounding)
constexpr int kNewtonSteps = 8;
constexpr double kTie = 1e-9;
// ... and answers as good whose impulses are within this of the largest normal impulse
// are one answer reached from two states (a redundant block's rounding through its free
// directions: 1e-8), not a tie (a mirror image: up to 1 apart)
constexpr double kSame = 1e-7;
// A row whose friction is at its cone's limit, within rounding: it slides, its friction
// mu times its normal impulse along its slip (solve_friction_block keeps it there).
constexpr double kSlides = 1e-9;
inline bool sliding(const ContactRow& r) {
  return r.normal > 0.0 && norm2(r.tangent[0], r.tangent[1]) >= r.mu * r.normal * (1.0 - kSlides);
}

// solve_coupled's linear solve of m unknowns: s[0 .. m) the tableau [matrix | right-hand
// side], by Gauss-Jordan elimination with partial pivoting, the answer into x[0 .. m);
// false when a pivot vanishes (within 1e-9 of its column's diagonal)
template <int m>
inline bool gauss_jordan(double (&s)[12][13], double* x) {
  for (int c = 0; c < m; ++c) {
    int pivot = c;
    for (int i = c + 1; i < m; ++i)
      if (std::fabs(s[i][c]) > std::fabs(s[pivot][c])) pivot = i;
    if (!(std::fabs(s[pivot][c]) > 1e-9 * std::fabs(s[c][c]) + 1e-300)) return false;
    if (pivot != c)
      for (int j = 0; j <= m; ++j) std::swap(s[c][j], s[pivot][j]);
    for (int i = 0; i < m; ++i) {
      if (i == c) continue;
      const double f = s[i][c] / s[c][c];   // (column c, off the pivot: never read again)
      for (int j = c + 1; j <= m; ++j) s[i][j] -= f * s[c][j];
    }
  }
  for (int u = 0; u < m; ++u) x[u] = s[u][m] / s[u][u];
  return true;
}

// The whole block of a manifold with its friction (solve_block: a coupled block, every
// block of an impact stage, a manifold of a body with an impact this step and one with a
// point that slips as the step begins), as a few linear solves from the twists without the
// block's impulses. Unknowns: the normal impulse of each active row (no approach beyond its
// allowance) and the friction of those that stick (no slip). A sliding row's friction is
// mu times its normal along its aim (a unit direction in t1, t2): frozen (its column holds
// its friction's effect too), or after a Newton step, f - mu n aim + stiff P slip = 0 with
// aim against the last slip, P = 1 - aim aim^T and stiff = mu n / |slip| (N s per m/s),
// the exact linearisation of f = -mu n slip / |slip| there. The matrix's diagonal is
// heavier on the total impulses by a fraction kRegular of each unknown's own effect along
// its direction (the row's K_nn, K_t1t1 or K_t2t2, > 0): the least-norm answer of a
// redundant block (four points of a face: 12 rows on 6 motions), so a mirror-symmetric hit
// gets mirror-symmetric impulses. (Not a fraction of the column's diagonal: a frozen
// sliding row's holds its friction's effect too, K_nn + mu aim . K_nt, which can cancel
// K_nn or turn it negative. On a box struck sliding on four points of another, the normals
// leave one direction free, the mirror-antisymmetric one; weighted so, its regularisation
// nearly vanished, 1.9e-10 of the block's scale instead of 1e-8, and rounding of 1e-14 in
// the matrix parted the mirror points' normal impulses by 1e-5 of them.) After each
// solve: a row whose normal would pull lets go; a
// sticking row pushed beyond its cone slides along that friction; a sliding row whose
// friction does not oppose its slip (straight, within kAimed) is aimed against it (a
// Newton step, every sliding row of the block with it: a redundant block's rounding, 1e-9
// rad, turned one point of a mirror pair and not the other), unless its slip is below
// kStill of the block's speeds, or its friction runs along its slip and it was not pushed
// off its cone in this solve (it sticks); a row
// left out that approaches beyond its allowance takes part (sliding against its slip, or
// sticking); and the block is solved again (at most kCoupledTries + 1 solves). These moves
// can cycle (a box struck on a face by a wall, its two pairs of mirror points taking
// turns: one pair's friction beyond its cone, it slides, the other pair would pull and
// lets go, then approaches and takes part sliding, ... every sweep of its impact stage),
// or let every row go (a box on four points of a wall: one pair sliding, the other left
// out, and the sliding pair's frozen friction pulls its normals), or meet a vanishing
// pivot; then, in a block that `search`es (an impact stage's; in the resting sweeps one
// that is its movable bodies' only manifold), every state of the rows is searched (below).
// Why: the normal block for the friction held, then the friction block for those normals,
// each sweep, is an iteration whose mirror-antisymmetric part can grow: a sliding row's
// friction follows its normal, the two points' friction turns the body, the turn moves
// their normals apart (period two, x3.5 a sweep on a box sliding on two points 20 mm
// apart), and sticking rows taking over the load of sliding ones converge by 2 % a sweep;
// the answer depended on the sweep the solver stopped at. A sliding row's friction frozen
// at the direction it held does the same across sweeps (the friction update after the
// block turns it against the slip, the next solve freezes that: x16 a sweep on a box
// sliding on four points of a wall through an impact stage). Returns the largest impulse
// change (N s), or -1 when no row is active as the solve begins (a block holding no
// impulse) or a pivot vanishes in its first solve, or when the moves find no answer and no
// state holds (or two hold as well: below; or, without `search`, none is searched): the
// caller solves the normal block alone, then the friction block (the iteration above).
double solve_coupled(ContactRow* r, int k, Twists& v, bool search) {
  bool active[4], slides[4], pushed[4] = {};   // pushed: off its cone in this solve
  double aim[4][2];   // unit direction (t1, t2) of a sliding row's friction
  double stiff[4];    // N s per m/s: its friction's response to slip across aim (0: frozen)
  for (int i = 0; i < k; ++i) {
    active[i] = r[i].normal > 0.0;
    slides[i] = sliding(r[i]);
    const double size = norm2(r[i].tangent[0], r[i].tangent[1]);
    aim[i][0] = slides[i] ? r[i].tangent[0] / size : 0.0;
    aim[i][1] = slides[i] ? r[i].tangent[1] / size : 0.0;
    stiff[i] = 0.0;
  }
  // the twists without the block's impulses
  Twists free = v;
  for (int i = 0; i < k; ++i)
    for (int b = 0; b < 3; ++b) {
      const double held = b == 0 ? r[i].normal : r[i].tangent[b - 1];
      if (held != 0.0) apply(r[i], free, b, direction(r[i], b), -held);
    }
  // m/s: each row's velocity along n, t1, t2 without the block's impulses (what every
  // solve's right-hand side reads), and the block's speeds: a slip below kStill of it is none
  double speed[4][3];
  double scale = 0.0;
  for (int i = 0; i < k; ++i)
    for (int b = 0; b < 3; ++b) {
      speed[i][b] = relative(r[i], free, b, direction(r[i], b));
      scale = std::max(scale, std::fabs(speed[i][b]));
    }
  // impulse along row j's direction b moves row i's velocity along its direction a by
  // (each computed once, when first needed: the solves after the first reuse them)
  double effects[12][12];
  bool known[12][12] = {};
  auto effect = [&](int i, int a, int j, int b) {
    const int p = 3 * i + a, q = 3 * j + b;
    if (!known[p][q]) {
      effects[p][q] = (r[j].ma + r[j].mb) * dot(direction(r[i], a), direction(r[j], b)) +
                      dot(r[i].ang_a[a], r[j].dw_a[b]) + dot(r[i].ang_b[a], r[j].dw_b[b]);
      known[p][q] = true;
    }
    return effects[p][q];
  };
  // the block's answer for the rows' state (active, slides, aim, stiff) into n, t; false
  // when no row is active or a pivot vanishes
  double n[4] = {}, t[4][2] = {};
  auto solve_state = [&]() -> bool {
    // unknown u: row[u]'s impulse along dir[u] (0 n, 1 t1, 2 t2); a sliding row with a
    // frozen aim has its normal only (its friction is mu times it along aim)
    int row[12], dir[12], m = 0;
    bool frozen[12];   // unknown c a frozen sliding row's normal (its column holds its friction)
    for (int i = 0; i < k; ++i) {
      if (!active[i]) continue;
      frozen[m] = slides[i] && stiff[i] == 0.0;
      row[m] = i, dir[m++] = 0;
      if (frozen[m - 1]) continue;
      frozen[m] = false, row[m] = i, dir[m++] = 1;
      frozen[m] = false, row[m] = i, dir[m++] = 2;
    }
    if (m == 0) return false;
    // e[a][c]: row i's velocity along its direction a per unit of unknown c
    auto column = [&](int i, int a, int c) {
      const int j = row[c];
      double e = effect(i, a, j, dir[c]);
      if (frozen[c])
        e += r[j].mu * (aim[j][0] * effect(i, a, j, 1) + aim[j][1] * effect(i, a, j, 2));
      return e;
    };
    double s[12][13];
    for (int u = 0; u < m; ++u) {
      const int i = row[u];
      const ContactRow& ru = r[i];
      if (dir[u] == 0 || !slides[i]) {   // no approach beyond the allowance; no slip
        for (int c = 0; c < m; ++c) s[u][c] = column(i, dir[u], c);
        s[u][u] += kRegular * effect(i, dir[u], i, dir[u]);
        s[u][m] = -(speed[i][dir[u]] + (dir[u] == 0 ? ru.allowance : 0.0));
        continue;
      }
      // a sliding row's friction, linearised about the slip of the last try (Newton):
      // f - mu n aim + stiff P slip = 0, P = 1 - aim aim^T the part across aim; its two
      // equations (u along t1, u + 1 along t2) from the same columns (its normal: u - 1)
      const double p[2][2] = {{1.0 - aim[i][0] * aim[i][0], 0.0 - aim[i][0] * aim[i][1]},
                              {0.0 - aim[i][1] * aim[i][0], 1.0 - aim[i][1] * aim[i][1]}};
      for (int c = 0; c < m; ++c) {
        const double c1 = column(i, 1, c), c2 = column(i, 2, c);
        for (int a = 0; a < 2; ++a) s[u + a][c] = stiff[i] * (p[a][0] * c1 + p[a][1] * c2);
      }
      for (int a = 0; a < 2; ++a) {
        s[u + a][u + a] = s[u + a][u + a] * (1.0 + kRegular) + 1.0;
        s[u + a][u - 1] -= ru.mu * aim[i][a];
        s[u + a][m] = -stiff[i] * (p[a][0] * speed[i][1] + p[a][1] * speed[i][2]);
      }
      ++u;   // (u + 1: done)
    }
    double x[12];
    bool solved;
    switch (m) {   // (m a constant: the elimination's loops unrolled)
      case 1: solved = gauss_jordan<1>(s, x); break;
      case 2: solved = gauss_jordan<2>(s, x); break;
      case 3: solved = gauss_jordan<3>(s, x); break;
      case 4: solved = gauss_jordan<4>(s, x); break;
      case 5: solved = gauss_jordan<5>(s, x); break;
      case 6: solved = gauss_jordan<6>(s, x); break;
      case 7: solved = gauss_jordan<7>(s, x); break;
      case 8: solved = gauss_jordan<8>(s, x); break;
      case 9: solved = gauss_jordan<9>(s, x); break;
      case 10: solved = gauss_jordan<10>(s, x); break;
      case 11: solved = gauss_jordan<11>(s, x); break;
      default: solved = gauss_jordan<12>(s, x); break;
    }
    if (!solved) return false;
    for (int i = 0; i < k; ++i) n[i] = t[i][0] = t[i][1] = 0.0;
    for (int u = 0; u < m; ++u) {
      if (dir[u] == 0) n[row[u]] = x[u];
      else t[row[u]][dir[u] - 1] = x[u];
    }
    for (int i = 0; i < k; ++i)
      if (active[i] && slides[i] && stiff[i] == 0.0) {   // frozen: mu n along its aim
        t[i][0] = r[i].mu * aim[i][0] * n[i];
        t[i][1] = r[i].mu * aim[i][1] * n[i];
      }
    return true;
  };
  // the twists with the answer's impulses
  Twists after;
  auto move = [&]() {
    after = free;
    for (int i = 0; i < k; ++i) {
      if (!active[i]) continue;
      const double d[3] = {n[i], t[i][0], t[i][1]};
      for (int b = 0; b < 3; ++b)
        if (d[b] != 0.0) apply(r[i], after, b, direction(r[i], b), d[b]);
    }
  };
  // the answer taken: the rows' impulses and the twists; the largest impulse change
  auto take = [&]() {
    double change = 0.0;
    for (int i = 0; i < k; ++i) {
      change = std::max({change, std::fabs(n[i] - r[i].normal),
                         std::fabs(t[i][0] - r[i].tangent[0]),
                         std::fabs(t[i][1] - r[i].tangent[1])});
      r[i].normal = n[i];
      r[i].tangent[0] = t[i][0];
      r[i].tangent[1] = t[i][1];
    }
    v = after;
    return change;
  };
  // a Newton step: every sliding row of the block aimed against its slip (the rows alike,
  // so that rounding below kAimed in one row and above it in its mirror image does not turn
  // one alone), its friction's response to slip across the aim from its normal impulse; a
  // slip below kStill of the block's speeds is none (left as it is)
  auto aim_sliding = [&]() {
    for (int i = 0; i < k; ++i) {
      if (!active[i] || !slides[i]) continue;
      const double x = relative(r[i], after, 1, r[i].t1), y = relative(r[i], after, 2, r[i].t2);
      const double speed = norm2(x, y);
      if (!(speed > kStill * scale)) continue;
      pushed[i] = false;   // aimed anew: should its slip then run along it, it sticks
      aim[i][0] = -x / speed;
      aim[i][1] = -y / speed;
      stiff[i] = r[i].mu * n[i] / speed;
    }
  };
  for (int tries = 0; tries <= kCoupledTries; ++tries) {
    if (!solve_state()) {   // no row active, or a pivot vanished
      if (tries == 0) return -1.0;
      break;
    }
    bool again = false;
    for (int i = 0; i < k; ++i) {
      if (!active[i]) continue;
      if (!(n[i] >= 0.0)) {   // it would pull: it lets go
        active[i] = false;
        again = true;
        continue;
      }
      if (slides[i]) continue;
      const double size = norm2(t[i][0], t[i][1]);
      if (!(size <= r[i].mu * n[i])) {   // beyond its cone: it slides, along that friction
        slides[i] = true;
        pushed[i] = true;
        aim[i][0] = t[i][0] / size;
        aim[i][1] = t[i][1] / size;
        stiff[i] = 0.0;
        again = true;
      }
    }
    if (again) continue;
    move();
    // a sliding row whose friction runs along its slip sticks, unless it was pushed off its
    // cone in this solve; where one does not oppose its slip straight, every sliding row
    // takes a Newton step (aim_sliding)
    bool turn = false;
    for (int i = 0; i < k; ++i) {
      if (!active[i] || !slides[i]) continue;
      const double x = relative(r[i], after, 1, r[i].t1), y = relative(r[i], after, 2, r[i].t2);
      const double speed = norm2(x, y);
      const bool along = aim[i][0] * x + aim[i][1] * y > 0.0;
      if (along && !pushed[i]) {
        slides[i] = false;
        again = true;
      } else if (speed > kStill * scale &&
                 (along || std::fabs(aim[i][0] * y - aim[i][1] * x) > kAimed * speed)) {
        turn = true;
      }
    }
    if (turn) {
      aim_sliding();
      again = true;
    }
    if (again) continue;
    for (int i = 0; i < k; ++i) {
      if (active[i] || !(relative(r[i], after, 0, r[i].n) + r[i].allowance < 0.0)) continue;
      // it takes part: sliding against its slip, or sticking when it does not slip
      const double x = relative(r[i], after, 1, r[i].t1), y = relative(r[i], after, 2, r[i].t2);
      const double speed = norm2(x, y);
      active[i] = again = true;
      slides[i] = pushed[i] = speed > kStill * scale;
      aim[i][0] = slides[i] ? -x / speed : 0.0;
      aim[i][1] = slides[i] ? -y / speed : 0.0;
      stiff[i] = 0.0;
    }
    if (again) continue;
    return take();
  }
  // no answer from the state the block held (its moves between states cycled, let every
  // row go, or met a vanishing pivot): every
  // state, each row left out (0), sticking (1), sliding (2) or at its cone's edge (3), and
  // of the answers that hold the one that leaves the block's bodies the least kinetic
  // energy, of those within kTie of it the one of least impulses (their squares weighted
  // by the diagonal, as kRegular weighs them: the one solve's least-norm answer). Coulomb
  // friction on a redundant block can have several answers: a box struck on a face by a
  // wall whose two mirror points can each carry it alone, or both (the most dissipative),
  // or a box on a box through four points, whose states give the same motion with other
  // impulses (the least, as kRegular picks in one solve). Neither choice depends on the
  // rows' order: a mirror-symmetric hit gets mirror-symmetric impulses; where another
  // answer is as good (its energy and impulses within kTie of the best's, its impulses
  // more than kSame of the largest apart: the best's mirror image, one point of a pair
  // carrying a box alone where both together do not hold) the choice would, and none is
  // taken (-1); one within kSame is the same answer reached from another state (a
  // redundant block's rounding). A sliding row starts against its slip without the
  // block's impulses (no slip then: not this state). A row at its cone's edge is one
  // that the block's all-sticking answer pushes beyond its cone (only such a row has that
  // state): it starts sliding along that friction, mu times its normal impulse, and holds
  // there where its slip vanishes (the block sticks as a whole, its other rows taking the
  // rest of the load): a box struck on a face by a wall at 240 Hz, whose all-sticking
  // answer pushed both pairs beyond their cones in opposite directions, all four sliding
  // turned the slip over each Newton step, and only the one pair held at its edge against
  // the other pair's sticking holds. While a sliding row does not oppose its slip straight
  // (within kAimed; a slip below kStill of the block's speeds is none), every sliding row
  // takes a Newton step, kNewtonSteps at most. An answer holds where no active row pulls,
  // no sticking row is beyond its cone, every sliding row's friction opposes its slip and
  // no row left out approaches beyond its allowance.
  if (!search) return -1.0;
  bool found = false;
  bool tied = false;    // another answer as good as the best
  double least = 0.0;   // J: the kinetic energy the best answer adds (< 0: takes)
  double smallest = 0.0;   // J: its impulses' squares, each times its row's own effect
  double best_n[4], best_t[4][2];
  Twists best_after;
  // the rows the all-sticking answer pushes beyond their cones, and that friction's
  // direction (unit, t1 and t2): their edge
  int kinds[4];   // each row's states: 4 with an edge, else 3
  double edge[4][2];
  for (int i = 0; i < k; ++i) {
    active[i] = true;
    slides[i] = false;
    stiff[i] = 0.0;
  }
  const bool sticks = solve_state();
  int states = 1;
  for (int i = 0; i < k; ++i) {
    const double size = sticks ? norm2(t[i][0], t[i][1]) : 0.0;
    kinds[i] = size > 0.0 && !(size <= r[i].mu * n[i]) ? 4 : 3;
    edge[i][0] = kinds[i] == 4 ? t[i][0] / size : 0.0;
    edge[i][1] = kinds[i] == 4 ? t[i][1] / size : 0.0;
    states *= kinds[i];
  }
  for (int state = 1; state < states; ++state) {
    bool holds = true;
    for (int i = 0, code = state; i < k; code /= kinds[i], ++i) {
      const int kind = code % kinds[i];
      active[i] = kind != 0;
      slides[i] = kind >= 2;
      stiff[i] = 0.0;
      if (kind == 3) {
        aim[i][0] = edge[i][0];
        aim[i][1] = edge[i][1];
        continue;
      }
      const double speed_t = norm2(speed[i][1], speed[i][2]);
      holds = holds && (!slides[i] || speed_t > 0.0);
      aim[i][0] = slides[i] && speed_t > 0.0 ? -speed[i][1] / speed_t : 0.0;
      aim[i][1] = slides[i] && speed_t > 0.0 ? -speed[i][2] / speed_t : 0.0;
    }
    for (int step = 0; holds && step <= kNewtonSteps; ++step) {
      if (!solve_state()) {
        holds = false;
        break;
      }
      for (int i = 0; i < k && holds; ++i)
        holds = !active[i] || (n[i] >= 0.0 && (slides[i] ||
                                               norm2(t[i][0], t[i][1]) <= r[i].mu * n[i]));
      if (!holds) break;
      move();
      bool aimed = true;
      for (int i = 0; i < k; ++i) {
        if (!active[i] || !slides[i]) continue;
        const double x = relative(r[i], after, 1, r[i].t1), y = relative(r[i], after, 2, r[i].t2);
        const double speed = norm2(x, y);
        aimed = aimed && (!(speed > kStill * scale) ||
                          (aim[i][0] * x + aim[i][1] * y < 0.0 &&
                           std::fabs(aim[i][0] * y - aim[i][1] * x) <= kAimed * speed));
      }
      if (!aimed) {
        aim_sliding();
        holds = step < kNewtonSteps;
        continue;
      }
      for (int i = 0; i < k && holds; ++i)
        holds = active[i] || relative(r[i], after, 0, r[i].n) + r[i].allowance >= 0.0;
      if (!holds) break;
      // the kinetic energy its impulses add: each impulse times its row's mean velocity
      // along it, before and after
      double added = 0.0;
      for (int i = 0; i < k; ++i) {
        if (!active[i]) continue;
        const double d[3] = {n[i], t[i][0], t[i][1]};
        for (int b = 0; b < 3; ++b)
          added += 0.5 * d[b] * (speed[i][b] + relative(r[i], after, b, direction(r[i], b)));
      }
      double size = 0.0;
      for (int i = 0; i < k; ++i) {
        if (!active[i]) continue;
        const double d[3] = {n[i], t[i][0], t[i][1]};
        for (int b = 0; b < 3; ++b) size += effect(i, b, i, b) * d[b] * d[b];
      }
      const double tie = kTie * std::max(std::fabs(added), std::fabs(least));
      if (found && std::fabs(added - least) <= tie &&
          std::fabs(size - smallest) <= kTie * std::max(size, smallest)) {
        double apart = 0.0, largest = 0.0;   // N s
        for (int i = 0; i < k; ++i) {
          apart = std::max({apart, std::fabs(n[i] - best_n[i]), std::fabs(t[i][0] - best_t[i][0]),
                            std::fabs(t[i][1] - best_t[i][1])});
          largest = std::max({largest, n[i], best_n[i]});
        }
        tied = tied || apart > kSame * largest;
      } else if (!found || added < least - tie || (added <= least + tie && size < smallest)) {
        found = true;
        tied = false;
        least = added;
        smallest = size;
        std::copy(&n[0], &n[0] + 4, best_n);
        std::copy(&t[0][0], &t[0][0] + 8, &best_t[0][0]);
        best_after = after;
      }
      break;
    }
  }
  if (!found || tied) return -1.0;
  std::copy(best_n, best_n + 4, n);
  std::copy(&best_t[0][0], &best_t[0][0] + 8, &t[0][0]);
  after = best_after;
  return take();
}

// solve_block's test of an active set `set` of m rows (bit i: row i of the block's k;
// idx[0 .. m): its rows in order): x (k) of A_SS x_S = -q_S by Gaussian elimination with
// partial pivoting, 0 off S; whether x >= 0 on S and w = A x + q >= 0 off S
template <int m>
inline __attribute__((always_inline)) bool fits_set(const double (&a)[4][4], const double* q,
                                                    int k, int set, const int* idx,
                                                    double* x) {
  double s[m + 1][m + 1];
  for (int i = 0; i < m; ++i) {
    for (int j = 0; j < m; ++j) s[i][j] = a[idx[i]][idx[j]];
    s[i][m] = -q[idx[i]];
  }
  for (int c = 0; c < m; ++c) {
    int pivot = c;
    for (int i = c + 1; i < m; ++i)
      if (std::fabs(s[i][c]) > std::fabs(s[pivot][c])) pivot = i;
    if (std::fabs(s[pivot][c]) <= 1e-9 * std::fabs(a[idx[c]][idx[c]]) + 1e-300) return false;
    if (pivot != c)
      for (int j = 0; j <= m; ++j) std::swap(s[c][j], s[pivot][j]);
    for (int i = 0; i < m; ++i) {
      if (i == c) continue;
      double f = s[i][c] / s[c][c];   // (column c, off the pivot: never read again)
      for (int j = c + 1; j <= m; ++j) s[i][j] -= f * s[c][j];
    }
  }
  for (int i = 0; i < k; ++i) x[i] = 0.0;
  for (int i = 0; i < m; ++i) {
    x[idx[i]] = s[i][m] / s[i][i];
    if (!(x[idx[i]] >= -1e-12 * (1.0 + std::fabs(x[idx[i]])))) return false;
  }
  for (int i = 0; i < k; ++i) {
    if (set & (1 << i)) continue;
    double w = q[i];
    for (int j = 0; j < k; ++j) w += a[i][j] * x[j];
    if (!(w >= -1e-12 * (1.0 + std::fabs(q[i])))) return false;
  }
  return true;
}

// The normal rows of one manifold (2..4 points of a pair) solved together, exactly: the
// small LCP  w = A x + q >= 0, x >= 0, x.w = 0  (A the rows' Delassus matrix, x the new
// accumulated impulses) by trying the active sets (the rows that carry impulse now first,
// then largest first), as Box2D's block solver does for two points. Gauss-Seidel converges slowly on a nearly singular
// manifold (close points, small lever arms) and leaves it spinning. Returns the largest
// impulse change, or -1 when no active set fits (the caller falls back to rows).
// A `coupled` block: the whole block with its friction (solve_coupled) first.
// `searched`: the block's q (below) as a wide group's lane found it, the lane's solve having
// found no answer (solve_groups): the block is not idle and, invertible and not coupled, its
// all-active answer and the set of the rows carrying impulse did not fit (two rows: no set
// did); the search goes on from there, the same sets in the same order. Null: none tried.
double solve_block(ContactRow* r, const Manifold& block, Twists& v, const double* searched) {
  const int k = block.count;
  if (block.coupled) {
    const double step = solve_coupled(r, k, v, block.search);
    if (step >= 0.0) return step;
  }
  const bool lanes_tried = searched != nullptr && block.invertible && !block.coupled;
  if (lanes_tried && k == 2) return -1.0;
  const BlockMatrices& m = *block.matrices;
  const double (&a)[4][4] = m.delassus;
  double q[4], x[4];
  if (searched != nullptr) {
    for (int i = 0; i < k; ++i) q[i] = searched[i];
  } else {
    bool idle = true;
    for (int i = 0; i < k; ++i) {
      double b = relative(r[i], v, 0, r[i].n) + r[i].allowance;
      q[i] = b;
      for (int j = 0; j < k; ++j) q[i] -= m.plain[i][j] * r[j].normal;
      idle = idle && r[i].normal == 0.0 && q[i] >= 0.0;
    }
    // no impulse and no row approaching beyond its allowance: x = 0 is the answer (the only
    // one: A is positive definite), and nothing changes; the active-set search would try
    // every set before the empty one (a speculative manifold that did not activate: most
    // blocks of a settled pile at 30 Hz)
    if (idle) return 0.0;
  }
  // every row active: the least-norm answer (prepare_block's inverse), when the block has
  // one and (a block with a free direction) it leaves no row approaching along the free
  // direction beyond rounding
  if (block.invertible && !lanes_tried) {
    bool ok = true;
    for (int i = 0; i < k; ++i) {
      x[i] = 0.0;
      for (int j = 0; j < k; ++j) x[i] -= m.inverse[i][j] * q[j];
      ok = ok && x[i] >= -1e-12 * (1.0 + std::fabs(x[i]));
    }
    if (ok && block.redundant) {
      double loose = 0.0, largest = 0.0;   // m/s: the largest approach left, the largest |q|
      for (int i = 0; i < k; ++i) {
        loose += m.residual[i] * q[i];
        largest = std::max(largest, std::fabs(q[i]));
      }
      ok = std::fabs(loose) <= 1e-12 * (1.0 + largest);
    }
    if (ok) return take_block(r, k, x, v);
  }
  // x for the active set `set` (bit i: row i active): A_SS x_S = -q_S by Gaussian
  // elimination with partial pivoting, x >= 0 on S and w >= 0 off S; false otherwise
  auto fits = [&](int set) {
    int idx[4], m = 0;
    for (int i = 0; i < k; ++i)
      if (set & (1 << i)) idx[m++] = i;
    switch (m) {   // (the set's size a constant: its elimination unrolled)
      case 0: return fits_set<0>(a, q, k, set, idx, x);
      case 1: return fits_set<1>(a, q, k, set, idx, x);
      case 2: return fits_set<2>(a, q, k, set, idx, x);
      case 3: return fits_set<3>(a, q, k, set, idx, x);
      default: return fits_set<4>(a, q, k, set, idx, x);
    }
  };
  // first the rows that carry impulse now (warm: usually still the answer), then every
  // set, largest first
  int carrying = 0;
  for (int i = 0; i < k; ++i) carrying |= r[i].normal > 0.0 ? 1 << i : 0;
  const bool tried = lanes_tried || (block.invertible && carrying == (1 << k) - 1);
  if (!tried && fits(carrying)) return take_block(r, k, x, v);
  for (int order = block.invertible ? 1 : 0; order < (1 << k); ++order) {
    const int set = kActiveSets.sets[k][order];
    if (set == carrying) continue;
    if (fits(set)) return take_block(r, k, x, v);
  }
  return -1.0;
}

}  // namespace

namespace {

// prepare_block() of a block of k rows (k a constant: every loop unrolled, the
// eliminations' tableaux in registers); k 1 (no inverse) to 4
template <int k>
inline __attribute__((always_inline)) void prepare_block_of(Manifold& block,
                                                            BlockMatrices& m,
                                                            const ContactRow* r) {
  for (int i = 0; i < k; ++i) {
    for (int j = 0; j < k; ++j) {
      m.plain[i][j] = (r[i].ma + r[i].mb) * dot(r[i].n, r[j].n) +
                      dot(r[i].ang_a[0], r[j].dw_a[0]) + dot(r[i].ang_b[0], r[j].dw_b[0]);
      m.delassus[i][j] = m.plain[i][j];
    }
    // ill-conditioned blocks (coincident points, four points of a face: rank 3) have many
    // impulse sets that give the same velocities; a diagonal a fraction kRegular heavier
    // (on the total impulses, not their change) picks the one of least norm: coincident
    // points share equally, a symmetric hit gets symmetric impulses, no pivot is near zero
    // (the active-set search's matrix; the all-active answer's: below)
    m.delassus[i][i] *= 1.0 + kRegular;
    m.residual[i] = 0.0;
  }
  block.invertible = block.redundant = false;
  if (k < 2) return;
  // The all-active answer x = -inverse q, the least-norm one (impulses weighted by their
  // rows' own effects, as kRegular weighs them). In units of the rows' own effects
  // (e = S A S, S = diag(1 / sqrt(A_ii)): a unit diagonal), a direction along which the
  // block moves its rows by less than kRegular (the regularisation's weight) is free: its
  // impulses move nothing (four points of one face: 4 normal impulses on 3 motions). The
  // regularised matrix's inverse had entries 1 / kRegular times the answer along it, and
  // rounding in their row-ordered sums (1e-16 of q) became impulses 1e-8 of the answer
  // apart along it (a mirror-symmetric hit's mirror points' normals, which the sliding
  // rows' frozen solves then amplified to 1e-6). So the free direction z (unit, in e's
  // units) is left out: inverse = S P E P S, P = 1 - z z^T, E the inverse of e on the other
  // directions (e's pseudo-inverse: entries of the answer's size). The answer's rows then
  // approach along z by (z_i / s_i) (z . S q) (m/s: what no impulse of the block changes);
  // `residual` holds z_j s_j times the largest |z_i / s_i|, so |residual . q| is the
  // largest of them. Two free directions or more (four points on a line): no inverse (the
  // active-set search solves the block).
  double s[k];
  for (int i = 0; i < k; ++i) {
    if (!(m.plain[i][i] > 0.0)) return;
    s[i] = 1.0 / std::sqrt(m.plain[i][i]);
  }
  // Gauss-Jordan elimination of [e | 1], each pivot the largest diagonal left (symmetric
  // pivoting: order[c] the unknown in place c; e is symmetric, positive semi-definite).
  // The pivot of place c is y^T e y for y its column's multiples (-u) and 1 there: where it
  // is within kRegular of y . y, y is free (the last place: else no inverse), and the
  // pivots before it give E (its own row and column 0). The right half's columns are in
  // place order too: before place c its columns from c on are still the identity's, so
  // row c's right half is zero beyond c, and a row's update skips those columns (each
  // would subtract a zero: the same bits); a column of e, once its place is eliminated,
  // is never read again and is left as it is.
  double t[k][2 * k];
  int order[k];
  for (int i = 0; i < k; ++i) {
    order[i] = i;
    for (int j = 0; j < k; ++j) {
      t[i][j] = s[i] * m.plain[i][j] * s[j];
      t[i][k + j] = i == j ? 1.0 : 0.0;
    }
  }
  int free = -1;   // the place of the free direction (the last), -1: none
  for (int c = 0; c < k; ++c) {
    int pivot = c;
    for (int i = c + 1; i < k; ++i)
      if (t[i][i] > t[pivot][pivot]) pivot = i;
    if (pivot != c) {   // (the right half's columns c and pivot: swapped back to the identity)
      for (int j = c; j < k + c; ++j) std::swap(t[c][j], t[pivot][j]);
      for (int i = 0; i < k; ++i) std::swap(t[i][c], t[i][pivot]);
      std::swap(order[c], order[pivot]);
    }
    double size = 1.0;   // y . y
    for (int i = 0; i < c; ++i) size += (t[i][c] / t[i][i]) * (t[i][c] / t[i][i]);
    if (!(t[c][c] > kRegular * size)) {
      if (c < k - 1) return;
      free = c;
      break;
    }
    for (int i = 0; i < k; ++i) {
      if (i == c) continue;
      const double f = t[i][c] / t[c][c];
      for (int j = c + 1; j <= k + c; ++j) t[i][j] -= f * t[c][j];
    }
  }
  if (free < 0) {   // no free direction: inverse = S E S
    for (int c = 0; c < k; ++c)
      for (int p = 0; p < k; ++p)
        m.inverse[order[c]][order[p]] =
            s[order[c]] * (t[c][k + p] / t[c][c]) * s[order[p]];
    block.invertible = true;
    return;
  }
  block.redundant = true;
  double z[k] = {};   // the free direction, unit
  double inverse[k][k];   // E
  for (int c = 0; c < k; ++c)
    for (int p = 0; p < k; ++p)
      inverse[order[c]][order[p]] = c == free ? 0.0 : t[c][k + p] / t[c][c];
  {
    double size = 1.0;
    z[order[free]] = 1.0;
    for (int c = 0; c < free; ++c) {
      z[order[c]] = -t[c][free] / t[c][c];
      size += z[order[c]] * z[order[c]];
    }
    size = std::sqrt(size);
    for (int i = 0; i < k; ++i) z[i] /= size;
  }
  // P E P = E - h z^T - z h^T + (z . h) z z^T, h = E z
  double h[k], zh = 0.0;
  for (int i = 0; i < k; ++i) {
    h[i] = 0.0;
    for (int j = 0; j < k; ++j) h[i] += inverse[i][j] * z[j];
    zh += z[i] * h[i];
  }
  double reach = 0.0;   // the largest |z_i / s_i|
  for (int i = 0; i < k; ++i) {
    reach = std::max(reach, std::fabs(z[i] / s[i]));
    for (int j = 0; j < k; ++j)
      m.inverse[i][j] =
          s[i] * (inverse[i][j] - h[i] * z[j] - z[i] * h[j] + zh * z[i] * z[j]) * s[j];
  }
  for (int i = 0; i < k; ++i) m.residual[i] = z[i] * s[i] * reach;
  block.invertible = true;
}

}  // namespace

COLLRES_CLONED
void prepare_block(Manifold& block, const ContactRow* r, BlockMatrices& matrices) {
  block.matrices = &matrices;
  switch (block.count) {
    case 1: prepare_block_of<1>(block, matrices, r); break;
    case 2: prepare_block_of<2>(block, matrices, r); break;
    case 3: prepare_block_of<3>(block, matrices, r); break;
    case 4: prepare_block_of<4>(block, matrices, r); break;
    default: block.invertible = block.redundant = false; break;   // (more rows: row by row)
  }
}

void row_velocity(const ContactRow& row, const double* v, double out[3]) {
  const Twists t(v, row.a, row.b);   // (loaded once: out may alias v for the compiler)
  for (int k = 0; k < 3; ++k) out[k] = relative(row, t, k, direction(row, k));
}

void frame_row(ContactRow& row, const SolverBodies& bodies, const ContactRow* framed) {
  if (framed != nullptr && std::memcmp(framed->n.data(), row.n.data(), sizeof(double) * 3) == 0) {
    row.t1 = framed->t1;
    row.t2 = framed->t2;
  } else {
    tangent_basis(row.n, row.t1, row.t2);
  }
  row.ma = bodies.inv_mass[row.a];
  row.mb = bodies.inv_mass[row.b];
  const Mat3& ia = bodies.inv_inertia[row.a];
  const Mat3& ib = bodies.inv_inertia[row.b];
  // the three directions d = n, t1, t2 side by side, lane k direction k (lane 3 idle):
  // each lane takes the IEEE operations of cross(r, d), mul(I^-1, .) and dot, in their
  // order, for its direction (the bits of one direction at a time)
  auto splat = [](double x) { return Lanes{x, x, x, x}; };
  const Lanes d[3] = {Lanes{row.n.x(), row.t1.x(), row.t2.x(), 0.0},
                      Lanes{row.n.y(), row.t1.y(), row.t2.y(), 0.0},
                      Lanes{row.n.z(), row.t1.z(), row.t2.z(), 0.0}};
  auto cross_all = [&](const Vec3& r, Lanes out[3]) {   // r x d, x y z
    out[0] = splat(r.y()) * d[2] - splat(r.z()) * d[1];
    out[1] = splat(r.z()) * d[0] - splat(r.x()) * d[2];
    out[2] = splat(r.x()) * d[1] - splat(r.y()) * d[0];
  };
  auto mul_all = [&](const Mat3& m, const Lanes v[3], Lanes out[3]) {   // m v, row by row
    for (int i = 0; i < 3; ++i)
      out[i] = splat(m(i, 0)) * v[0] + splat(m(i, 1)) * v[1] + splat(m(i, 2)) * v[2];
  };
  Lanes ang_a[3], ang_b[3], dw_a[3], dw_b[3];
  cross_all(row.ra, ang_a);
  cross_all(row.rb, ang_b);
  mul_all(ia, ang_a, dw_a);
  mul_all(ib, ang_b, dw_b);
  for (int k = 0; k < 3; ++k) {
    row.ang_a[k] = Vec3(ang_a[0][k], ang_a[1][k], ang_a[2][k]);
    row.ang_b[k] = Vec3(ang_b[0][k], ang_b[1][k], ang_b[2][k]);
    row.dw_a[k] = Vec3(dw_a[0][k], dw_a[1][k], dw_a[2][k]);
    row.dw_b[k] = Vec3(dw_b[0][k], dw_b[1][k], dw_b[2][k]);
  }
  // K_ij = (m_A + m_B) d_i . d_j + (r_A x d_i) I_A^-1 (r_A x d_j) + (same for B), in lanes:
  // K_kk (the lanes as they are), K_12 and K_21 (lanes 1 and 2 of dw swapped)
  auto dot_all = [](const Lanes a[3], const Lanes b[3]) {
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
  };
  auto swap12 = [](const Lanes v[3], Lanes out[3]) {
    for (int i = 0; i < 3; ++i) out[i] = __builtin_shufflevector(v[i], v[i], 0, 2, 1, 3);
  };
  Lanes cross_a[3], cross_b[3];
  swap12(dw_a, cross_a);
  swap12(dw_b, cross_b);
  const Lanes diagonal = splat(row.ma + row.mb) + dot_all(ang_a, dw_a) + dot_all(ang_b, dw_b);
  const Lanes off = splat(0.0) + dot_all(ang_a, cross_a) + dot_all(ang_b, cross_b);
  const double k_n = diagonal[0];
  row.normal_mass = k_n > kTiny ? 1.0 / k_n : 0.0;
  row.kt[0] = diagonal[1];
  row.kt[1] = off[1] + off[2];
  row.kt[2] = diagonal[2];
}

COLLRES_CLONED_FLAT
void prepare_row(ContactRow& row, const ContactRow* framed, const SolverBodies& bodies,
                 const double* slow, double sticking_speed, double mu_static,
                 double mu_kinetic) {
  frame_row(row, bodies, framed);
  double before[2];
  slip_velocity(row, slow, before);
  row.bounce = false;
  row.sticking = norm2(before[0], before[1]) < sticking_speed;
  row.mu = row.sticking ? mu_static : mu_kinetic;
}

COLLRES_CLONED
void warm_start(ContactRow* rows, size_t count, SolverBodies& bodies) {
  double* v = bodies.velocity;
  // a run of consecutive rows of one pair (a manifold's) on its two twists loaded once and
  // stored once: each number takes the same operations in the same order as row by row
  for (size_t i = 0; i < count;) {
    const int32_t a = rows[i].a, b = rows[i].b;
    Twists t(v, a, b);
    bool changed = false;
    for (; i < count && rows[i].a == a && rows[i].b == b; ++i) {
      const ContactRow& r = rows[i];
      if (r.normal != 0.0) apply(r, t, 0, r.n, r.normal), changed = true;
      if (r.tangent[0] != 0.0) apply(r, t, 1, r.t1, r.tangent[0]), changed = true;
      if (r.tangent[1] != 0.0) apply(r, t, 2, r.t2, r.tangent[1]), changed = true;
    }
    if (changed) t.store(v, a, b);
  }
}

namespace {

// What a part of a sweep did: the largest impulse change, the largest normal impulse (N s);
// the wide groups' kept per lane (lanes_*, folded in by solve_velocities). A cache line of
// its own: a sweep's chunks are solve_velocities' adjacent entries, each written after
// every group by the thread that runs it, and two sides' chunks sharing a line made the
// two cores pass it back and forth the whole sweep
struct alignas(64) Progress {
  double change = 0.0, largest = 0.0;
  Lanes lanes_change = {0.0, 0.0, 0.0, 0.0}, lanes_largest = {0.0, 0.0, 0.0, 0.0};
};

// +0 (not -0: a row holding -0 would be rewritten +0 by its update)
inline bool positive_zero(double x) { return x == 0.0 && !std::signbit(x); }

// One sweep's update of one manifold (its rows; its spin row's load), twists at hand.
// `searched`: solve_block's (a lane's q; the manifold is then not idle), or null.
double solve_manifold(std::vector<ContactRow>& rows, const Manifold& manifold, Twists& t,
                      std::vector<SpinRow>* spins, Progress& progress,
                      const double* searched = nullptr) {
  const size_t lo = static_cast<size_t>(manifold.first);
  const size_t hi = lo + static_cast<size_t>(manifold.count);
  const int k = manifold.count;
  // every row idle: no impulse held (+0) and none approaching beyond its allowance, so its
  // update would change nothing (solve_block's idle answer, solve_normal's max(0 - m q, 0)
  // = +0, solve_friction's empty cone): done, as solve_groups' idle groups (a speculative
  // manifold that did not activate)
  bool idle = searched == nullptr;
  for (size_t i = lo; i < hi && idle; ++i) {
    const ContactRow& r = rows[i];
    idle = positive_zero(r.normal) && positive_zero(r.tangent[0]) &&
           positive_zero(r.tangent[1]) && relative(r, t, 0, r.n) + r.allowance >= 0.0;
  }
  if (idle) {
    if (spins != nullptr && manifold.spin >= 0) (*spins)[manifold.spin].load = 0.0;
    return 0.0;
  }
  double step = k >= 2 && k <= 4 ? solve_block(&rows[lo], manifold, t, searched) : -1.0;
  if (step >= 0.0) {
    step = std::max(step, solve_friction_block(&rows[lo], k, t));
  } else {
    step = 0.0;
    for (size_t i = lo; i < hi; ++i) step = std::max(step, solve_row(rows[i], t));
  }
  progress.change = std::max(progress.change, step);
  for (size_t i = lo; i < hi; ++i) progress.largest = std::max(progress.largest, rows[i].normal);
  if (spins != nullptr && manifold.spin >= 0) {   // its load, while its rows are at hand
    double load = 0.0;
    for (size_t i = lo; i < hi; ++i) load += rows[i].normal;
    (*spins)[manifold.spin].load = load;
  }
  return step;
}

// solve_manifold() of a manifold of 2 to 4 rows, lane l of a wide group, whose solve in
// the lane found no answer (solve_groups; q its block's q in lanes: solve_block's
// `searched`). Returns the largest impulse change (N s).
double solve_searched(std::vector<ContactRow>& rows, const Manifold& manifold, Twists& t,
                      const Lanes* q, int l) {
  double searched[4];
  for (int i = 0; i < manifold.count; ++i) searched[i] = q[i][l];
  Progress own;
  return solve_manifold(rows, manifold, t, nullptr, own, searched);
}

// One sweep over manifolds [from, to), one by one.
COLLRES_CLONED_FLAT
void solve_manifolds(std::vector<ContactRow>& rows, const std::vector<Manifold>& manifolds,
                     size_t from, size_t to, const SolverBodies& bodies,
                     std::vector<SpinRow>* spins, Progress& progress) {
  double* v = bodies.velocity;
  for (size_t m = from; m < to; ++m) {
    const Manifold& manifold = manifolds[m];
    Twists t(v, manifold.a, manifold.b);
    solve_manifold(rows, manifold, t, spins, progress);
    t.store(v, manifold.a, manifold.b, bodies.inv_mass);
  }
}

// One sweep over spin rows [from, to).
void solve_spins(std::vector<SpinRow>& spins, size_t from, size_t to, const SolverBodies& bodies,
                 Progress& progress) {
  for (size_t i = from; i < to; ++i)
    progress.change = std::max(progress.change, solve_spin(spins[i], bodies.velocity,
                                                           bodies.inv_mass));
}

// ---- wide groups: the update of solve_manifold on kLanes manifolds at once, lane by lane
// the same arithmetic in the same order (a manifold's bits do not depend on its lane)

typedef int64_t Mask __attribute__((vector_size(32), aligned(32)));
// (the helpers below are inlined into each clone of solve_groups: a vector argument passed
// between code of different targets would not agree on registers)
#define WIDE inline __attribute__((always_inline))

WIDE Lanes splat(double x) { return Lanes{x, x, x, x}; }
WIDE Lanes pick(Mask m, Lanes a, Lanes b) {   // m ? a : b, lane by lane (m: 0 or -1)
  // (by its sign: one blend where the target has one, e.g. the AVX2 clone, with no test
  // of a mask read back from memory against zero first)
  return m < 0 ? a : b;
}
WIDE Lanes maximum(Lanes a, Lanes b) { return pick(a < b, b, a); }   // std::max(a, b)
WIDE Lanes magnitude(Lanes a) {                                        // std::fabs
  return (Lanes)((Mask)a & (Mask){INT64_MAX, INT64_MAX, INT64_MAX, INT64_MAX});
}
WIDE Lanes root(Lanes a) {
  Lanes r;
  for (int l = 0; l < kLanes; ++l) r[l] = std::sqrt(a[l]);
  return r;
}
WIDE bool any(Mask m) {   // (its halves or-ed, then their two numbers)
  typedef int64_t Half __attribute__((vector_size(16)));
  const Half h = __builtin_shufflevector(m, m, 0, 1) | __builtin_shufflevector(m, m, 2, 3);
  return (h[0] | h[1]) != 0;
}
WIDE bool all(Mask m) {   // (its halves and-ed, then their two numbers)
  typedef int64_t Half __attribute__((vector_size(16)));
  const Half h = __builtin_shufflevector(m, m, 0, 1) & __builtin_shufflevector(m, m, 2, 3);
  return (h[0] & h[1]) != 0;
}

// Four rows of four to four columns (a 4x4 transpose: lane l of column c is row l's c):
// a body's twist read or written four numbers at once (one load or store per lane, not
// one per number), the same values
WIDE void transpose(const Lanes* row, Lanes* column) {
  const Lanes t0 = __builtin_shufflevector(row[0], row[1], 0, 4, 2, 6);
  const Lanes t1 = __builtin_shufflevector(row[0], row[1], 1, 5, 3, 7);
  const Lanes t2 = __builtin_shufflevector(row[2], row[3], 0, 4, 2, 6);
  const Lanes t3 = __builtin_shufflevector(row[2], row[3], 1, 5, 3, 7);
  column[0] = __builtin_shufflevector(t0, t2, 0, 1, 4, 5);
  column[1] = __builtin_shufflevector(t1, t3, 0, 1, 4, 5);
  column[2] = __builtin_shufflevector(t0, t2, 2, 3, 6, 7);
  column[3] = __builtin_shufflevector(t1, t3, 2, 3, 6, 7);
}
typedef double Pair __attribute__((vector_size(16)));
WIDE Lanes load4(const double* at) {
  Lanes r;
  std::memcpy(&r, at, sizeof(r));
  return r;
}
WIDE Pair load2(const double* at) {
  Pair r;
  std::memcpy(&r, at, sizeof(r));
  return r;
}
WIDE void store2(double* at, Pair p) { std::memcpy(at, &p, sizeof(p)); }
// numbers at and at + 1 of each lane's body's twist (v: 6 per body), as two columns
// (lanes 0 and 2 read into one vector, 1 and 3 into another, then interleaved)
WIDE void load_pair(const double* v, const int64_t* offset, int at, Lanes& first,
                    Lanes& second) {
  const Lanes even = __builtin_shufflevector(load2(v + offset[0] + at),
                                             load2(v + offset[2] + at), 0, 1, 2, 3);
  const Lanes odd = __builtin_shufflevector(load2(v + offset[1] + at),
                                            load2(v + offset[3] + at), 0, 1, 2, 3);
  first = __builtin_shufflevector(even, odd, 0, 4, 2, 6);
  second = __builtin_shufflevector(even, odd, 1, 5, 3, 7);
}
// load_pair's inverse: pairs[l % 2] holds lane l's (first, second) in its half l / 2
WIDE void pair_rows(Lanes first, Lanes second, Lanes* pairs) {
  pairs[0] = __builtin_shufflevector(first, second, 0, 4, 2, 6);
  pairs[1] = __builtin_shufflevector(first, second, 1, 5, 3, 7);
}
WIDE void store_pair(double* at, const Lanes* pairs, int l) {
  const Lanes& p = pairs[l % 2];
  store2(at, l / 2 == 0 ? __builtin_shufflevector(p, p, 0, 1)
                        : __builtin_shufflevector(p, p, 2, 3));
}
// numbers [at, at + 4) of each lane's body's twist (v: 6 per body), as four columns
WIDE void load_lanes(const double* v, const int64_t* offset, int at, Lanes* column) {
  const Lanes row[kLanes] = {load4(v + offset[0] + at), load4(v + offset[1] + at),
                             load4(v + offset[2] + at), load4(v + offset[3] + at)};
  transpose(row, column);
}

struct WideVec {
  Lanes x, y, z;
};
WIDE Lanes dot(const WideVec& a, const Lanes* b) { return a.x * b[0] + a.y * b[1] + a.z * b[2]; }

// The twists of the lanes' bodies (as Twists).
struct WideTwists {
  WideVec va, wa, vb, wb;
  WIDE WideTwists(const double* v, const WideGroup& g) {
    load_pair(v, g.offset_a, 0, va.x, va.y);
    load_pair(v, g.offset_a, 2, va.z, wa.x);
    load_pair(v, g.offset_a, 4, wa.y, wa.z);
    load_pair(v, g.offset_b, 0, vb.x, vb.y);
    load_pair(v, g.offset_b, 2, vb.z, wb.x);
    load_pair(v, g.offset_b, 4, wb.y, wb.z);
  }
  WIDE Twists lane(int l) const {
    Twists t;
    t.va = Vec3(va.x[l], va.y[l], va.z[l]);
    t.wa = Vec3(wa.x[l], wa.y[l], wa.z[l]);
    t.vb = Vec3(vb.x[l], vb.y[l], vb.z[l]);
    t.wb = Vec3(wb.x[l], wb.y[l], wb.z[l]);
    return t;
  }
  WIDE void set_lane(int l, const Twists& t) {
    va.x[l] = t.va.x(), va.y[l] = t.va.y(), va.z[l] = t.va.z();
    wa.x[l] = t.wa.x(), wa.y[l] = t.wa.y(), wa.z[l] = t.wa.z();
    vb.x[l] = t.vb.x(), vb.y[l] = t.vb.y(), vb.z[l] = t.vb.z();
    wb.x[l] = t.wb.x(), wb.y[l] = t.wb.y(), wb.z[l] = t.wb.z();
  }
  WIDE void store(double* v, const WideGroup& g) const {
    Lanes a[3][2], b[3][2];   // pair_rows of numbers (0, 1), (2, 3), (4, 5)
    pair_rows(va.x, va.y, a[0]);
    pair_rows(va.z, wa.x, a[1]);
    pair_rows(wa.y, wa.z, a[2]);
    pair_rows(vb.x, vb.y, b[0]);
    pair_rows(vb.z, wb.x, b[1]);
    pair_rows(wb.y, wb.z, b[2]);
#pragma GCC unroll 4   // (l a constant: each half stored straight from its register)
    for (int l = 0; l < kLanes; ++l) {
      double* const at_a = v + g.offset_a[l];
      double* const at_b = v + g.offset_b[l];
      if (g.write_a[l])
        for (int p = 0; p < 3; ++p) store_pair(at_a + 2 * p, a[p], l);
      if (g.write_b[l])
        for (int p = 0; p < 3; ++p) store_pair(at_b + 2 * p, b[p], l);
    }
  }
};

// relative(): velocity of B's point relative to A's along direction k of the row
WIDE Lanes relative(const WideRow& r, const WideTwists& t, int k, const Lanes* d) {
  const WideVec rel{t.vb.x - t.va.x, t.vb.y - t.va.y, t.vb.z - t.va.z};
  return dot(rel, d) + dot(t.wb, r.ang_b[k]) - dot(t.wa, r.ang_a[k]);
}

// apply(): impulse s along direction k, +s on B, -s on A; lanes where s is 0 unchanged
WIDE void apply(const WideRow& r, const WideGroup& g, WideTwists& t, int k, const Lanes* d,
                  Lanes s) {
  const Mask on = s != 0.0;
  const Lanes sa = s * g.ma, sb = s * g.mb;
  t.va.x = pick(on, t.va.x - sa * d[0], t.va.x);
  t.va.y = pick(on, t.va.y - sa * d[1], t.va.y);
  t.va.z = pick(on, t.va.z - sa * d[2], t.va.z);
  t.wa.x = pick(on, t.wa.x - s * r.dw_a[k][0], t.wa.x);
  t.wa.y = pick(on, t.wa.y - s * r.dw_a[k][1], t.wa.y);
  t.wa.z = pick(on, t.wa.z - s * r.dw_a[k][2], t.wa.z);
  t.vb.x = pick(on, t.vb.x + sb * d[0], t.vb.x);
  t.vb.y = pick(on, t.vb.y + sb * d[1], t.vb.y);
  t.vb.z = pick(on, t.vb.z + sb * d[2], t.vb.z);
  t.wb.x = pick(on, t.wb.x + s * r.dw_b[k][0], t.wb.x);
  t.wb.y = pick(on, t.wb.y + s * r.dw_b[k][1], t.wb.y);
  t.wb.z = pick(on, t.wb.z + s * r.dw_b[k][2], t.wb.z);
}

// apply() in every lane, lanes where s is 0 included: apply() itself where no lane's s is
// 0 (its picks keep no old number). Elsewhere each adds or subtracts products
// that are +-0 there, which leave a number unchanged but for the sign of a zero. For
// twists whose change from the start is all that is read (solve_friction_block's `moved`,
// read as moved - start) that is the same bits as apply(): along a lane, the sums take
// the same values, so differ at most in the sign of a zero result, and a zero's
// difference from its start is +0 whatever its sign and the start's (a start of +0 stays
// +0 under sums of zeros and exact cancellations; -0 - -0 and +0 - -0 are both +0)
WIDE void apply_all(const WideRow& r, const WideGroup& g, WideTwists& t, int k,
                    const Lanes* d, Lanes s) {
  const Lanes sa = s * g.ma, sb = s * g.mb;
  t.va.x = t.va.x - sa * d[0];
  t.va.y = t.va.y - sa * d[1];
  t.va.z = t.va.z - sa * d[2];
  t.wa.x = t.wa.x - s * r.dw_a[k][0];
  t.wa.y = t.wa.y - s * r.dw_a[k][1];
  t.wa.z = t.wa.z - s * r.dw_a[k][2];
  t.vb.x = t.vb.x + sb * d[0];
  t.vb.y = t.vb.y + sb * d[1];
  t.vb.z = t.vb.z + sb * d[2];
  t.wb.x = t.wb.x + s * r.dw_b[k][0];
  t.wb.y = t.wb.y + s * r.dw_b[k][1];
  t.wb.z = t.wb.z + s * r.dw_b[k][2];
}

// friction_target() in every lane
WIDE void friction_target(const WideRow& r, Lanes x, Lanes y, Lanes& tx, Lanes& ty) {
  const Lanes speed2 = x * x + y * y;
  const Lanes stiffness = r.kt[0] * x * x + r.kt[1] * x * y + r.kt[2] * y * y;
  const Lanes slip = speed2 / maximum(stiffness, splat(kTiny) * speed2 + 1e-300);
  tx = r.tangent[0] - x * slip;
  ty = r.tangent[1] - y * slip;
  const Lanes size = root(tx * tx + ty * ty);
  const Lanes limit = r.mu * r.normal;
  const Lanes scale = pick(size > 0.0, limit / size, splat(0.0));
  const Mask over = size > limit;
  tx = pick(over, tx * scale, tx);
  ty = pick(over, ty * scale, ty);
}

// solve_friction() in the lanes of `live`; returns the largest impulse change per lane
// (0 elsewhere)
WIDE Lanes solve_friction(WideRow& r, const WideGroup& g, WideTwists& t, Mask live) {
  const Mask held = (r.normal != 0.0) | (r.tangent[0] != 0.0) | (r.tangent[1] != 0.0);
  live &= held;
  const Lanes x = relative(r, t, 1, g.t1), y = relative(r, t, 2, g.t2);
  Lanes tx, ty;
  friction_target(r, x, y, tx, ty);
  const Lanes zero = splat(0.0);
  const Lanes d_x = pick(live, tx - r.tangent[0], zero), d_y = pick(live, ty - r.tangent[1], zero);
  r.tangent[0] = pick(live, tx, r.tangent[0]);
  r.tangent[1] = pick(live, ty, r.tangent[1]);
  if (all((d_x != 0.0) & (d_y != 0.0))) {   // (mostly: apply() would keep no lane's twist)
    apply_all(r, g, t, 1, g.t1, d_x);
    apply_all(r, g, t, 2, g.t2, d_y);
  } else {
    apply(r, g, t, 1, g.t1, d_x);
    apply(r, g, t, 2, g.t2, d_y);
  }
  return maximum(magnitude(d_x), magnitude(d_y));
}

// solve_friction_block() on the k rows of the lanes of `live`; returns the largest impulse
// change per lane (0 elsewhere)
template <int k>
WIDE Lanes solve_friction_block(WideRow* w, const WideGroup& g, WideTwists& t, Mask live) {
  const Lanes zero = splat(0.0);
  Lanes change = zero;
  Lanes size[4], limit[4];
  Mask over[4], outside = (Mask){0, 0, 0, 0};
  for (int i = 0; i < k; ++i) {   // into the cones (one test for all rows: mostly none)
    WideRow& r = w[i];
    size[i] = root(r.tangent[0] * r.tangent[0] + r.tangent[1] * r.tangent[1]);
    limit[i] = r.mu * r.normal;
    over[i] = live & (size[i] > limit[i]);
    outside |= over[i];
  }
  const int outside_rows = any(outside) ? k : 0;
  for (int i = 0; i < outside_rows; ++i) {
    WideRow& r = w[i];
    if (!any(over[i])) continue;
    const Lanes scale = limit[i] / size[i];
    const Lanes d_x = pick(over[i], r.tangent[0] * scale - r.tangent[0], zero);
    const Lanes d_y = pick(over[i], r.tangent[1] * scale - r.tangent[1], zero);
    r.tangent[0] = pick(over[i], r.tangent[0] + d_x, r.tangent[0]);
    r.tangent[1] = pick(over[i], r.tangent[1] + d_y, r.tangent[1]);
    apply(r, g, t, 1, g.t1, d_x);
    apply(r, g, t, 2, g.t2, d_y);
    change = maximum(change, maximum(magnitude(d_x), magnitude(d_y)));
  }
  Lanes d[4][2];
  Lanes along = zero;
  for (int i = 0; i < k; ++i) {
    WideRow& r = w[i];
    const Lanes x = relative(r, t, 1, g.t1), y = relative(r, t, 2, g.t2);
    const Mask on = live & ((r.normal != 0.0) | (r.tangent[0] != 0.0) | (r.tangent[1] != 0.0));
    Lanes tx, ty;
    friction_target(r, x, y, tx, ty);
    d[i][0] = pick(on, tx - r.tangent[0], zero);
    d[i][1] = pick(on, ty - r.tangent[1], zero);
    along = pick(on, along + (d[i][0] * x + d[i][1] * y), along);
  }
  const Mask go = live & (along < 0.0);
  if (!any(go)) return change;
  // the twists the k targets together would give, in the rows' order (read as the change
  // from t, delta); after the targets, which read t alone: fewer values live at once
  WideTwists moved = t;
  for (int i = 0; i < k; ++i) {
    apply_all(w[i], g, moved, 1, g.t1, d[i][0]);
    apply_all(w[i], g, moved, 2, g.t2, d[i][1]);
  }
  WideTwists delta = moved;
  delta.va = WideVec{moved.va.x - t.va.x, moved.va.y - t.va.y, moved.va.z - t.va.z};
  delta.wa = WideVec{moved.wa.x - t.wa.x, moved.wa.y - t.wa.y, moved.wa.z - t.wa.z};
  delta.vb = WideVec{moved.vb.x - t.vb.x, moved.vb.y - t.vb.y, moved.vb.z - t.vb.z};
  delta.wb = WideVec{moved.wb.x - t.wb.x, moved.wb.y - t.wb.y, moved.wb.z - t.wb.z};
  Lanes curve = zero;
  for (int i = 0; i < k; ++i)
    curve += d[i][0] * relative(w[i], delta, 1, g.t1) +
             d[i][1] * relative(w[i], delta, 2, g.t2);
  const Lanes s = pick(curve > -along, -along / curve, splat(1.0));
  // the proposals taken in the lanes of `go` (`every`: all four, mostly; no pick then)
  auto take = [&](const bool every) __attribute__((always_inline)) {
    auto at = [&](Lanes taken, Lanes kept) __attribute__((always_inline)) {
      return every ? taken : pick(go, taken, kept);
    };
    auto by = [&](WideVec& to, const WideVec& change) __attribute__((always_inline)) {
      to.x = at(to.x + s * change.x, to.x);
      to.y = at(to.y + s * change.y, to.y);
      to.z = at(to.z + s * change.z, to.z);
    };
    by(t.va, delta.va);
    by(t.wa, delta.wa);
    by(t.vb, delta.vb);
    by(t.wb, delta.wb);
    for (int i = 0; i < k; ++i) {
      const Lanes d_x = s * d[i][0], d_y = s * d[i][1];
      w[i].tangent[0] = at(w[i].tangent[0] + d_x, w[i].tangent[0]);
      w[i].tangent[1] = at(w[i].tangent[1] + d_y, w[i].tangent[1]);
      change = maximum(change, at(maximum(magnitude(d_x), magnitude(d_y)), zero));
    }
  };
  if (all(go)) {
    take(true);
  } else {
    take(false);
  }
  return change;
}

// solve_normal() of a one-row manifold, every lane; `free` its normal speed plus its
// allowance (m/s) at the twists t
WIDE Lanes solve_normal(WideRow& r, const WideGroup& g, WideTwists& t, Lanes free) {
  const Lanes new_n = maximum(r.normal - r.normal_mass * free, splat(0.0));
  const Lanes d_n = new_n - r.normal;
  r.normal = new_n;
  apply(r, g, t, 0, g.n, d_n);
  return magnitude(d_n);
}

// The rows of a lane's manifold to and from its ContactRows (normal and friction impulses).
void lane_to_rows(const WideRow* w, int l, ContactRow* r, int count) {
  for (int i = 0; i < count; ++i) {
    r[i].normal = w[i].normal[l];
    r[i].tangent[0] = w[i].tangent[0][l];
    r[i].tangent[1] = w[i].tangent[1][l];
  }
}
void rows_to_lane(const ContactRow* r, int count, WideRow* w, int l) {
  for (int i = 0; i < count; ++i) {
    w[i].normal[l] = r[i].normal;
    w[i].tangent[0][l] = r[i].tangent[0];
    w[i].tangent[1][l] = r[i].tangent[1];
  }
}

// One sweep's update of a wide group of k rows (g.count): solve_manifold on its manifolds
// (its padding lanes idle: nothing taken, nothing searched, nothing stored). A block whose
// all-active answer does not fit (the active-set search, or rows one by one) is handed to
// solve_manifold in its lane. (k a constant: each row count's
// loops unrolled, their values in registers; solve_groups picks one.)
template <int k>
WIDE void solve_group_of(WideGroup& g, WideRow* w, std::vector<ContactRow>& rows,
                         const std::vector<Manifold>& manifolds, double* v,
                         std::vector<SpinRow>* spins, WideSpin* spin_lanes, WideFace* kept,
                         Progress& progress) {
  WideTwists t(v, g);
  // every lane idle: no impulse held (+0 bits) and no row approaching beyond its
  // allowance, so each lane's update would change nothing (solve_block's idle answer x = 0,
  // solve_normal's max(0 - m q, 0) = +0, solve_friction's empty cone): the group is done
  // (a speculative group that did not activate: most groups of a settled pile at 30 Hz)
  // (free[i]: row i's normal speed plus its allowance, m/s, from the twists as loaded: what
  // the normal updates below start from too)
  Lanes free[4];
  for (int i = 0; i < k; ++i) free[i] = relative(w[i], t, 0, g.n) + w[i].allowance;
  {
    Mask idle = (Mask){-1, -1, -1, -1};
    const Mask zero = (Mask){0, 0, 0, 0};
    for (int i = 0; i < k; ++i)   // (+0: all bits clear; the three or-ed, one test)
      idle &= (((Mask)w[i].normal | (Mask)w[i].tangent[0] | (Mask)w[i].tangent[1]) == zero) &
              (free[i] >= 0.0);
    if (!any(~idle)) {
      if (spin_lanes != nullptr) {
        spin_lanes->load = splat(0.0);
      } else {
        for (int l = 0; l < g.lanes; ++l) {
          const int32_t spin = manifolds[g.manifold + static_cast<size_t>(l)].spin;
          if (spins != nullptr && spin >= 0) (*spins)[spin].load = 0.0;
        }
      }
      return;
    }
  }
  Lanes step = splat(0.0);
  Mask live = (Mask){-1, -1, -1, -1};   // lanes whose friction is solved here
  if (k == 1) {
    step = solve_normal(w[0], g, t, free[0]);
  } else {
    // solve_block: q = J v + allowance - A normal; x = 0 when idle, else inverse (-q) when
    // every row ends active (and the approach left along the free direction is rounding),
    // else the lane's own search
    Lanes q[4], x[4];
    Mask idle = (Mask){-1, -1, -1, -1};
    for (int i = 0; i < k; ++i) {
      q[i] = free[i];
      for (int j = 0; j < k; ++j) q[i] -= g.plain[i][j] * w[j].normal;
      idle &= (w[i].normal == 0.0) & (q[i] >= 0.0);
    }
    Mask fits = g.invertible != 0.0;
    for (int i = 0; i < k; ++i) {
      x[i] = splat(0.0);
      for (int j = 0; j < k; ++j) x[i] -= g.inverse[i][j] * q[j];
      fits &= x[i] >= -1e-12 * (1.0 + magnitude(x[i]));
    }
    if (g.redundant) {   // (else every lane's residual is 0: the test passes)
      Lanes loose = splat(0.0), largest_q = splat(0.0);
      for (int i = 0; i < k; ++i) {
        loose += g.residual[i] * q[i];
        largest_q = maximum(largest_q, magnitude(q[i]));
      }
      fits &= magnitude(loose) <= 1e-12 * (1.0 + largest_q);
    }
    // take_block's changes of the normal impulses, per row: each lane's from the one answer
    // that fits it (all-active, edge or face; the three take disjoint lanes), applied to the
    // twists once, below, the same operations on each lane as one apply per answer (a lane
    // whose change is 0 in an apply is left alone by it)
    Lanes taken[4];
    const Mask take = fits & ~idle;
    for (int i = 0; i < k; ++i) {   // take_block
      const Lanes d = pick(take, maximum(x[i], splat(0.0)) - w[i].normal, splat(0.0));
      w[i].normal += d;
      taken[i] = d;
      step = maximum(step, magnitude(d));
    }
    Mask search = ~(fits | idle);
    // two rows (an edge) whose all-active answer failed: solve_block's search tries sets
    // of one row or none (the rows carrying impulse first, then {1}, {0}, {}), each a
    // division; solved here in lanes, the same sets in the same order, the same arithmetic
    const Mask two = search & (g.invertible != 0.0);
    if (k == 2 && any(two)) {
      const Lanes zero = splat(0.0);
      Lanes candidate[3][2];   // x of the sets {0} (bit 1), {1} (bit 2), {} (0)
      Mask fit[3];
      for (int i = 0; i < 2; ++i) {
        const int j = 1 - i;
        const Lanes a_ii = kept->delassus[i][i];
        const Lanes x_i = (-q[i]) / a_ii;
        candidate[i][i] = x_i;
        candidate[i][j] = zero;
        const Lanes w_j = q[j] + kept->delassus[j][0] * candidate[i][0] +
                          kept->delassus[j][1] * candidate[i][1];
        fit[i] = (magnitude(a_ii) > 1e-9 * magnitude(a_ii) + 1e-300) &
                 (x_i >= -1e-12 * (1.0 + magnitude(x_i))) &
                 (w_j >= -1e-12 * (1.0 + magnitude(q[j])));
      }
      candidate[2][0] = candidate[2][1] = zero;
      fit[2] = (Mask){-1, -1, -1, -1};
      for (int i = 0; i < 2; ++i)
        fit[2] &= q[i] + kept->delassus[i][0] * zero + kept->delassus[i][1] * zero >=
                  -1e-12 * (1.0 + magnitude(q[i]));
      Mask chosen = {0, 0, 0, 0};
      Lanes found[2] = {zero, zero};
      for (int l = 0; l < kLanes; ++l) {
        if (!two[l]) continue;
        const int carrying = (w[0].normal[l] > 0.0 ? 1 : 0) | (w[1].normal[l] > 0.0 ? 2 : 0);
        const int order[4] = {carrying, 2, 1, 0};   // (carrying 3: tried above)
        for (int o = carrying == 3 ? 1 : 0; o < 4; ++o) {
          const int set = order[o];
          if (o > 0 && set == carrying) continue;
          const int c = set == 1 ? 0 : (set == 2 ? 1 : 2);
          if (fit[c][l]) {
            chosen[l] = -1;
            found[0][l] = candidate[c][0][l];
            found[1][l] = candidate[c][1][l];
            break;
          }
        }
      }
      for (int i = 0; i < 2; ++i) {   // take_block
        const Lanes d = pick(chosen, maximum(found[i], zero) - w[i].normal, zero);
        w[i].normal += d;
        taken[i] = pick(chosen, d, taken[i]);
        step = maximum(step, magnitude(d));
      }
      search &= ~chosen;
    }
    // three or four rows (a face) whose all-active answer failed: solve_block's search
    // tries the rows carrying impulse first, and they are usually the answer: that set
    // solved in lanes, each lane's set in its leading rows and the rest an identity that
    // the elimination leaves alone (the same pivots and arithmetic as solve_block's
    // `fits`); a lane whose set does not fit searches on one by one
    const Mask face = search & (g.invertible != 0.0);
    if (k >= 3 && any(face)) {
      const Lanes zero = splat(0.0), one = splat(1.0);
      Lanes e[4][5], diagonal[4];   // the set's rows, rhs last; each column's reference
      // each lane's carrying set as lane masks: carry[i] where row i carries, rank[i] its
      // place in the set (the rows before it that carry), `in`[r][i] where row i is the
      // set's r-th row; `bits` the set (bit i: row i) in the lanes tried, else 0
      Mask carry[4], all_carry = (Mask){-1, -1, -1, -1};
      for (int i = 0; i < k; ++i) {
        carry[i] = w[i].normal > 0.0;
        all_carry &= carry[i];
      }
      const Mask tried = face & ~all_carry;   // (the all-active set: failed above)
      if (any(tried)) {
        Mask rank[4], bits = (Mask){0, 0, 0, 0};
        rank[0] = (Mask){0, 0, 0, 0};
        for (int i = 0; i < k; ++i) {
          carry[i] &= tried;
          bits |= carry[i] & (Mask){1 << i, 1 << i, 1 << i, 1 << i};
          if (i + 1 < k) rank[i + 1] = rank[i] - carry[i];
        }
        Mask in[4][4];   // [r][i], r <= i
        for (int i = 0; i < k; ++i)
          for (int r = 0; r <= i; ++r) in[r][i] = carry[i] & (rank[i] == (Mask){r, r, r, r});
        for (int r = 0; r < 4; ++r) e[r][4] = zero;   // the right-hand side, -q of the set
        for (int i = 0; i < k; ++i)
          for (int r = 0; r <= i; ++r) e[r][4] = pick(in[r][i], -q[i], e[r][4]);
        Mask kept_bits;
        std::memcpy(&kept_bits, kept->set, sizeof(kept_bits));
        const bool replay = !any(tried & (kept_bits != bits));
        Mask ok = tried;
        if (replay) {
          // the kept elimination on the right-hand side alone (its swaps and multiples)
          ok &= (Mask)kept->usable;
          for (int c = 0; c < 4; ++c) {
            for (int r = c + 1; r < 4; ++r) {
              const Mask swap = kept->pivot[c] == static_cast<double>(r);
              const Lanes upper = e[c][4];
              e[c][4] = pick(swap, e[r][4], upper);
              e[r][4] = pick(swap, upper, e[r][4]);
            }
            for (int r = 0; r < 4; ++r) {
              if (r == c) continue;
              e[r][4] -= kept->factor[c][r] * e[c][4];
            }
          }
          for (int r = 0; r < 4; ++r) e[r][r] = kept->diagonal[r];
        } else {
          for (int r = 0; r < 4; ++r) {
            for (int c = 0; c < 4; ++c) e[r][c] = zero;
            diagonal[r] = one;
          }
          for (int l = 0; l < kLanes; ++l) {
            // (idx zeroed: GCC cannot tell that a lane reads only the entries it wrote)
            int idx[4] = {}, m = 0;
            for (int i = 0; i < k; ++i)
              if (bits[l] & (1 << i)) idx[m++] = i;
            for (int r = 0; r < 4; ++r) {
              if (r >= m) {
                e[r][r][l] = 1.0;
                continue;
              }
              for (int c = 0; c < m; ++c) e[r][c][l] = kept->delassus[idx[r]][idx[c]][l];
              diagonal[r][l] = kept->delassus[idx[r]][idx[r]][l];
            }
          }
          Mask usable = (Mask){-1, -1, -1, -1};
          for (int c = 0; c < 4; ++c) {
            // partial pivoting: the first row below c of strictly larger magnitude
            Lanes best = magnitude(e[c][c]);
            Lanes pivot = splat(static_cast<double>(c));
            for (int r = c + 1; r < 4; ++r) {
              const Mask larger = magnitude(e[r][c]) > best;
              best = pick(larger, magnitude(e[r][c]), best);
              pivot = pick(larger, splat(static_cast<double>(r)), pivot);
            }
            usable &= ~(best <= 1e-9 * magnitude(diagonal[c]) + 1e-300);
            for (int r = c + 1; r < 4; ++r) {
              const Mask swap = pivot == static_cast<double>(r);
              for (int j = 0; j < 5; ++j) {
                const Lanes upper = e[c][j];
                e[c][j] = pick(swap, e[r][j], upper);
                e[r][j] = pick(swap, upper, e[r][j]);
              }
            }
            for (int r = 0; r < 4; ++r) {
              if (r == c) continue;
              const Lanes f = e[r][c] / e[c][c];
              for (int j = c; j < 5; ++j) e[r][j] -= f * e[c][j];
              kept->factor[c][r] = f;
            }
            kept->pivot[c] = pivot;
          }
          ok &= usable;
          // kept for the next sweeps (lanes not tried: none, -1)
          for (int r = 0; r < 4; ++r) kept->diagonal[r] = e[r][r];
          kept->usable = (Lanes)usable;
          const Mask set = bits | ~tried;
          std::memcpy(kept->set, &set, sizeof(set));
        }
        Lanes x[4];   // the set's r-th row's impulse
        for (int r = 0; r < 4; ++r) x[r] = e[r][4] / e[r][r];
        Lanes xs[4] = {zero, zero, zero, zero};   // by row of the block
        for (int i = 0; i < k; ++i) {
          for (int r = 0; r <= i; ++r) xs[i] = pick(in[r][i], x[r], xs[i]);
          // (a row of the set: its x[r]'s test; one left out holds +0, which passes)
          ok &= xs[i] >= -1e-12 * (1.0 + magnitude(xs[i]));
        }
        for (int i = 0; i < k; ++i) {   // the rows left out: no approach
          Lanes w_i = q[i];
          for (int j = 0; j < k; ++j) w_i += kept->delassus[i][j] * xs[j];
          ok &= carry[i] | (w_i >= -1e-12 * (1.0 + magnitude(q[i])));
        }
        for (int i = 0; i < k; ++i) {   // take_block
          const Lanes d = pick(ok, maximum(xs[i], zero) - w[i].normal, zero);
          w[i].normal += d;
          taken[i] = pick(ok, d, taken[i]);
          step = maximum(step, magnitude(d));
        }
        search &= ~ok;
      }
    }
    for (int i = 0; i < k; ++i) apply(w[i], g, t, 0, g.n, taken[i]);
    if (any(search)) {
      for (int l = 0; l < kLanes; ++l) {
        if (!search[l]) continue;
        const Manifold& manifold = manifolds[g.manifold + static_cast<size_t>(l)];
        ContactRow* r = &rows[static_cast<size_t>(manifold.first)];
        lane_to_rows(w, l, r, k);
        Twists lane = t.lane(l);
        step[l] = solve_searched(rows, manifold, lane, q, l);
        rows_to_lane(r, k, w, l);
        t.set_lane(l, lane);
      }
      live = ~search;
    }
  }
  if (k == 1) {
    step = maximum(step, solve_friction(w[0], g, t, live));
  } else {
    step = maximum(step, solve_friction_block<k>(w, g, t, live));
  }
  t.store(v, g);
  Lanes largest = splat(0.0), load = splat(0.0);
  for (int i = 0; i < k; ++i) {
    largest = maximum(largest, w[i].normal);
    load += w[i].normal;
  }
  progress.lanes_change = maximum(progress.lanes_change, step);
  progress.lanes_largest = maximum(progress.lanes_largest, largest);
  if (spin_lanes != nullptr) {
    spin_lanes->load = load;
    return;
  }
  for (int l = 0; l < g.lanes; ++l) {
    const int32_t spin = manifolds[g.manifold + static_cast<size_t>(l)].spin;
    if (spins != nullptr && spin >= 0) (*spins)[spin].load = load[l];
  }
}

// The wide groups [lo, hi) of wave l, in order (one call for a part of a wave: the groups'
// updates inlined, no call each). Without GCC's code hoisting: it moved products to the
// block that dominates their uses (e.g. the line search's impulses times the inverse
// masses, all sixteen ahead of the sums that read them), which kept more Lanes live than
// the AVX2 clone's 16 registers hold, each spilled and read back (the same operations
// either way: the same bits).
COLLRES_CLONED COLLRES_NO_HOISTING
void solve_groups(SweepPlan& plan, size_t l, size_t lo, size_t hi,
                  std::vector<ContactRow>& rows, const std::vector<Manifold>& manifolds,
                  double* v, std::vector<SpinRow>* spins, Progress& progress) {
  for (size_t item = lo; item < hi; ++item) {
    const int32_t entry = plan.slot[plan.wave_groups[l] + item];
    WideGroup& g = plan.groups[entry];
    WideRow* const w = &plan.wide_rows[g.row];
    WideSpin* const spin_lanes = spins != nullptr && plan.spin_groups[entry].wide
                                     ? &plan.spin_groups[entry] : nullptr;
    WideFace* const kept = &plan.faces[entry];   // (read where the search runs: 2 to 4 rows)
    switch (g.count) {   // 1 to 4 (WideGroup)
      case 1:
        solve_group_of<1>(g, w, rows, manifolds, v, spins, spin_lanes, kept, progress);
        break;
      case 2:
        solve_group_of<2>(g, w, rows, manifolds, v, spins, spin_lanes, kept, progress);
        break;
      case 3:
        solve_group_of<3>(g, w, rows, manifolds, v, spins, spin_lanes, kept, progress);
        break;
      default:
        solve_group_of<4>(g, w, rows, manifolds, v, spins, spin_lanes, kept, progress);
        break;
    }
  }
}

// solve_spin() on the spin rows of a wide group (all four lanes, WideSpin::load their
// SpinRow::load); returns the change over the lever per lane
WIDE void solve_wide_spin(WideSpin& s, const WideGroup& g, double* v, Progress& progress) {
  const Lanes normal = s.load;
  const Mask held = (normal != 0.0) | (s.torque[0] != 0.0) | (s.torque[1] != 0.0) |
                    (s.torque[2] != 0.0);
  if (!any(held)) return;
  // each lane's (v_z, w) of A and of B (numbers 2 to 5 of a twist: in bounds for the
  // last body, where 3 to 6 would not be); wa, wb the angular velocities
  Lanes twist_a[4], twist_b[4];
  load_lanes(v, g.offset_a, 2, twist_a);
  load_lanes(v, g.offset_b, 2, twist_b);
  Lanes* const wa = twist_a + 1;
  Lanes* const wb = twist_b + 1;
  auto dot3 = [](const Lanes* a, const Lanes* b) __attribute__((always_inline)) {
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
  };
  auto mul3 = [](const Lanes (*m)[3], const Lanes* x, Lanes* out) __attribute__((always_inline)) {
    for (int r = 0; r < 3; ++r) out[r] = m[r][0] * x[0] + m[r][1] * x[1] + m[r][2] * x[2];
  };
  const Lanes zero = splat(0.0);
  Lanes w[3], rolling[3], old_roll[3], roll[3];
  for (int e = 0; e < 3; ++e) w[e] = wb[e] - wa[e];
  const Lanes spin = dot3(w, s.n);
  for (int e = 0; e < 3; ++e) rolling[e] = w[e] - spin * s.n[e];
  const Lanes old_twist = dot3(s.torque, s.n);
  for (int e = 0; e < 3; ++e) old_roll[e] = s.torque[e] - old_twist * s.n[e];
  const Lanes speed2 = dot3(rolling, rolling);
  Lanes k_rolling[3];
  mul3(s.inv_ab, rolling, k_rolling);
  const Lanes k_roll = dot3(rolling, k_rolling);
  const Mask slips = (speed2 > 0.0) & (k_roll > kTiny * speed2);
  const Lanes ratio = speed2 / k_roll;
  for (int e = 0; e < 3; ++e) roll[e] = pick(slips, old_roll[e] - ratio * rolling[e], old_roll[e]);
  const Lanes roll_size = root(dot3(roll, roll)), roll_limit = s.roll * normal;
  const Mask over = roll_size > roll_limit;
  const Lanes shrink = roll_limit / roll_size;
  for (int e = 0; e < 3; ++e) roll[e] = pick(over, shrink * roll[e], roll[e]);
  Lanes twist = pick(s.k_n > kTiny, old_twist - spin / s.k_n, old_twist);
  const Lanes low = -s.twist * normal, high = s.twist * normal;
  twist = pick(twist < low, low, pick(high < twist, high, twist));   // std::clamp
  Lanes change[3];
  for (int e = 0; e < 3; ++e) {
    change[e] = pick(held, (roll[e] - old_roll[e]) + (twist - old_twist) * s.n[e], zero);
    s.torque[e] = pick(held, roll[e] + twist * s.n[e], s.torque[e]);
  }
  const Mask moved = (change[0] != 0.0) | (change[1] != 0.0) | (change[2] != 0.0);
  Lanes turn_a[3], turn_b[3];
  mul3(s.inv_a, change, turn_a);
  mul3(s.inv_b, change, turn_b);
  const Lanes size = pick(moved, root(dot3(change, change)) / s.lever, zero);
  for (int e = 0; e < 3; ++e) {
    wa[e] -= turn_a[e];
    wb[e] += turn_b[e];
  }
  Lanes row_a[kLanes], row_b[kLanes];   // each lane's (v_z, w) back, v_z as it was read
  transpose(twist_a, row_a);
  transpose(twist_b, row_b);
  for (int l = 0; l < kLanes; ++l) {
    if (!moved[l]) continue;
    double* const at_a = v + g.offset_a[l] + 2;
    double* const at_b = v + g.offset_b[l] + 2;
    if (g.write_a[l]) std::memcpy(at_a, &row_a[l], sizeof(Lanes));
    if (g.write_b[l]) std::memcpy(at_b, &row_b[l], sizeof(Lanes));
  }
  progress.lanes_change = maximum(progress.lanes_change, size);   // (0 where not moved)
}

// The spin rows of the wide groups [lo, hi) of wave l, in order (inlined into sweep_chunk's
// clones).
WIDE void solve_wide_spins(SweepPlan& plan, size_t l, size_t lo, size_t hi, double* v,
                           Progress& progress) {
  for (size_t item = lo; item < hi; ++item) {
    const int32_t entry = plan.slot[plan.wave_groups[l] + item];
    if (plan.spin_groups[entry].wide)
      solve_wide_spin(plan.spin_groups[entry], plan.groups[entry], v, progress);
  }
}

// The plan's wide groups from the manifolds (pack_groups: plan.groups' entries, wave_groups,
// slot; pack_entry then fills an entry's fields that stay as prepared for the whole step,
// once per plan; refresh_entry writes the others). A group of the same manifolds in the
// same lanes as one in the pool since the rows were prepared (plan.rows_epoch) keeps its
// entry and kept elimination (the same fields from the same rows: the same bits); the
// others get new entries (SweepPlan::fresh). A wave's groups: its full ones, then its
// padded ones (each run of one row count in [wide_end, lone)).
// Lane l of group g an idle pad (WideGroup): its rows and frame zero, lane 0's bodies, not
// written.
void pad_lane(WideGroup& g, WideRow* w, WideFace& search, int l) {
  g.offset_a[l] = g.offset_a[0];
  g.offset_b[l] = g.offset_b[0];
  g.write_a[l] = g.write_b[l] = false;
  g.ma[l] = g.mb[l] = 0.0;
  g.invertible[l] = 0.0;
  for (int e = 0; e < 3; ++e) g.n[e][l] = g.t1[e][l] = g.t2[e][l] = 0.0;
  for (int i = 0; i < 4; ++i)
    for (int j = 0; j < 4; ++j)
      g.plain[i][j][l] = g.inverse[i][j][l] = search.delassus[i][j][l] = 0.0;
  for (int i = 0; i < 4; ++i) g.residual[i][l] = 0.0;
  for (int i = 0; i < g.count; ++i) {
    WideRow& r = w[i];
    for (int e = 0; e < 3; ++e) {
      r.kt[e][l] = 0.0;
      for (int d = 0; d < 3; ++d)
        r.ang_a[d][e][l] = r.ang_b[d][e][l] = r.dw_a[d][e][l] = r.dw_b[d][e][l] = 0.0;
    }
    r.normal_mass[l] = r.allowance[l] = r.mu[l] = 0.0;
    r.normal[l] = r.tangent[0][l] = r.tangent[1][l] = 0.0;
  }
}

// The numbers of a ContactRow from ang_a to dw_b (ang_a, ang_b, dw_a, dw_b: 36, in that
// order) are those of a WideRow's first 36 Lanes, in the same order; its frame (n, t1, t2:
// 9) those of a WideGroup's n, t1, t2.
constexpr size_t kHot = 36;
static_assert(sizeof(Vec3) == 3 * sizeof(double), "a Vec3 is its three numbers");
static_assert(offsetof(ContactRow, ma) - offsetof(ContactRow, ang_a) == kHot * sizeof(double),
              "ContactRow's levers and their images follow each other");
static_assert(offsetof(WideRow, normal_mass) == kHot * sizeof(Lanes),
              "WideRow's levers and their images come first, in the same order");
static_assert(offsetof(ContactRow, ang_a) - offsetof(ContactRow, n) == 9 * sizeof(double) &&
                  offsetof(WideGroup, t2) - offsetof(WideGroup, n) == 6 * sizeof(Lanes),
              "a frame's numbers follow each other, n, t1, t2");
// ... and so are the numbers from normal_mass on: normal_mass, kt (3), allowance, mu,
// normal, tangent (2)
template <typename Row, size_t kSize>
constexpr bool follows() {
  return offsetof(Row, kt) == offsetof(Row, normal_mass) + kSize &&
         offsetof(Row, allowance) == offsetof(Row, normal_mass) + 4 * kSize &&
         offsetof(Row, mu) == offsetof(Row, normal_mass) + 5 * kSize &&
         offsetof(Row, normal) == offsetof(Row, normal_mass) + 6 * kSize &&
         offsetof(Row, tangent) == offsetof(Row, normal_mass) + 7 * kSize;
}
static_assert(follows<ContactRow, sizeof(double)>() && follows<WideRow, sizeof(Lanes)>(),
              "ContactRow's and WideRow's numbers from normal_mass on follow each other alike");
// Four numbers of each of four rows from field `at` on (a byte offset), transposed into
// four Lanes from `to` on: the same values.
inline __attribute__((always_inline)) void transpose_rows(const ContactRow* const* c, size_t at,
                                                         Lanes* to) {
  const Lanes row[kLanes] = {
      load4(reinterpret_cast<const double*>(reinterpret_cast<const char*>(c[0]) + at)),
      load4(reinterpret_cast<const double*>(reinterpret_cast<const char*>(c[1]) + at)),
      load4(reinterpret_cast<const double*>(reinterpret_cast<const char*>(c[2]) + at)),
      load4(reinterpret_cast<const double*>(reinterpret_cast<const char*>(c[3]) + at))};
  transpose(row, to);
}

// pack_groups' fields of a group of four manifolds (no padding lane) that are read row by
// row: its matrices, its frame and its rows' constant fields, four numbers of each lane at
// a time (one load per lane, a 4x4 transpose, four stores), the same values.
COLLRES_CLONED
void pack_full(WideGroup& g, WideRow* w, WideFace& search, const std::vector<ContactRow>& rows,
               const std::vector<Manifold>& manifolds) {
  const Manifold* m[kLanes];
  for (int l = 0; l < kLanes; ++l) m[l] = &manifolds[g.manifold + static_cast<size_t>(l)];
  // a matrix's row i, four numbers (columns past g.count too: never read)
  const BlockMatrices* b[kLanes];
  for (int l = 0; l < kLanes; ++l) b[l] = m[l]->matrices;
  auto matrix = [&](double const (BlockMatrices::*of)[4][4], Lanes (*to)[4]) {
    for (int i = 0; i < g.count; ++i) {
      const Lanes row[kLanes] = {load4((b[0]->*of)[i]), load4((b[1]->*of)[i]),
                                 load4((b[2]->*of)[i]), load4((b[3]->*of)[i])};
      transpose(row, to[i]);
    }
  };
  matrix(&BlockMatrices::plain, g.plain);
  matrix(&BlockMatrices::inverse, g.inverse);
  matrix(&BlockMatrices::delassus, search.delassus);
  {
    const Lanes row[kLanes] = {load4(b[0]->residual), load4(b[1]->residual),
                               load4(b[2]->residual), load4(b[3]->residual)};
    transpose(row, g.residual);
  }
  const ContactRow* c[kLanes];
  for (int l = 0; l < kLanes; ++l) c[l] = &rows[static_cast<size_t>(m[l]->first)];
  transpose_rows(c, offsetof(ContactRow, n), g.n);   // the frame: n, t1.x
  transpose_rows(c, offsetof(ContactRow, n) + 4 * sizeof(double), g.t1 + 1);   // to t2.y
  for (int l = 0; l < kLanes; ++l) g.t2[2][l] = c[l]->t2[2];
  for (int i = 0; i < g.count; ++i) {
    for (int l = 0; l < kLanes; ++l) c[l] = &rows[static_cast<size_t>(m[l]->first + i)];
    for (size_t q = 0; q < kHot; q += 4)
      transpose_rows(c, offsetof(ContactRow, ang_a) + q * sizeof(double), w[i].ang_a[0] + q);
    transpose_rows(c, offsetof(ContactRow, normal_mass), &w[i].normal_mass);   // and kt
  }
}

void pack_groups(SweepPlan& plan, const std::vector<ContactRow>& rows,
                 const std::vector<Manifold>& manifolds) {
  if (plan.packed_epoch != plan.rows_epoch) {   // rows anew: an empty pool
    plan.packed_epoch = plan.rows_epoch;
    plan.pool_groups = plan.pool_rows = 0;
    plan.entry_at.assign(rows.size(), -1);
    plan.fresh.clear();
  }
  plan.wave_groups.assign(1, 0);
  plan.slot.clear();
  // the group of manifolds [m, m + lanes) (one row count)
  auto group = [&](size_t m, int lanes) {
    int32_t first[kLanes];
    for (int l = 0; l < kLanes; ++l)
      first[l] = l < lanes ? manifolds[m + static_cast<size_t>(l)].first : -1;
    int32_t entry = plan.entry_at[static_cast<size_t>(first[0])];
    if (entry < 0 || !std::equal(first, first + kLanes, plan.groups[entry].first)) {
      // a new entry (sized, not cleared: every field below is written)
      entry = static_cast<int32_t>(plan.pool_groups++);
      if (plan.groups.size() < plan.pool_groups) plan.groups.resize(plan.pool_groups);
      WideGroup& g = plan.groups[entry];
      g.count = manifolds[m].count;
      g.lanes = lanes;
      g.row = plan.pool_rows;
      plan.pool_rows += static_cast<size_t>(g.count);
      std::copy(first, first + kLanes, g.first);
      plan.entry_at[static_cast<size_t>(first[0])] = entry;
      if (plan.fresh.size() < plan.pool_groups) plan.fresh.resize(plan.pool_groups);
      plan.fresh[static_cast<size_t>(entry)] = 1;
    }
    plan.groups[entry].manifold = m;
    plan.slot.push_back(entry);
  };
  for (const SweepWave& c : plan.waves) {
    for (size_t m = c.first; m < c.wide_end; m += kLanes) group(m, kLanes);
    for (size_t m = c.wide_end, end = m; m < c.lone; m = end) {
      while (end < c.lone && manifolds[end].count == manifolds[m].count) ++end;
      group(m, static_cast<int>(end - m));
    }
    plan.wave_groups.push_back(plan.slot.size());
  }
  if (plan.wide_rows.size() < plan.pool_rows) plan.wide_rows.resize(plan.pool_rows);
  if (plan.faces.size() < plan.pool_groups) plan.faces.resize(plan.pool_groups);
  if (plan.spin_groups.size() < plan.pool_groups) plan.spin_groups.resize(plan.pool_groups);
}

// The constant fields of pool entry `entry` (pack_groups made it: SweepPlan::fresh), its
// kept elimination none.
void pack_entry(SweepPlan& plan, int32_t entry, const std::vector<ContactRow>& rows,
                const std::vector<Manifold>& manifolds, const double* inv_mass) {
  WideGroup& g = plan.groups[entry];
  WideFace& search = plan.faces[entry];
  for (int l = 0; l < kLanes; ++l) search.set[l] = -1;   // (nothing kept)
  const bool full = g.lanes == kLanes;
  if (full) pack_full(g, &plan.wide_rows[g.row], search, rows, manifolds);
  g.redundant = false;
  for (int l = 0; l < g.lanes; ++l) {
    const Manifold& m = manifolds[g.manifold + static_cast<size_t>(l)];
    g.offset_a[l] = 6 * static_cast<int64_t>(m.a);
    g.offset_b[l] = 6 * static_cast<int64_t>(m.b);
    g.write_a[l] = inv_mass[m.a] > 0.0;
    g.write_b[l] = inv_mass[m.b] > 0.0;
    const ContactRow* r = &rows[static_cast<size_t>(m.first)];
    g.ma[l] = r[0].ma;
    g.mb[l] = r[0].mb;
    g.invertible[l] = m.invertible && !m.coupled ? 1.0 : 0.0;
    g.redundant = g.redundant || m.redundant;
    if (full) continue;   // (the rest: pack_full)
    const BlockMatrices& b = *m.matrices;
    for (int i = 0; i < g.count; ++i)
      for (int j = 0; j < g.count; ++j) {
        g.plain[i][j][l] = b.plain[i][j];
        g.inverse[i][j][l] = b.inverse[i][j];
        search.delassus[i][j][l] = b.delassus[i][j];
      }
    for (int i = 0; i < g.count; ++i) g.residual[i][l] = b.residual[i];
    for (int e = 0; e < 3; ++e) {
      g.n[e][l] = r[0].n[e];
      g.t1[e][l] = r[0].t1[e];
      g.t2[e][l] = r[0].t2[e];
    }
    for (int i = 0; i < g.count; ++i) {
      WideRow& w = plan.wide_rows[g.row + static_cast<size_t>(i)];
      const ContactRow& c = r[i];
      for (int e = 0; e < 3; ++e) {
        for (int d = 0; d < 3; ++d) {
          w.ang_a[d][e][l] = c.ang_a[d][e];
          w.ang_b[d][e][l] = c.ang_b[d][e];
          w.dw_a[d][e][l] = c.dw_a[d][e];
          w.dw_b[d][e][l] = c.dw_b[d][e];
        }
        w.kt[e][l] = c.kt[e];
      }
      w.normal_mass[l] = c.normal_mass;
    }
  }
  for (int l = g.lanes; l < kLanes; ++l) pad_lane(g, &plan.wide_rows[g.row], search, l);
}

// The wide rows' fields that change between calls of solve_velocities in a step (the
// substeps' allowances, impulses, a friction coefficient hold_energy set to 0).
inline __attribute__((always_inline)) void refresh_entry(
    SweepPlan& plan, int32_t entry, const std::vector<ContactRow>& rows,
    const std::vector<Manifold>& manifolds) {
  const WideGroup& g = plan.groups[entry];
  if (g.lanes == kLanes) {   // allowance, mu, normal, tangent[0] four at a time
    WideRow* w = &plan.wide_rows[g.row];
    for (int i = 0; i < g.count; ++i) {
      const ContactRow* c[kLanes];
      for (int l = 0; l < kLanes; ++l) {
        const Manifold& m = manifolds[g.manifold + static_cast<size_t>(l)];
        c[l] = &rows[static_cast<size_t>(m.first + i)];
      }
      transpose_rows(c, offsetof(ContactRow, allowance), &w[i].allowance);
      for (int l = 0; l < kLanes; ++l) w[i].tangent[1][l] = c[l]->tangent[1];
    }
    return;
  }
  for (int l = 0; l < g.lanes; ++l) {   // (a padding lane stays zero)
    const Manifold& m = manifolds[g.manifold + static_cast<size_t>(l)];
    const ContactRow* r = &rows[static_cast<size_t>(m.first)];
    WideRow* w = &plan.wide_rows[g.row];
    for (int i = 0; i < g.count; ++i) {
      w[i].allowance[l] = r[i].allowance;
      w[i].mu[l] = r[i].mu;
    }
    rows_to_lane(r, g.count, w, l);
  }
}

// (pack_entry's spin rows: the fields that stay as prepared; refresh_spins the others)
void pack_spins(SweepPlan& plan, int32_t entry, const std::vector<Manifold>& manifolds,
                const std::vector<SpinRow>* spins) {
  const SpinRow none;   // (a lane without one: all zero)
  const WideGroup& g = plan.groups[entry];
  WideSpin& w = plan.spin_groups[entry];
  w.wide = false;
  for (int l = 0; l < kLanes; ++l) {
    w.spin[l] = spins != nullptr && l < g.lanes
                    ? manifolds[g.manifold + static_cast<size_t>(l)].spin : -1;
    w.wide = w.wide || w.spin[l] >= 0;
  }
  if (!w.wide) return;
  for (int l = 0; l < kLanes; ++l) {
    const SpinRow& r = w.spin[l] >= 0 ? (*spins)[w.spin[l]] : none;
    for (int e = 0; e < 3; ++e) {
      w.n[e][l] = r.n[e];
      for (int c = 0; c < 3; ++c) {
        w.inv_a[e][c][l] = r.inv_a(e, c);
        w.inv_b[e][c][l] = r.inv_b(e, c);
        w.inv_ab[e][c][l] = r.inv_ab(e, c);
      }
    }
    w.k_n[l] = r.k_n;
    w.lever[l] = r.lever;
  }
}

// (refresh_entry's spin rows: the substeps start them cold, hold_energy may zero a limit)
inline __attribute__((always_inline)) void refresh_spins(SweepPlan& plan, int32_t entry,
                                                        const std::vector<SpinRow>& spins) {
  const SpinRow none;   // (a lane without one: all zero)
  WideSpin& w = plan.spin_groups[entry];
  if (!w.wide) return;
  for (int l = 0; l < kLanes; ++l) {
    const SpinRow& r = w.spin[l] >= 0 ? spins[w.spin[l]] : none;
    for (int e = 0; e < 3; ++e) w.torque[e][l] = r.torque[e];
    w.roll[l] = r.roll;
    w.twist[l] = r.twist;
  }
}

// Part l's wide groups made ready for a solve's sweeps (in its first sweep, on the thread
// that sweeps them): an entry's constant fields once per plan (SweepPlan::fresh), the
// changing ones at every solve.
COLLRES_CLONED
void ready_part(SweepPlan& plan, size_t l, const std::vector<ContactRow>& rows,
                const std::vector<Manifold>& manifolds, const double* inv_mass,
                const std::vector<SpinRow>* spins) {
  for (size_t item = plan.wave_groups[l]; item < plan.wave_groups[l + 1]; ++item) {
    const int32_t entry = plan.slot[item];
    if (plan.fresh[static_cast<size_t>(entry)]) {
      pack_entry(plan, entry, rows, manifolds, inv_mass);
      pack_spins(plan, entry, manifolds, spins);
      plan.fresh[static_cast<size_t>(entry)] = 0;
    }
    refresh_entry(plan, entry, rows, manifolds);
    if (spins != nullptr) refresh_spins(plan, entry, *spins);
  }
}

// The wide rows' impulses back into the rows, the wide spin rows' torques into the spins.
void unpack_groups(const SweepPlan& plan, std::vector<ContactRow>& rows,
                   const std::vector<Manifold>& manifolds, std::vector<SpinRow>* spins) {
  for (const int32_t entry : plan.slot) {
    const WideGroup& g = plan.groups[entry];
    const WideSpin& w = plan.spin_groups[entry];
    for (int l = 0; l < g.lanes; ++l) {
      const Manifold& m = manifolds[g.manifold + static_cast<size_t>(l)];
      lane_to_rows(&plan.wide_rows[g.row], l, &rows[static_cast<size_t>(m.first)], g.count);
      if (spins != nullptr && w.spin[l] >= 0)
        (*spins)[w.spin[l]].torque = Vec3(w.torque[0][l], w.torque[1][l], w.torque[2][l]);
    }
  }
}

// The parts of a sweep's chunk (SweepChunk), in order: one call a chunk (the spin rows'
// updates inlined). `ready`: the solve's first sweep.
// Part l < the plan's waves (SweepWave): its wide groups (full, then padded; in the first
// sweep made ready first, on the thread that sweeps them), then its manifolds one by one.
// Else the spin rows of part l less the waves: its groups' in lanes (WideSpin), then its
// manifolds' one by one (a wave's spin rows share no movable body: the bits of their order;
// without wide groups, all of them one by one).
COLLRES_CLONED
void sweep_chunk(SweepPlan& plan, const SweepChunk& chunk, bool ready,
                 std::vector<ContactRow>& rows, const std::vector<Manifold>& manifolds,
                 const SolverBodies& bodies, std::vector<SpinRow>* spins, Progress& progress) {
  double* v = bodies.velocity;
  const size_t waves = plan.waves.size();
  for (uint32_t i = chunk.begin; i < chunk.end; ++i) {
    const auto p = static_cast<size_t>(plan.chunk_parts[i]);
    const size_t l = p < waves ? p : p - waves;
    const SweepWave& span = plan.waves[l];
    const size_t groups = plan.wide ? plan.wave_groups[l + 1] - plan.wave_groups[l] : 0;
    if (p >= waves) {   // spin parts (none to solve without spins)
      if (spins == nullptr) continue;
      if (groups > 0) solve_wide_spins(plan, l, 0, groups, v, progress);
      for (size_t m = groups > 0 ? span.lone : span.first; m < span.end; ++m) {
        const int32_t spin = manifolds[m].spin;
        if (spin >= 0)
          progress.change = std::max(progress.change,
                                     solve_spin((*spins)[spin], v, bodies.inv_mass));
      }
      continue;
    }
    if (groups > 0 && ready) ready_part(plan, l, rows, manifolds, bodies.inv_mass, spins);
    if (groups > 0) solve_groups(plan, l, 0, groups, rows, manifolds, v, spins, progress);
    const size_t lone = plan.wide ? span.lone : span.first;
    if (lone < span.end)   // (most parts have none one by one: no call)
      solve_manifolds(rows, manifolds, lone, span.end, bodies, spins, progress);
  }
}

#undef WIDE

// A sweep's work in chunks, in the sweep's order, for the two threads (Worker::run_sides;
// one thread runs them in turn): the parts of the waves before the seam's (SweepWave::seam)
// in the chunks of their side's queue, then their spin rows (if any) the same way, then
// the seam's parts and their spin rows (SweepPlan::sequence; waiting as SweepWave::after
// and spin_after say). A part joins its side's last chunk when it waits for no more of the
// other side's chunks than that chunk does at its start, and that chunk's last part is not
// one the other side waits for (a chunk ends with such a part, so that the wait ends with it): no
// part waits longer than alone in a chunk, and a side's run of parts between two waits is
// one hand-over (with two sides, each side's rows and spin rows wait for none: the seam's
// wait for side 0's last parts on their bodies). Run in turn (one thread), a chunk's parts
// go before the other side's parts between them, which share no movable body with them (a
// part that does waits for that part: it starts a chunk).
void plan_chunks(SweepPlan& plan) {
  plan.chunks.clear();
  plan.sides.clear();
  plan.needs.clear();
  const size_t size = plan.waves.size(), parts = plan.sequence.size();
  // part p: the rows of wave part p (p < size), or the spin rows of part p - size
  auto after = [&](size_t p) {
    return p < size ? plan.waves[p].after : plan.waves[p - size].spin_after;
  };
  plan.awaited.assign(parts, 0);
  for (size_t p = 0; p < parts; ++p)
    if (after(p) >= 0) plan.awaited[static_cast<size_t>(after(p))] = 1;
  plan.places.resize(parts);
  plan.owner.resize(parts);
  int32_t queued[2] = {0, 0};   // chunks per side so far
  int32_t open[2] = {-1, -1};   // each side's chunk that a part may join (-1: none)
  for (const int32_t q : plan.sequence) {
    const auto p = static_cast<size_t>(q);
    const int32_t side = plan.waves[p % size].side, waits = after(p);
    const int32_t need = waits < 0 ? 0 : plan.places[static_cast<size_t>(waits)] + 1;
    if (open[side] < 0 || need > plan.needs[static_cast<size_t>(open[side])]) {
      open[side] = static_cast<int32_t>(plan.chunks.size());
      plan.chunks.push_back({});
      plan.needs.push_back(need);
      plan.sides.push_back(static_cast<uint8_t>(side));
      ++queued[side];
    }
    plan.places[p] = queued[side] - 1;
    plan.owner[p] = open[side];
    if (plan.awaited[p]) open[side] = -1;
  }
  // each chunk's parts, in sweep order (a counting sort by chunk)
  for (size_t p = 0; p < parts; ++p) ++plan.chunks[static_cast<size_t>(plan.owner[p])].end;
  uint32_t at = 0;
  for (SweepChunk& chunk : plan.chunks) {
    chunk.begin = at;
    at += chunk.end;
    chunk.end = chunk.begin;
  }
  plan.chunk_parts.resize(parts);
  for (const int32_t q : plan.sequence) {
    SweepChunk& chunk = plan.chunks[static_cast<size_t>(plan.owner[static_cast<size_t>(q)])];
    plan.chunk_parts[chunk.end++] = q;
  }
}

}  // namespace

void repack(SweepPlan& plan, const uint8_t* changed) {
  plan.packed = false;
  if (plan.packed_epoch != plan.rows_epoch) return;   // (no entry of these rows yet)
  for (int32_t entry = 0; entry < static_cast<int32_t>(plan.pool_groups); ++entry) {
    const WideGroup& g = plan.groups[static_cast<size_t>(entry)];
    bool any = false;
    for (int l = 0; l < g.lanes && !any; ++l) any = changed[g.first[l]] != 0;
    int32_t& at = plan.entry_at[static_cast<size_t>(g.first[0])];
    if (any && at == entry) at = -1;
  }
}

int solve_velocities(std::vector<ContactRow>& rows, const std::vector<Manifold>& manifolds,
                     SolverBodies& bodies, int iterations, double converged,
                     std::vector<SpinRow>* spins, SweepPlan* plan) {
  const size_t count = manifolds.size(), spin_count = spins != nullptr ? spins->size() : 0;
  const bool wide = plan != nullptr && plan->wide;
  if (wide && !plan->packed) {   // (the groups' fields: in the first sweep, part by part)
    pack_groups(*plan, rows, manifolds);
    plan->packed = true;
  }
  int done = 0;
  if (plan != nullptr) plan_chunks(*plan);
  const size_t chunks = plan != nullptr ? plan->chunks.size() : 0;
  // (per chunk: a chunk's part runs on either thread)
  std::vector<Progress> part(std::max<size_t>(chunks, 1));
  // chunk c of the sweep: its parts' rows or spin rows
  const std::function<void(int)> chunk = [&](int c) {
    sweep_chunk(*plan, plan->chunks[static_cast<size_t>(c)], done == 1, rows, manifolds, bodies,
                spins, part[static_cast<size_t>(c)]);
  };
  while (done < iterations) {
    ++done;
    std::fill(part.begin(), part.end(), Progress());
    if (plan == nullptr) {
      solve_manifolds(rows, manifolds, 0, count, bodies, spins, part[0]);
    } else if (plan->worker != nullptr) {
      // (kind 3: a solve's first sweep, which also readies the parts' groups: it costs
      // 2-4 times a later sweep per manifold, in either mode; kind 0 the later ones)
      plan->worker->run_sides(chunk, static_cast<int>(chunks), plan->sides.data(),
                              plan->needs.data(), done == 1 ? 3 : 0, static_cast<double>(count));
    } else {
      for (size_t c = 0; c < chunks; ++c) chunk(static_cast<int>(c));
    }
    if (spins != nullptr && plan == nullptr) solve_spins(*spins, 0, spin_count, bodies, part[0]);
    double change = 0.0, largest = 0.0;
    for (const Progress& p : part) {
      change = std::max(change, p.change);
      largest = std::max(largest, p.largest);
      for (int l = 0; l < kLanes; ++l) {
        change = std::max(change, p.lanes_change[l]);
        largest = std::max(largest, p.lanes_largest[l]);
      }
    }
    if (change <= converged * largest) break;
  }
  if (wide && done > 0) unpack_groups(*plan, rows, manifolds, spins);   // (none: as they were)
  return done;
}

// The row as its upper body sees it while the lower one is held by what it rests on
// (shock propagation, the push-out's one-sided rows): the lower body's inverse mass and
// inverse inertia zeroed, the normal and friction effective masses recomputed. False when
// the upper body cannot move along the normal (the row then does nothing).
static bool hold_lower(ContactRow& r, bool upper_b) {
  if (upper_b) {
    r.ma = 0.0;
    for (int k = 0; k < 3; ++k) r.dw_a[k] = Vec3::Zero();
  } else {
    r.mb = 0.0;
    for (int k = 0; k < 3; ++k) r.dw_b[k] = Vec3::Zero();
  }
  double k_n = r.ma + r.mb + dot(r.ang_a[0], r.dw_a[0]) + dot(r.ang_b[0], r.dw_b[0]);
  if (!(k_n > kTiny)) return false;
  r.normal_mass = 1.0 / k_n;
  auto block = [&](int i, int j) {
    return (i == j ? r.ma + r.mb : 0.0) + dot(r.ang_a[i], r.dw_a[j]) +
           dot(r.ang_b[i], r.dw_b[j]);
  };
  r.kt[0] = block(1, 1);
  r.kt[1] = block(1, 2) + block(2, 1);
  r.kt[2] = block(2, 2);
  return true;
}

void shock_rows(const std::vector<ContactRow>& rows, const std::vector<int32_t>& level,
                std::vector<int32_t>& order, std::vector<ContactRow>& scratch,
                ShockBlocks& shock, std::vector<uint8_t>& holding, double ratio, bool wide) {
  order.clear();
  for (size_t r = 0; r < rows.size(); ++r) {
    const ContactRow& row = rows[r];
    int32_t la = level[row.a], lb = level[row.b];
    if (row.bounce || la < 0 || lb < 0 || la == lb) continue;
    // only on an immovable body or where the upper body is at least `ratio` times
    // heavier than the lower one
    const double inv_upper = la > lb ? row.ma : row.mb, inv_lower = la > lb ? row.mb : row.ma;
    if (inv_lower == 0.0 || inv_upper * ratio <= inv_lower)
      order.push_back(static_cast<int32_t>(r));
  }
  // by lower level, stably (a counting sort: levels are small non-negative integers)
  auto lower = [&](int32_t i) { return std::min(level[rows[i].a], level[rows[i].b]); };
  int32_t top = -1;
  for (const int32_t i : order) top = std::max(top, lower(i));
  std::vector<size_t> start(static_cast<size_t>(top) + 2, 0);
  for (const int32_t i : order) ++start[static_cast<size_t>(lower(i)) + 1];
  for (size_t l = 1; l < start.size(); ++l) start[l] += start[l - 1];
  std::vector<int32_t> by_level(order.size());
  for (const int32_t i : order) by_level[start[static_cast<size_t>(lower(i))]++] = i;
  order.swap(by_level);
  // the rows between levels L and L + 1 see the bodies below as fixed: copies of the rows
  // with the lower body's inverse mass and inertia zeroed
  scratch.clear();
  for (int32_t index : order) {
    ContactRow r = rows[index];
    if (!hold_lower(r, level[r.b] > level[r.a])) continue;
    r.contact = index;               // (the row it stands for, while it is a copy)
    scratch.push_back(r);
  }
  // a manifold's copies on an immovable body (consecutive: the sort is stable) are one
  // block, solved as the sweeps solve a manifold, whatever the order of its points (a
  // mirror-symmetric hit on a wall gets mirror-symmetric impulses); a row whose lower
  // body is held, and the rows under a body that holds another, stay one by one (a
  // manifold's block friction in two sweeps let a 1000 kg box slide 20 mm on a 1 kg one
  // at 240 Hz; the 1 kg box stopped exactly on the floor under it, the 1000 kg box
  // tilted on it and rose by 1.6 um in the first two steps)
  holding.assign(level.size(), 0);
  auto held = [&](const ContactRow& r) {
    return (level[r.b] > level[r.a] ? rows[r.contact].ma : rows[r.contact].mb) != 0.0;
  };
  for (const ContactRow& r : scratch)
    if (held(r)) holding[level[r.b] > level[r.a] ? r.a : r.b] = 1;
  std::vector<Manifold>& blocks = shock.blocks;
  blocks.clear();
  for (size_t j = 0; j < scratch.size(); ++j) {
    const ContactRow& r = scratch[j];
    const bool alone = held(r) || holding[level[r.b] > level[r.a] ? r.b : r.a];
    if (j == 0 || alone || r.manifold != scratch[j - 1].manifold || blocks.back().count == 4) {
      blocks.emplace_back();
      blocks.back().a = r.a;
      blocks.back().b = r.b;
      blocks.back().first = static_cast<int32_t>(j);
    }
    ++blocks.back().count;
  }
  fit_matrices(shock.matrices, blocks);
  for (size_t j = 0; j < blocks.size(); ++j)
    prepare_block(blocks[j], &scratch[blocks[j].first], shock.matrices[j]);
  // each lower level's blocks in waves: a body's blocks in their order (its inverse mass
  // as its rows had it before the copies held the lower one: a held body is movable, so
  // the blocks on it stay in order too)
  shock.inv_mass.assign(level.size(), 0.0);
  for (const ContactRow& r : scratch) {
    shock.inv_mass[r.a] = rows[r.contact].ma;
    shock.inv_mass[r.b] = rows[r.contact].mb;
  }
  auto lower_of = [&](const Manifold& m) { return std::min(level[m.a], level[m.b]); };
  WaveScratch waves;
  std::vector<int32_t> chosen;
  size_t levels = 0;
  for (size_t lo = 0; lo < blocks.size(); ++levels) {
    size_t hi = lo;
    chosen.clear();
    for (; hi < blocks.size() && lower_of(blocks[hi]) == lower_of(blocks[lo]); ++hi)
      chosen.push_back(static_cast<int32_t>(hi));
    if (shock.plans.size() <= levels) shock.plans.resize(levels + 1);
    if (shock.levels.size() <= levels) shock.levels.resize(levels + 1);
    SweepPlan& plan = shock.plans[levels];
    plan.wide = wide;
    ++plan.rows_epoch;   // (new rows: nothing of the last pool kept)
    wave_manifolds(blocks, chosen, scratch, shock.inv_mass.data(),
                   static_cast<int64_t>(level.size()), plan, shock.levels[levels], waves);
    lo = hi;
  }
  shock.levels.resize(levels);
}

void propagate_shock(std::vector<ContactRow>& rows, SolverBodies& bodies,
                     const std::vector<int32_t>& level, std::vector<ContactRow>& scratch,
                     ShockBlocks& shock, int sweeps) {
  const double* v = bodies.velocity;
  // the copies take the fields that change within a step from the rows they stand for
  for (ContactRow& r : scratch) {
    const ContactRow& row = rows[r.contact];
    r.allowance = row.allowance;
    r.mu = row.mu;
    r.normal = row.normal;
    r.tangent[0] = row.tangent[0];
    r.tangent[1] = row.tangent[1];
  }
  for (size_t l = 0; l < shock.levels.size(); ++l) {
    const std::vector<Manifold>& blocks = shock.levels[l];
    // the lower body moving towards the upper one does not push it (no energy gain): only
    // the upper body's own approach is stopped, each row's allowance the larger by the
    // lower body's approach while the level is swept (a held lower body: its blocks leave
    // its twist as it was)
    shock.allowance.clear();
    for (const Manifold& m : blocks) {
      const bool upper_b = level[m.b] > level[m.a];
      const int32_t low = upper_b ? m.a : m.b;
      for (int i = 0; i < m.count; ++i) {
        ContactRow& r = scratch[static_cast<size_t>(m.first + i)];
        const double towards = (upper_b ? 1.0 : -1.0) *
                               (dot(lin(v, low), r.n) +
                                dot(ang(v, low), upper_b ? r.ang_a[0] : r.ang_b[0]));
        shock.allowance.push_back(r.allowance);
        r.allowance += std::max(towards, 0.0);
      }
    }
    // `sweeps` sweeps (a threshold below every change: never converged before)
    solve_velocities(scratch, blocks, bodies, sweeps, -std::numeric_limits<double>::infinity(),
                     nullptr, &shock.plans[l]);
    size_t at = 0;
    for (const Manifold& m : blocks)
      for (int i = 0; i < m.count; ++i)
        scratch[static_cast<size_t>(m.first + i)].allowance = shock.allowance[at++];
  }
  for (const ContactRow& r : scratch) {
    ContactRow& kept = rows[r.contact];
    kept.normal = r.normal;
    kept.tangent[0] = r.tangent[0];
    kept.tangent[1] = r.tangent[1];
  }
}

// The bodies' support in the impact stages (shock propagation): each body's touching
// level, its distance from an immovable body over touching rows (no allowance: a
// speculative row holds nothing yet), -1 where no chain of touching rows reaches one, and
// per body its touching rows to a body one level below (what holds it up).
struct ImpactSupport {
  std::vector<int32_t> level, first, below, queue;

  void find(const std::vector<ContactRow>& rows, const SolverBodies& bodies) {
    const size_t n = static_cast<size_t>(bodies.count);
    auto touching = [](const ContactRow& r) { return !(r.allowance > 0.0); };
    // the touching rows' graph (CSR in `first` / `below`), breadth first from the
    // immovable bodies in it
    first.assign(n + 1, 0);
    for (const ContactRow& r : rows)
      if (touching(r)) {
        ++first[static_cast<size_t>(r.a) + 1];
        ++first[static_cast<size_t>(r.b) + 1];
      }
    for (size_t i = 0; i < n; ++i) first[i + 1] += first[i];
    below.resize(static_cast<size_t>(first[n]));
    queue.assign(first.begin(), first.end() - 1);   // fill cursor per body
    for (size_t i = 0; i < rows.size(); ++i)
      if (touching(rows[i])) {
        below[static_cast<size_t>(queue[rows[i].a]++)] = static_cast<int32_t>(i);
        below[static_cast<size_t>(queue[rows[i].b]++)] = static_cast<int32_t>(i);
      }
    level.assign(n, -1);
    queue.clear();
    for (size_t i = 0; i < n; ++i)
      if (bodies.inv_mass[i] == 0.0 && first[i + 1] > first[i]) {
        level[i] = 0;
        queue.push_back(static_cast<int32_t>(i));
      }
    for (size_t head = 0; head < queue.size(); ++head) {
      const int32_t i = queue[head];
      for (int32_t k = first[i]; k < first[i + 1]; ++k) {
        const ContactRow& r = rows[static_cast<size_t>(below[static_cast<size_t>(k)])];
        const int32_t j = r.a == i ? r.b : r.a;
        if (level[j] < 0) {
          level[j] = level[i] + 1;
          queue.push_back(j);
        }
      }
    }
  }

  // Whether a stage's row `r` sees its lower body held: the lower body is supported
  // (level >= 1), the upper one is not supported at the same or a lower level (free, or
  // above it), the upper body is at least `ratio` times heavier, and the push on the
  // lower body (along the row's normal, away from the upper body) lies inside the
  // friction cone of one of the lower body's touching rows to the level below, so what
  // holds the lower body up takes the push. A push outside every support's cone (a
  // sideways hit) moves the lower body. `upper_b`: whether B is the upper body.
  bool held(const ContactRow& r, const std::vector<ContactRow>& rows, double ratio,
            bool& upper_b) const {
    const int32_t la = level[r.a], lb = level[r.b];
    if (la == lb || (la < 1 && lb < 1)) return false;
    upper_b = la >= 1 && (lb < 0 || lb > la);
    const int32_t low = upper_b ? r.a : r.b;
    const double inv_upper = upper_b ? r.mb : r.ma, inv_lower = upper_b ? r.ma : r.mb;
    if (level[low] < 1 || inv_upper == 0.0 || inv_lower == 0.0 || inv_upper * ratio > inv_lower)
      return false;
    const Vec3 push = upper_b ? Vec3(-r.n) : Vec3(r.n);
    for (int32_t k = first[low]; k < first[low + 1]; ++k) {
      const ContactRow& s = rows[static_cast<size_t>(below[static_cast<size_t>(k)])];
      const int32_t other = s.a == low ? s.b : s.a;
      if (level[other] != level[low] - 1) continue;
      // the support's normal from the lower body into what holds it
      const Vec3 into = s.a == low ? Vec3(s.n) : Vec3(-s.n);
      const double along = dot(push, into);
      if (along > 0.0 && length(push - along * into) <= s.mu * along) return true;
    }
    return false;
  }
};

namespace {

// A stage's manifold with no touching row (all speculative: its gap closes later in the
// step) waits for a later stage if one of its movable bodies is in a touching manifold of
// the stage: that impact comes first and may turn the body away (a cradle's striker,
// stopped by the first ball, never reaches the second, which the step's motion alone
// would have put within its reach)
void hold_back_gaps(const std::vector<ContactRow>& rows, const SolverBodies& bodies,
                    std::vector<int32_t>& members, std::vector<uint8_t>& struck) {
  int32_t last = 0;
  for (const int32_t i : members) last = std::max({last, rows[i].a, rows[i].b});
  struck.assign(static_cast<size_t>(last) + 1, 0);
  bool any = false;
  auto each_manifold = [&](auto&& visit) {
    for (size_t lo = 0; lo < members.size();) {
      size_t hi = lo;
      bool touches = false;
      for (; hi < members.size() && rows[members[hi]].manifold == rows[members[lo]].manifold;
           ++hi)
        if (!(rows[members[hi]].allowance > 0.0)) touches = true;
      visit(lo, hi, touches);
      lo = hi;
    }
  };
  each_manifold([&](size_t lo, size_t, bool touches) {
    if (!touches) return;
    const ContactRow& r = rows[members[lo]];
    struck[r.a] = struck[r.b] = 1;
    any = true;
  });
  if (!any) return;
  size_t kept = 0;
  each_manifold([&](size_t lo, size_t hi, bool touches) {
    const ContactRow& r = rows[members[lo]];
    const bool waits = !touches && ((struck[r.a] && bodies.inv_mass[r.a] > 0.0) ||
                                    (struck[r.b] && bodies.inv_mass[r.b] > 0.0));
    for (size_t j = lo; j < hi && !waits; ++j) members[kept++] = members[j];
  });
  members.resize(kept);
}

// A stage row's velocity along n, t1, t2 as its impulses move the bodies (`row`: the row
// it copies): a row whose lower body is held (shock propagation) pushes its upper body
// only, so the energy its impulses take or return is the upper body's alone, measured
// with the held body's twist left out (the held body moving, its friction and its
// approach could otherwise drive the upper body and the stage's energy budget would count
// that work as taken from it)
void stage_velocity(const ContactRow& c, const ContactRow& row, const double* v,
                    double out[3]) {
  row_velocity(c, v, out);
  const bool held_a = c.ma == 0.0 && row.ma != 0.0, held_b = c.mb == 0.0 && row.mb != 0.0;
  for (int k = 0; k < 3 && (held_a || held_b); ++k) {
    const Vec3 d = direction(c, k);
    using collres::dot;   // (the Vec3 one: this namespace's is for lanes)
    if (held_a) out[k] += dot(lin(v, c.a), d) + dot(ang(v, c.a), c.ang_a[k]);
    if (held_b) out[k] -= dot(lin(v, c.b), d) + dot(ang(v, c.b), c.ang_b[k]);
  }
}

}  // namespace

int resolve_impacts(std::vector<ContactRow>& rows, SolverBodies& bodies,
                    const ImpactSettings& settings, std::vector<ContactRow>& scratch,
                    std::vector<Manifold>& blocks, std::vector<BlockMatrices>& matrices,
                    std::vector<int32_t>& members, std::vector<double>& work) {
  double* v = bodies.velocity;
  ImpactSupport support;   // found when a first stage has rows
  std::vector<uint8_t> struck;
  int stage = 0;
  for (; stage < settings.stages; ++stage) {
    members.clear();
    for (size_t i = 0; i < rows.size(); ++i) {
      const ContactRow& r = rows[i];
      if (!(r.normal_mass > 0.0)) continue;
      double u = relative(r, v, 0, r.n);
      if (u < -settings.threshold[r.contact] - kSlowest && u + r.allowance < 0.0)
        members.push_back(static_cast<int32_t>(i));
    }
    if (members.empty()) break;
    hold_back_gaps(rows, bodies, members, struck);
    if (stage == 0) support.find(rows, bodies);
    // the stage's rows (copies, in row order: a manifold's rows stay one block), from zero
    const size_t k = members.size();
    scratch.clear();
    blocks.clear();
    work.assign(19 * k, 0.0);   // per row: velocity before (n, t1, t2), after the
                                // compression (n, t1, t2), restitution impulse; then
                                // A's and B's twists before the stage (12 per row)
    double* saved = &work[7 * k];
    for (size_t j = 0; j < k; ++j) {
      ContactRow c = rows[members[j]];
      std::copy(v + 6 * c.a, v + 6 * c.a + 6, saved + 12 * j);
      std::copy(v + 6 * c.b, v + 6 * c.b + 6, saved + 12 * j + 6);
      c.normal = c.tangent[0] = c.tangent[1] = 0.0;
      c.allowance = 0.0;          // a speculative row that closes bounces off its approach
      bool upper_b = false;
      if (support.held(c, rows, settings.shock_ratio, upper_b)) {
        // the lower body held: the upper one stops (and bounces) on it in this stage,
        // instead of passing a share m_light / m_heavy of its momentum per pair of
        // stages down the chain. The lower body moving towards the upper one does not
        // push it (no energy gain): only the upper body's own approach is stopped
        const int32_t low = upper_b ? c.a : c.b;
        const double towards = (upper_b ? 1.0 : -1.0) *
                               (dot(lin(v, low), c.n) +
                                dot(ang(v, low), upper_b ? c.ang_a[0] : c.ang_b[0]));
        ContactRow held = c;
        if (hold_lower(held, upper_b)) {
          c = held;
          c.allowance = std::max(towards, 0.0);
        }
      }
      stage_velocity(c, rows[members[j]], v, &work[7 * j]);
      if (j == 0 || c.manifold != rows[members[j - 1]].manifold) {
        blocks.emplace_back();
        blocks.back().a = c.a;
        blocks.back().b = c.b;
        blocks.back().first = static_cast<int32_t>(j);
        blocks.back().coupled = true;
        blocks.back().search = true;
      }
      ++blocks.back().count;
      scratch.push_back(c);
    }
    fit_matrices(matrices, blocks);
    for (size_t j = 0; j < blocks.size(); ++j)
      prepare_block(blocks[j], &scratch[blocks[j].first], matrices[j]);
    // exact inelastic compression with friction; the energy it took (J). Coulomb
    // friction on coupled points can return energy (a slip turned around); such a stage
    // is compressed again without friction, and if it still gains, without holding
    // any body (below): a projection, which never gains
    double taken = 0.0;
    for (int attempt = 0; attempt < 3; ++attempt) {
      solve_velocities(scratch, blocks, bodies, settings.sweeps, settings.converged);
      taken = 0.0;
      for (size_t j = 0; j < k; ++j) {
        const ContactRow& c = scratch[j];
        double* w = &work[7 * j];
        stage_velocity(c, rows[members[j]], v, w + 3);
        taken -= 0.5 * (c.normal * (w[0] + w[3]) + c.tangent[0] * (w[1] + w[4]) +
                        c.tangent[1] * (w[2] + w[5]));
      }
      if (taken >= 0.0 || attempt == 2) break;
      for (size_t j = k; j-- > 0;) {       // undo: the twists before the stage
        const ContactRow& c = scratch[j];
        std::copy(saved + 12 * j, saved + 12 * j + 6, v + 6 * c.a);
        std::copy(saved + 12 * j + 6, saved + 12 * j + 12, v + 6 * c.b);
      }
      for (ContactRow& c : scratch) c.mu = c.normal = c.tangent[0] = c.tangent[1] = 0.0;
      if (attempt == 0) continue;
      // still a gain without friction: a held body that another row of the stage drives
      // into its upper body pushes that one at no cost of its own (coal's clusters on a
      // floor: +50 J of 3364). Last, every row with its own bodies' masses, no body held:
      // a projection, which never gains
      for (size_t j = 0; j < k; ++j) {
        ContactRow& c = scratch[j];
        const ContactRow& row = rows[members[j]];
        if (c.ma == row.ma && c.mb == row.mb) continue;
        c = row;
        c.mu = c.normal = c.tangent[0] = c.tangent[1] = c.allowance = 0.0;
        row_velocity(c, v, &work[7 * j]);
      }
      for (size_t j = 0; j < blocks.size(); ++j)
        prepare_block(blocks[j], &scratch[blocks[j].first], matrices[j]);
    }
    // restitution: e times the compression impulse along each normal (per object: A's
    // and B's own e); the energy it returns, linear + quadratic in a common scale s
    for (size_t j = 0; j < k; ++j) {
      const ContactRow& c = scratch[j];
      if (c.e_a == c.e_b) {
        work[7 * j + 6] = c.e_a * c.normal;
        if (work[7 * j + 6] != 0.0) apply(c, v, 0, c.n, work[7 * j + 6]);
        continue;
      }
      const double d_a = c.e_a * c.normal, d_b = c.e_b * c.normal;
      double* va = v + 6 * c.a;
      double* vb = v + 6 * c.b;
      store3(va, lin(v, c.a) - (d_a * c.ma) * c.n);
      store3(va + 3, ang(v, c.a) - d_a * c.dw_a[0]);
      store3(vb, lin(v, c.b) + (d_b * c.mb) * c.n);
      store3(vb + 3, ang(v, c.b) + d_b * c.dw_b[0]);
    }
    double linear = 0.0, returned = 0.0;
    for (size_t j = 0; j < k; ++j) {
      const double r = work[7 * j + 6];
      if (r == 0.0) continue;
      double after[3];
      stage_velocity(scratch[j], rows[members[j]], v, after);
      linear += r * work[7 * j + 3];
      returned += 0.5 * r * (work[7 * j + 3] + after[0]);
    }
    double scale = 1.0;
    if (returned > std::max(taken, 0.0)) {
      // largest s in [0, 1] with  linear s + quadratic s^2 <= taken
      const double quadratic = returned - linear, budget = std::max(taken, 0.0);
      scale = 0.0;
      if (quadratic > 0.0) {
        scale = (-linear + std::sqrt(std::max(linear * linear + 4.0 * quadratic * budget,
                                              0.0))) / (2.0 * quadratic);
      } else if (linear > 0.0) {
        scale = budget / linear;
      }
      scale = std::clamp(scale, 0.0, 1.0);
      for (size_t j = 0; j < k; ++j) {
        const double r = work[7 * j + 6];
        if (r != 0.0) apply(scratch[j], v, 0, scratch[j].n, (scale - 1.0) * r);
      }
    }
    for (size_t j = 0; j < k; ++j) {
      const ContactRow& c = scratch[j];
      ContactRow& kept = rows[members[j]];
      const double restitution = c.e_a == c.e_b ? scale * work[7 * j + 6]
                                                : 0.5 * (c.e_a + c.e_b) * c.normal;
      kept.impact += c.normal + restitution;
      kept.impact_tangent[0] += c.tangent[0];
      kept.impact_tangent[1] += c.tangent[1];
      kept.bounce = kept.bounce || c.normal > 0.0;
    }
    // a stage that ended without impulse (its sweeps cycled through zero: a manifold's
    // friction lifting its own normal rows) left the velocities as they were: the next
    // one would do the same
    bool carried = false;
    for (const ContactRow& c : scratch) carried = carried || c.normal > 0.0;
    if (!carried) return stage + 1;
  }
  return stage;
}

bool solve_positions(std::vector<ContactRow>& rows, const SolverBodies& bodies,
                     const std::vector<int32_t>& level, double ratio, double* pseudo,
                     int iterations, int fixed_sweeps, int deep_sweeps, double deep_push) {
  std::fill(pseudo, pseudo + 6 * bodies.count, 0.0);
  bool any = false;
  for (ContactRow& r : rows) {
    r.pseudo = 0.0;
    any = any || r.push > 0.0;
  }
  if (!any) return false;
  // each swept row as its sweeps see it, found once: the row itself, or (a row between
  // two levels whose upper body is at least `ratio` times heavier than the lower one, any
  // row between two levels in the deep sweeps) a copy with the lower body held, so that it
  // pushes the upper body only (as propagate_shock): the lower one is held by what it
  // rests on, so the push cannot drive it into that. A held row that cannot move its upper
  // body along the normal is left out (it does nothing).
  std::vector<ContactRow> held;
  auto seen = [&](std::vector<std::pair<int32_t, int32_t>>& out, int32_t i, bool deep) {
    const ContactRow& r = rows[static_cast<size_t>(i)];
    const int32_t la = level[r.a], lb = level[r.b];
    const bool upper_b = la >= 0 && lb > la, upper_a = lb >= 0 && la > lb;
    const double inv_upper = upper_b ? r.mb : r.ma, inv_lower = upper_b ? r.ma : r.mb;
    if (!((upper_a || upper_b) && inv_lower > 0.0 && (deep || inv_upper * ratio <= inv_lower))) {
      out.emplace_back(i, -1);
      return;
    }
    ContactRow copy = r;
    if (!hold_lower(copy, upper_b)) return;
    out.emplace_back(i, static_cast<int32_t>(held.size()));
    held.push_back(copy);
  };
  // (row, its held copy or -1): every row; the rows on an immovable body; the deep rows
  std::vector<std::pair<int32_t, int32_t>> every, fixed, deep;
  for (int32_t i = 0; i < static_cast<int32_t>(rows.size()); ++i) {
    const ContactRow& r = rows[static_cast<size_t>(i)];
    const bool immovable = r.ma == 0.0 || r.mb == 0.0;
    seen(every, i, false);
    if (immovable && fixed_sweeps > 0 && !every.empty() && every.back().first == i)
      fixed.push_back(every.back());
    if (!immovable && deep_sweeps > 0 && r.push > deep_push) seen(deep, i, true);
  }
  auto sweeps = [&](const std::vector<std::pair<int32_t, int32_t>>& swept, int count) {
    for (int it = 0; it < count; ++it)
      for (const auto& [i, h] : swept) {
        ContactRow& r = rows[static_cast<size_t>(i)];
        const ContactRow& as = h < 0 ? r : held[static_cast<size_t>(h)];
        const double v_n = relative(as, pseudo, 0, as.n);
        const double updated = std::max(r.pseudo + as.normal_mass * (r.push - v_n), 0.0);
        const double delta = updated - r.pseudo;
        r.pseudo = updated;
        if (delta != 0.0) apply(as, pseudo, 0, as.n, delta);
      }
  };
  sweeps(every, iterations);
  sweeps(fixed, fixed_sweeps);
  if (deep_sweeps > 0) {
    sweeps(deep, deep_sweeps);
    sweeps(fixed, fixed_sweeps);
  }
  return true;
}

}  // namespace collres
