#include "detection.h"

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <thread>

namespace collres {

namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();
// A feature id is the corner code of both pieces (< 729), the rank among equal codes (< the
// points of a patch) times 729, and the piece pair times kPiecePairFeature: unique within a
// pair of bodies, and the same as before compounds for a body of one shape (piece 0).
constexpr std::int64_t kPiecePairFeature = 729 * 64;
constexpr std::int64_t kMaxPieces = 1 << 20;

bool finite(const double* v, int count) {
  for (int k = 0; k < count; ++k) {
    if (!std::isfinite(v[k])) return false;
  }
  return true;
}

double angle_between(const Quat& a, const Quat& b) {
  return 2.0 * std::acos(std::min(1.0, std::abs(a.dot(b))));
}

}  // namespace

void ContactRows::reserve(std::size_t rows) {
  each_row_column([rows](auto& column, std::size_t width) { column.reserve(width * rows); });
  manifolds.reserve(kManifoldFields * rows);
}

void ContactRows::close_manifold(std::int64_t a, std::int64_t b, std::size_t first) {
  if (size() > first) {
    manifolds.push_back(a);
    manifolds.push_back(b);
    manifolds.push_back(static_cast<std::int64_t>(first));
    manifolds.push_back(static_cast<std::int64_t>(size() - first));
  }
}

void ContactRows::drop_from(std::size_t first) { rows_ = first; }

void ContactRows::trim() { resize_columns(rows_); }

// Room for kRoomRows more rows or `count` if more (zeros, overwritten by `add` and `put`):
// one resize per column per kRoomRows rows, within the reserved capacity for a step's
// usual rows.
void ContactRows::make_room(std::size_t count) {
  constexpr std::size_t kRoomRows = 64;
  resize_columns(rows_ + std::max(count, kRoomRows));
}

void ContactRows::set_kind(std::size_t first, ContactKind contact) {
  std::fill(kind.begin() + static_cast<std::ptrdiff_t>(first),
            kind.begin() + static_cast<std::ptrdiff_t>(rows_), static_cast<std::int8_t>(contact));
}

void ContactRows::resize_columns(std::size_t rows) {
  each_row_column([rows](auto& column, std::size_t width) { column.resize(width * rows); });
}

void ContactRows::keep(const std::vector<std::size_t>& rows) {
  // each manifold's kept rows, counted before the columns are compacted
  std::size_t to = 0, next = 0;
  for (std::size_t k = 0; k < manifolds.size(); k += kManifoldFields) {
    const auto end = static_cast<std::size_t>(manifolds[k + 2] + manifolds[k + 3]);
    std::size_t first = next;
    while (next < rows.size() && rows[next] < end) ++next;
    if (next > first) {
      manifolds[to] = manifolds[k];
      manifolds[to + 1] = manifolds[k + 1];
      manifolds[to + 2] = static_cast<std::int64_t>(first);
      manifolds[to + 3] = static_cast<std::int64_t>(next - first);
      to += kManifoldFields;
    }
  }
  manifolds.resize(to);
  auto compact = [&rows](auto& column, std::size_t width) {
    std::size_t to = 0;
    for (const std::size_t row : rows) {
      for (std::size_t c = 0; c < width; ++c) column[to++] = column[width * row + c];
    }
    column.resize(to);
  };
  rows_ = rows.size();
  compact(body_a, 1);
  compact(body_b, 1);
  compact(point, 3);
  compact(normal, 3);
  compact(separation, 1);
  compact(toi, 1);
  compact(kind, 1);
  compact(feature, 1);
  compact(piece_a, 1);
  compact(piece_b, 1);
}

void ContactRows::take(const std::vector<std::size_t>& rows, ContactRows& out) const {
  out.clear();
  out.reserve(rows.size());
  for (const std::size_t row : rows) {
    out.body_a.push_back(body_a[row]);
    out.body_b.push_back(body_b[row]);
    out.point.insert(out.point.end(), point.begin() + 3 * row, point.begin() + 3 * row + 3);
    out.normal.insert(out.normal.end(), normal.begin() + 3 * row, normal.begin() + 3 * row + 3);
    out.separation.push_back(separation[row]);
    out.toi.push_back(toi[row]);
    out.kind.push_back(kind[row]);
    out.feature.push_back(feature[row]);
    out.piece_a.push_back(piece_a[row]);
    out.piece_b.push_back(piece_b[row]);
  }
  out.rows_ = rows.size();
}

// Inlined into the loops that add rows: into the columns' room (one test a row, not one a
// column), the row's columns but its kind (put), then the kind's byte, stored last (a byte's
// store may alias any column's data pointer, which the stores before it then need not load
// again).
void ContactRows::add(const BodyShape& a, const BodyShape& b, const Vec3& at, const Vec3& n,
                      double gap, double fraction, ContactKind contact, std::int64_t id) {
  room(1);
  put(a, b, at, n, gap, fraction, id);
  kind[rows_ - 1] = static_cast<std::int8_t>(contact);
}

void ContactRows::room(std::size_t count) {
  if (body_a.size() - rows_ < count) make_room(count);
}

void ContactRows::put(const BodyShape& a, const BodyShape& b, const Vec3& at, const Vec3& n,
                      double gap, double fraction, std::int64_t id) {
  const std::size_t row = rows_;
  body_a[row] = a.body;
  body_b[row] = b.body;
  piece_a[row] = a.piece;
  piece_b[row] = b.piece;
  double* const p = point.data() + 3 * row;
  double* const m = normal.data() + 3 * row;
  for (int k = 0; k < 3; ++k) p[k] = at[k];
  for (int k = 0; k < 3; ++k) m[k] = n[k];
  separation[row] = gap;
  toi[row] = fraction;
  feature[row] = id;
  rows_ = row + 1;
}

void ContactRows::append_part(const ContactRows& other, int part) {
  // a column cut to size() rows, then other's rows (`width` values a row; its room after)
  auto join = [this, n = other.size()](auto& column, const auto& from, std::size_t width) {
    column.resize(width * rows_);
    column.insert(column.end(), from.begin(),
                  from.begin() + static_cast<std::ptrdiff_t>(width * n));
  };
  if (part == 0) {
    join(point, other.point, 3);
    join(normal, other.normal, 3);
    return;
  }
  join(body_a, other.body_a, 1);
  join(body_b, other.body_b, 1);
  join(separation, other.separation, 1);
  join(toi, other.toi, 1);
  join(kind, other.kind, 1);
  join(feature, other.feature, 1);
  join(piece_a, other.piece_a, 1);
  join(piece_b, other.piece_b, 1);
}

void ContactRows::appended(const ContactRows& other) {
  const auto shift = static_cast<std::int64_t>(size());
  rows_ += other.size();
  const std::size_t from = manifolds.size();
  manifolds.insert(manifolds.end(), other.manifolds.begin(), other.manifolds.end());
  for (std::size_t k = from; k < manifolds.size(); k += kManifoldFields) manifolds[k + 2] += shift;
}

void ContactRows::clear() {
  body_a.clear();
  body_b.clear();
  point.clear();
  normal.clear();
  separation.clear();
  toi.clear();
  kind.clear();
  feature.clear();
  piece_a.clear();
  piece_b.clear();
  manifolds.clear();
  rows_ = 0;
}

Detector::Detector(std::vector<BodyShape> shapes, int bodies)
    : shapes_(std::move(shapes)), bodies_count_(bodies), sweep_(kSkin) {
  int next = 0;   // the body the next shape may start
  mesh_.assign(std::max(bodies, 0), false);
  sides_.assign(std::max(bodies, 0), 0);
  for (int k = 0; k < pieces(); ++k) {
    const int body = shapes_[k].body;
    if (body != next && body != next - 1) {
      throw std::invalid_argument("shapes must come in body order, every body at least one");
    }
    if (body >= 0 && body < bodies) sides_[body] |= shapes_[k].is_static ? 1 : 2;
    compound_ = compound_ || body == next - 1;
    if (body == next) first_shape_.push_back(k);
    next = body + 1;
    if (shapes_[k].kind == ShapeKind::triangle) {
      if (body >= 0 && body < bodies) mesh_[body] = true;
      if (meshes_.empty() || shapes_[meshes_.back().first].body != body) {
        meshes_.push_back({k, 0, BoxTree({})});
      }
      ++meshes_.back().count;
      continue;
    }
    (shapes_[k].kind == ShapeKind::plane ? planes_ : finite_).push_back(k);
  }
  if (next != bodies) throw std::invalid_argument("every body needs at least one shape");
  boxes_.resize(finite_.size());
  sieve_.resize(shapes_.size());
  for (int k = 0; k < pieces(); ++k) sieve_[k].body = shapes_[k].body;
  sieve_filter();
  mark_active_edges(shapes_);
  for (Mesh& mesh : meshes_) {
    std::vector<Aabb> boxes;
    for (int k = mesh.first; k < mesh.first + mesh.count; ++k) {
      boxes.push_back({shapes_[k].local_lo, shapes_[k].local_hi});
    }
    mesh.tree = BoxTree(std::move(boxes));
  }
}

void Detector::set_settings(const DetectionSettings& settings) {
  if (settings.speculative_margin != settings_.speculative_margin) reset();
  settings_ = settings;
}

void Detector::set_filter(std::vector<std::uint64_t> group, std::vector<std::uint64_t> mask,
                          const std::vector<std::pair<int, int>>& ignored) {
  filter_ = PairFilter(count(), std::move(group), std::move(mask), ignored);
  sieve_filter();
}

void Detector::sieve_filter() {
  for (Sieve& shape : sieve_) {
    shape.group = filter_.group(shape.body);
    shape.mask = filter_.mask(shape.body);
  }
}

// -- motion and broad phase ----------------------------------------------------------------

void Detector::prepare(const StepPoses& poses, bool queried) {
  bodies_.resize(pieces());
  prepare(poses, queried, 0, pieces());
}

void Detector::prepare(const StepPoses& poses, bool queried, int lo, int hi) {
  for (int k = lo; k < hi; ++k) {
    Body& body = bodies_[k];
    const int owner = shapes_[k].body;
    if (k > lo && owner == shapes_[k - 1].body) {   // another piece: the same motion
      body = bodies_[k - 1];
      body.moved = (body.p1 - body.p0).norm() +
                   (shapes_[k].is_static ? 0.0 : body.turn * shapes_[k].radius);
      if (!std::isfinite(body.moved)) body.moved = 0.0;
      body.swing = body.turn * radius_or_zero(k);
      sieve_[k].fixed = body.fixed;
      sieve_[k].valid = body.valid;
      if (queried) {
        body.pose1 = coal::Transform3s(body.r1 * shapes_[k].rotation,
                                       body.p1 + body.r1 * shapes_[k].offset);
      }
      continue;
    }
    const double* p0 = poses.p0 + 3 * owner;
    const double* p1 = poses.p1 + 3 * owner;
    const double* q0 = poses.q0 + 4 * owner;
    const double* q1 = poses.q1 + 4 * owner;
    body.valid = finite(p0, 3) && finite(p1, 3) && finite(q0, 4) && finite(q1, 4);
    Quat a = Eigen::Map<const Quat>(q0), b = Eigen::Map<const Quat>(q1);  // x, y, z, w
    body.valid = body.valid && a.norm() > 0.5 && b.norm() > 0.5;
    // the caller validates; this only keeps NaN out of coal
    body.p0 = body.valid ? Vec3(p0[0], p0[1], p0[2]) : Vec3::Zero();
    body.p1 = body.valid ? Vec3(p1[0], p1[1], p1[2]) : Vec3::Zero();
    if (!body.valid) a = b = Quat::Identity();
    a.normalize();
    b.normalize();
    if (a.w() < 0.0) a.coeffs() = -a.coeffs();
    if (b.w() < 0.0) b.coeffs() = -b.coeffs();
    body.q0 = a;
    body.q1 = b;
    body.fixed = shapes_[k].is_static;
    const bool frozen = poses.active != nullptr && poses.active[owner] == 0;
    if (frozen) {
      body.p0 = body.p1;
      body.q0 = body.q1;
      body.fixed = true;
    }
    sieve_[k].fixed = body.fixed;
    sieve_[k].valid = body.valid;
    body.turn = angle_between(body.q0, body.q1);
    body.shift = body.p1 - body.p0;
    body.swing = body.turn * radius_or_zero(k);
    body.moved = (body.p1 - body.p0).norm() +
                 (shapes_[k].is_static ? 0.0 : body.turn * shapes_[k].radius);
    if (!std::isfinite(body.moved)) body.moved = 0.0;
    body.r1 = body.q1.toRotationMatrix();
    if (!queried) continue;
    body.linear = body.angular = Vec3::Zero();
    body.external_linear = body.external_angular = Vec3::Zero();
    if (!frozen && poses.linear != nullptr && finite(poses.linear + 3 * owner, 3) &&
        finite(poses.angular + 3 * owner, 3)) {
      body.linear = Eigen::Map<const Vec3>(poses.linear + 3 * owner);
      body.angular = Eigen::Map<const Vec3>(poses.angular + 3 * owner);
      if (poses.linear0 != nullptr && finite(poses.linear0 + 3 * owner, 3) &&
          finite(poses.angular0 + 3 * owner, 3)) {
        body.external_linear = body.linear - Eigen::Map<const Vec3>(poses.linear0 + 3 * owner);
        body.external_angular =
            body.angular - Eigen::Map<const Vec3>(poses.angular0 + 3 * owner);
      }
    }
    body.loaded = external_change_acts(
        body.external_linear != Vec3::Zero() || body.external_angular != Vec3::Zero(),
        body.linear != Vec3::Zero() || body.angular != Vec3::Zero(),
        body.p0 != body.p1 || !(body.q0.coeffs() == body.q1.coeffs()));
    body.pose1 = coal::Transform3s(body.r1 * shapes_[k].rotation,
                                   body.p1 + body.r1 * shapes_[k].offset);
  }
}

void Detector::find_pairs() {
  bound(0, finite_.size());
  pairs_.resize(sweep_.refit(boxes_, sweep_.inside(boxes_, 0, boxes_.size())));
  other_pairs_.clear();
  pairs_.resize(finite_pairs(0, pairs_.size(), 0, finite_.size(), other_pairs_));
  merge_pairs();
}

void Detector::bound(std::size_t lo, std::size_t hi) {
  const double pad = 0.5 * settings_.speculative_margin;
  for (std::size_t i = lo; i < hi; ++i) {
    const int k = finite_[i];
    const Body& body = bodies_[k];
    const BodyShape& shape = shapes_[k];
    const Aabb b0 = world_box(body.q0.toRotationMatrix(), body.p0, shape.local_lo,
                              shape.local_hi);
    const Aabb b1 = world_box(body.r1, body.p1, shape.local_lo, shape.local_hi);
    // a point at radius r turning by angle t leaves its chord by r (1 - cos(t / 2))
    const double bulge = shape.radius * (1.0 - std::cos(0.5 * std::min(body.turn, M_PI)));
    const Vec3 grow = Vec3::Constant(bulge + pad);
    boxes_[i] = {b0.lo.cwiseMin(b1.lo) - grow, b0.hi.cwiseMax(b1.hi) + grow};
  }
}

// Inlined into the loops over the broad phase's pairs: without branches but for the filter's
// ignored pairs (none by default)
inline bool Detector::skip(const std::pair<int, int>& pair) const {
  const Sieve& a = sieve_[pair.first];
  const Sieve& b = sieve_[pair.second];
  const bool drop = (a.fixed & b.fixed) | !(a.valid & b.valid) | (a.body == b.body) |
                    ((a.group & b.mask) == 0) | ((b.group & a.mask) == 0);
  return drop || filter_.ignores(a.body, b.body);
}

std::size_t Detector::finite_pairs(std::size_t from, std::size_t to, std::size_t lo,
                                   std::size_t hi, std::vector<std::pair<int, int>>& others) {
  // the finite pairs, sorted by (a, b) (finite_ is increasing), the skipped ones dropped
  std::pair<int, int>* const part = pairs_.data() + from;
  const std::size_t tested = sweep_.test(from, to, part);
  std::size_t kept = 0;
  for (std::size_t k = 0; k < tested; ++k) {
    const std::pair<int, int> pair{finite_[part[k].first], finite_[part[k].second]};
    if (!skip(pair)) part[kept++] = pair;
  }
  const double pad = 0.5 * settings_.speculative_margin;
  for (int plane : planes_) {  // half-space n.x <= d against each swept box, both poses
    const Body& body = bodies_[plane];
    const BodyShape& shape = shapes_[plane];
    const Vec3 normal0 = body.q0 * shape.plane_normal, normal1 = body.r1 * shape.plane_normal;
    const double offset0 = shape.plane_offset + normal0.dot(body.p0);
    const double offset1 = shape.plane_offset + normal1.dot(body.p1);
    // a half-space that did not move has one test
    const bool still = normal0 == normal1 && offset0 == offset1;
    for (std::size_t i = lo; i < hi; ++i) {
      if (box_reaches_plane(boxes_[i], normal0, offset0, pad) ||
          (!still && box_reaches_plane(boxes_[i], normal1, offset1, pad))) {
        others.emplace_back(std::min(plane, finite_[i]), std::max(plane, finite_[i]));
      }
    }
  }
  return kept;
}

void Detector::merge_pairs() {
  const double pad = 0.5 * settings_.speculative_margin;
  for (const Mesh& mesh : meshes_) {   // its triangles near each finite box, in its frame
    const Body& body = bodies_[mesh.first];   // the mesh body's motion
    const Mat3 r0 = body.q0.toRotationMatrix();
    const bool moved = body.p0 != body.p1 || body.q0.coeffs() != body.q1.coeffs();
    auto local = [](const Aabb& box, const Mat3& r, const Vec3& p) {
      const Vec3 centre = r.transpose() * (0.5 * (box.lo + box.hi) - p);
      const Vec3 half = r.transpose().cwiseAbs() * (0.5 * (box.hi - box.lo));
      return Aabb{centre - half, centre + half};
    };
    for (std::size_t i = 0; i < finite_.size(); ++i) {
      const int k = finite_[i];
      if (body.fixed && bodies_[k].fixed) continue;   // two fixed bodies never pair
      Aabb near = local(boxes_[i], body.r1, body.p1);
      if (moved) {
        const Aabb before = local(boxes_[i], r0, body.p0);
        near = {near.lo.cwiseMin(before.lo), near.hi.cwiseMax(before.hi)};
      }
      near = {near.lo - Vec3::Constant(pad), near.hi + Vec3::Constant(pad)};
      mesh.tree.query(near, [&](int t) {
        const int shape = mesh.first + t;
        other_pairs_.emplace_back(std::min(shape, k), std::max(shape, k));
      });
    }
  }
  // all sorted by (a, b): the others' skipped ones dropped, the rest sorted and merged in
  // (no pair is in both: the others each have a half-space or a triangle, and each comes
  // once)
  other_pairs_.erase(std::remove_if(other_pairs_.begin(), other_pairs_.end(),
                                    [this](const std::pair<int, int>& pair) {
                                      return skip(pair);
                                    }),
                     other_pairs_.end());
  if (other_pairs_.empty()) return;
  std::sort(other_pairs_.begin(), other_pairs_.end());
  merged_pairs_.resize(pairs_.size() + other_pairs_.size());
  std::merge(pairs_.begin(), pairs_.end(), other_pairs_.begin(), other_pairs_.end(),
             merged_pairs_.begin());
  pairs_.swap(merged_pairs_);
}

void Detector::candidate_pairs(const StepPoses& poses, std::vector<std::pair<int, int>>& pairs) {
  prepare(poses, false);
  find_pairs();
  pairs.clear();
  for (const auto& [a, b] : pairs_) pairs.emplace_back(shapes_[a].body, shapes_[b].body);
  std::sort(pairs.begin(), pairs.end());
  pairs.erase(std::unique(pairs.begin(), pairs.end()), pairs.end());
}

void Detector::hold_back(const StepPoses& poses, std::vector<double>& fraction) {
  prepare(poses, false);
  fraction.assign(count(), 1.0);
  const double slop = settings_.linear_slop;
  std::vector<int> fixed;
  for (int j = 0; j < pieces(); ++j) {
    if (bodies_[j].fixed && bodies_[j].valid && shapes_[j].kind != ShapeKind::triangle) {
      fixed.push_back(j);
    }
  }
  if (fixed.empty()) return;
  PointPair witness;
  Vec3 normal;
  for (int k = 0; k < pieces(); ++k) {
    const Body& body = bodies_[k];
    const BodyShape& shape = shapes_[k];
    if (body.fixed || !body.valid || !(body.moved > slop) || shape.kind == ShapeKind::plane) {
      continue;
    }
    const Aabb b0 = world_box(body.q0.toRotationMatrix(), body.p0, shape.local_lo,
                              shape.local_hi);
    const Aabb b1 = world_box(body.r1, body.p1, shape.local_lo, shape.local_hi);
    const double bulge = shape.radius * (1.0 - std::cos(0.5 * std::min(body.turn, M_PI)));
    const Vec3 grow = Vec3::Constant(bulge + slop);
    const Aabb swept{b0.lo.cwiseMin(b1.lo) - grow, b0.hi.cwiseMax(b1.hi) + grow};
    const Motion mk = motion(k);
    for (const int j : fixed) {
      if (shapes_[j].body == shape.body || !filter_.collides(shape.body, shapes_[j].body)) {
        continue;
      }
      const BodyShape& other = shapes_[j];
      const bool plane = other.kind == ShapeKind::plane;
      if (plane) {
        const Vec3 n = bodies_[j].r1 * other.plane_normal;
        if (!box_reaches_plane(swept, n, other.plane_offset + n.dot(bodies_[j].p1), 0.0)) {
          continue;
        }
      } else {
        const Aabb box = world_box(bodies_[j].r1, bodies_[j].p1, other.local_lo,
                                   other.local_hi);
        if ((swept.lo.array() > box.hi.array()).any() ||
            (swept.hi.array() < box.lo.array()).any()) {
          continue;
        }
      }
      // the pair in (a, b) order, as detection queries it
      const int a = std::min(k, j), b = std::max(k, j);
      const Motion ma = a == k ? mk : motion(j), mb = b == k ? mk : motion(j);
      auto depth = [&](double s) {
        return lanes_[0].query.signed_distance(*shapes_[a].geometry, ma.at(s), *shapes_[b].geometry,
                                      mb.at(s), normal, witness);
      };
      // held back where the motion takes it deeper than it was (or touching) by more than
      // the slop: a step's answer that deep is no contact the next step can push out
      const double allowed = std::min(depth(0.0), 0.0) - slop;
      const int samples = plane ? 1 : std::clamp(
          static_cast<int>(std::ceil(body.moved / std::max(other.thickness, slop))), 1, 64);
      double ok = 0.0, bad = -1.0;
      for (int i = 1; i <= samples && bad < 0.0; ++i) {
        const double s = static_cast<double>(i) / samples;
        if (depth(s) < allowed) {
          bad = s;
        } else {
          ok = s;
        }
      }
      if (bad < 0.0) continue;
      std::tie(ok, bad) = bisect([&](double s) { return depth(s) < allowed; }, ok, bad,
                                 settings_.toi_tolerance, settings_.toi_max_iterations);
      fraction[shape.body] = std::min(fraction[shape.body], ok);
    }
  }
}

// -- one step -------------------------------------------------------------------------------

void Detector::detect(const StepPoses& poses, ContactRows& out) {
  out.clear();
  out.reserve(last_rows_ + last_rows_ / 8 + 16);
  budget_ = StepBudget();
  const double margin = settings_.speculative_margin;
  resting_ = std::min(margin,
                      std::max(kRestingMargin * margin, settings_.margin_speed * poses.dt));
  for (Lane& lane : lanes_) {
    lane.next.clear();
    lane.cursor[0] = lane.cursor[1] = 0;
  }
  if (threads_ < 2 || pieces() < kParallelShapes) {
    prepare(poses, true);
    find_pairs();
    limit_pairs();
    run_pairs(lanes_[0], 0, pairs_.size(), out);
  } else {
    detect_paired(poses, out);
  }
  // the lanes' manifolds stay apart: the second's keys are all greater (none: it ran no pair)
  for (int part = 0; part < 2; ++part) stored_[part].swap(lanes_[part].next);
  if (compound_) group_by_bodies(out);
  drop_buried_faces(out);
  if (out.size() > static_cast<std::size_t>(std::max(settings_.max_contacts, 0))) {
    limit_rows(out);
  }
  out.trim();
  last_rows_ = out.size();
}

void Detector::run_pairs(Lane& lane, std::size_t lo, std::size_t hi, ContactRows& out) const {
  for (std::size_t k = lo; k < hi; ++k) {
    const auto [a, b] = pairs_[k];
    // the pair's record of last step, if any, for `reuse`
    const std::int64_t key = static_cast<std::int64_t>(a) * pieces() + b;
    const int part = stored_[1].starts_by(key) ? 1 : 0;
    const StoredManifold* stored = stored_[part].find(key, lane.cursor[part]);
    if (stored != nullptr && reuse(lane, a, b, key, stored_[part], *stored, out)) continue;
    // bounding spheres farther apart than the margin and than the relative motion: the pair
    // can neither touch now nor have met during the step (no query)
    const double relative = relative_motion(a, b);
    const double bound = (bodies_[b].p1 - bodies_[a].p1).norm() - shapes_[a].radius -
                         shapes_[b].radius;
    if (bound > pair_margin(a, b) && bound >= relative) continue;
    narrow_phase(lane, a, b, relative, out);
  }
}

// The chunks of one run (queue 0 this thread's, queue 1 the worker's; each starts once the
// chunks of the other queue it reads are done, `need`), posted first so that the worker's
// wake overlaps this thread's first chunk:
//   0 (q0)  the motion of the first half of the bodies' shapes, their boxes, whether those
//           are inside their fat boxes;  1 (q1) the same of the second half
//   2 (q0, after 1)     the sweep's refit (rebuilt when a box left its fat box)
//   3 (q1, after 0, 2)  the second half of the fat pairs tested, the half-spaces against
//                       the second half of the boxes;  4 (q0) the same of the first halves
//   5 (q0, after 3)     the two parts joined, the other pairs merged in, the budget
//   6 (q0)              the first part of the pairs, into the first lane and `out`
//   7.. (q1, after 5)   the rest of the pairs in kPairChunks ordered chunks
//   then the second lane's rows after the first's, their columns in two parts: one (q0)
//   after every pair chunk, the other (q1) after the first part.
void Detector::detect_paired(const StepPoses& poses, ContactRows& out) {
  using Clock = std::chrono::steady_clock;
  bodies_.resize(pieces());
  // the shapes of the first half of the bodies, and their finite ones
  const int mid = first_shape_[static_cast<std::size_t>(bodies_count_ / 2)];
  const auto finite_mid = static_cast<std::size_t>(
      std::lower_bound(finite_.begin(), finite_.end(), mid) - finite_.begin());
  constexpr int kStages = 7;   // the chunks before the second part's pairs
  constexpr int kChunks = kStages + kPairChunks + 2;   // and the second lane's rows joined
  std::array<std::uint8_t, kChunks> side{0, 1, 0, 1, 0, 0, 0};
  std::array<std::int32_t, kChunks> need{0, 0, 1, 2, 1, 2, 2};
  for (int c = kStages; c < kStages + kPairChunks; ++c) {
    side[c] = 1;
    need[c] = 4;
  }
  side[kChunks - 2] = 0;   // after every pair chunk
  need[kChunks - 2] = 2 + kPairChunks;
  side[kChunks - 1] = 1;   // after the first part's pairs
  need[kChunks - 1] = 5;
  bool inside[2] = {false, false};
  std::size_t fat = 0, kept[2] = {0, 0}, count = 0, split = 0;
  Lane& second = lanes_[1];
  second.rows.clear();
  int direct = 0;   // the leading pair chunks run here, in the first lane (read only here)
  int helped = 0;   // pair chunks the worker ran
  Clock::duration first_took{}, second_took{};
  Clock::time_point second_began;
  const std::thread::id here = std::this_thread::get_id();
  auto task = [&](int c) {
    switch (c) {
      case 0:
        prepare(poses, true, 0, mid);
        bound(0, finite_mid);
        inside[0] = sweep_.inside(boxes_, 0, finite_mid);
        break;
      case 1:
        prepare(poses, true, mid, pieces());
        bound(finite_mid, finite_.size());
        inside[1] = sweep_.inside(boxes_, finite_mid, finite_.size());
        break;
      case 2:
        fat = sweep_.refit(boxes_, inside[0] && inside[1]);
        pairs_.resize(fat);
        break;
      case 3:
        second.others.clear();
        kept[1] = finite_pairs(fat / 2, fat, finite_mid, finite_.size(), second.others);
        break;
      case 4:
        lanes_[0].others.clear();
        kept[0] = finite_pairs(0, fat / 2, 0, finite_mid, lanes_[0].others);
        break;
      case 5: {
        // the second part's pairs after the first's, the half-spaces' pairs of both
        const auto from = pairs_.begin() + static_cast<std::ptrdiff_t>(fat / 2);
        std::copy(from, from + static_cast<std::ptrdiff_t>(kept[1]),
                  pairs_.begin() + static_cast<std::ptrdiff_t>(kept[0]));
        pairs_.resize(kept[0] + kept[1]);
        other_pairs_.assign(lanes_[0].others.begin(), lanes_[0].others.end());
        other_pairs_.insert(other_pairs_.end(), second.others.begin(), second.others.end());
        merge_pairs();
        limit_pairs();
        count = pairs_.size();
        split = static_cast<std::size_t>(pair_share_ * static_cast<double>(count));
        break;
      }
      case 6: {
        const Clock::time_point began = Clock::now();
        run_pairs(lanes_[0], 0, split, out);
        first_took = Clock::now() - began;
        break;
      }
      case kChunks - 2:
      case kChunks - 1:
        if (direct < kPairChunks) out.append_part(second.rows, c - (kChunks - 2));
        break;
      default: {
        const int chunk = c - kStages;
        const std::size_t lo = split + (count - split) * chunk / kPairChunks;
        const std::size_t hi = split + (count - split) * (chunk + 1) / kPairChunks;
        if (chunk == 0) second_began = Clock::now();
        if (std::this_thread::get_id() == here && chunk == direct) {
          run_pairs(lanes_[0], lo, hi, out);
          ++direct;
        } else {
          run_pairs(second, lo, hi, second.rows);
        }
        if (std::this_thread::get_id() != here) ++helped;
        if (chunk == kPairChunks - 1) second_took = Clock::now() - second_began;
      }
    }
  };
  if (!worker_) worker_ = std::make_unique<Worker>();
  worker_->run_sides(task, kChunks, side.data(), need.data(), 0, static_cast<double>(pieces()));
  if (direct < kPairChunks) out.appended(second.rows);
  // the first part's share of the pairs, towards the one at which the two parts took as
  // long, from the time a pair took in each (when the worker ran the whole second part)
  if (helped == kPairChunks && split > 0 && count > split && first_took.count() > 0 &&
      second_took.count() > 0) {
    const double first = std::chrono::duration<double>(first_took).count() /
                         static_cast<double>(split);
    const double second_pair = std::chrono::duration<double>(second_took).count() /
                               static_cast<double>(count - split);
    const double even = second_pair / (first + second_pair);
    pair_share_ = std::clamp(pair_share_ + kShareWeight * (even - pair_share_), kLeastShare,
                             1.0 - kLeastShare);
  }
}

// Rows grouped by pair of bodies in (a, b) order, manifold by manifold (piece pairs of one
// pair of bodies may be apart: piece order is body order, but a's first piece meets c
// before a's second meets b), then each pair cut to its max_contacts_per_pair deepest rows
// (ties by position), in their order; a manifold keeps its kept rows.
void Detector::group_by_bodies(ContactRows& out) {
  const std::size_t spans = out.manifolds.size() / kManifoldFields;
  const std::int64_t* m = out.manifolds.data();
  rank_.resize(spans);
  for (std::size_t k = 0; k < spans; ++k) rank_[k] = k;
  std::stable_sort(rank_.begin(), rank_.end(), [m](std::size_t i, std::size_t j) {
    const std::int64_t* x = m + kManifoldFields * i;
    const std::int64_t* y = m + kManifoldFields * j;
    return x[0] < y[0] || (x[0] == y[0] && x[1] < y[1]);
  });
  order_.clear();
  std::vector<std::int64_t> manifolds;
  manifolds.reserve(out.manifolds.size());
  for (const std::size_t k : rank_) {
    const std::int64_t* span = m + kManifoldFields * k;
    manifolds.insert(manifolds.end(), {span[0], span[1],
                                       static_cast<std::int64_t>(order_.size()), span[3]});
    for (std::int64_t r = 0; r < span[3]; ++r) {
      order_.push_back(static_cast<std::size_t>(span[2] + r));
    }
  }
  out.take(order_, grouped_);
  grouped_.manifolds.swap(manifolds);
  std::swap(out, grouped_);
  merge_mesh_faces(out);
  // the cap, per pair of bodies (rows are now grouped by pair)
  const auto cap = static_cast<std::size_t>(std::max(settings_.max_contacts_per_pair, 1));
  const std::size_t count = out.size();
  const std::vector<double>& gap = out.separation;
  std::vector<std::size_t> kept;
  bool cut = false;
  for (std::size_t lo = 0; lo < count;) {
    std::size_t hi = lo + 1;
    while (hi < count && out.body_a[hi] == out.body_a[lo] && out.body_b[hi] == out.body_b[lo]) {
      ++hi;
    }
    const std::size_t first = kept.size();
    for (std::size_t r = lo; r < hi; ++r) kept.push_back(r);
    if (hi - lo > cap) {
      cut = true;
      std::stable_sort(kept.begin() + first, kept.end(),
                       [&gap](std::size_t i, std::size_t j) { return gap[i] < gap[j]; });
      kept.resize(first + cap);
      std::sort(kept.begin() + first, kept.end());
    }
    lo = hi;
  }
  if (cut) out.keep(kept);
}

void Detector::merge_mesh_faces(ContactRows& out) {
  constexpr double kSameNormal = 1.0 - 1e-9;   // cosine: one face's normal
  if (std::find(mesh_.begin(), mesh_.end(), true) == mesh_.end()) return;
  const std::size_t spans = out.manifolds.size() / kManifoldFields;
  const std::int64_t* m = out.manifolds.data();
  std::vector<std::int64_t> manifolds;
  std::vector<char> taken(spans, 0);
  order_.clear();
  bool merged = false;
  for (std::size_t k = 0; k < spans; ++k) {
    if (taken[k]) continue;
    const std::int64_t* span = m + kManifoldFields * k;
    const auto first = static_cast<std::size_t>(span[2]);
    const Vec3 normal(out.normal[3 * first], out.normal[3 * first + 1],
                      out.normal[3 * first + 2]);
    merge_rows_.clear();
    // with a mesh, the later manifolds of this pair with this normal (a pair's manifolds
    // are adjacent)
    const bool mesh = mesh_[span[0]] || mesh_[span[1]];
    for (std::size_t j = k; j < spans; ++j) {
      const std::int64_t* other = m + kManifoldFields * j;
      if (other[0] != span[0] || other[1] != span[1] || (j > k && !mesh)) break;
      const auto row = static_cast<std::size_t>(other[2]);
      const Vec3 n(out.normal[3 * row], out.normal[3 * row + 1], out.normal[3 * row + 2]);
      if (taken[j] || !(n.dot(normal) > kSameNormal)) continue;
      taken[j] = 1;
      for (std::int64_t r = 0; r < other[3]; ++r) merge_rows_.push_back(row + r);
    }
    const std::size_t start = order_.size();
    const bool several = merge_rows_.size() > static_cast<std::size_t>(span[3]);
    if (several && merge_rows_.size() > static_cast<std::size_t>(kMaxManifoldPoints)) {
      merge_points_.clear();
      merge_separations_.clear();
      for (const std::size_t r : merge_rows_) {
        merge_points_.emplace_back(out.point[3 * r], out.point[3 * r + 1], out.point[3 * r + 2]);
        merge_separations_.push_back(out.separation[r]);
      }
      reduce_manifold(merge_points_, merge_separations_, normal, settings_.linear_slop,
                      merge_keep_);
      for (const int i : merge_keep_) order_.push_back(merge_rows_[i]);
      merged = true;
    } else {
      order_.insert(order_.end(), merge_rows_.begin(), merge_rows_.end());
      merged = merged || several;
    }
    manifolds.insert(manifolds.end(), {span[0], span[1], static_cast<std::int64_t>(start),
                                       static_cast<std::int64_t>(order_.size() - start)});
  }
  if (!merged) return;
  out.take(order_, grouped_);
  grouped_.manifolds.swap(manifolds);
  std::swap(out, grouped_);
}

int Detector::shape_of(std::int64_t body, std::int32_t piece) const {
  return first_shape_[static_cast<std::size_t>(body)] + piece;
}

double Detector::buried_depth(int k, const Vec3& point) const {
  const BodyShape& shape = shapes_[k];
  const Body& body = bodies_[k];
  if (shape.kind == ShapeKind::plane) {
    const Vec3 normal = body.r1 * shape.plane_normal;
    return shape.plane_offset + normal.dot(body.p1) - normal.dot(point);
  }
  if (shape.kind != ShapeKind::box) return -kInf;
  const Vec3 local = (body.r1 * shape.rotation).transpose() *
                     (point - body.p1 - body.r1 * shape.offset);
  return (shape.half - local.cwiseAbs()).minCoeff();
}

void Detector::drop_buried_faces(ContactRows& out) {
  constexpr double kOpposed = -0.5;   // cosine: two rows' normals push against each other
  const std::size_t count = out.size();
  // the moving bodies with rows on two static bodies or more: only theirs are looked at,
  // among the rows of a moving and a static shape (sided_)
  static_of_.assign(static_cast<std::size_t>(bodies_count_), -1);
  several_.assign(static_cast<std::size_t>(bodies_count_), 0);
  sided_.clear();
  bool any = false;
  // manifold by manifold (they tile the rows in order, each of one pair of bodies): a pair
  // of two static or two moving bodies has no such row
  for (std::size_t m = 0; m < out.manifolds.size(); m += kManifoldFields) {
    const std::int64_t* span = out.manifolds.data() + m;
    const char side = sides_[static_cast<std::size_t>(span[0])];
    if (side != 3 && side == sides_[static_cast<std::size_t>(span[1])]) continue;
    const auto end = static_cast<std::size_t>(span[2] + span[3]);
    for (auto r = static_cast<std::size_t>(span[2]); r < end; ++r) {
      const bool sa = shapes_[shape_of(out.body_a[r], out.piece_a[r])].is_static;
      if (sa == shapes_[shape_of(out.body_b[r], out.piece_b[r])].is_static) continue;
      const auto moving = static_cast<std::size_t>(sa ? out.body_b[r] : out.body_a[r]);
      sided_.emplace_back(static_cast<std::int64_t>(moving), r);
      const std::int64_t fixed = sa ? out.body_a[r] : out.body_b[r];
      if (static_of_[moving] < 0) {
        static_of_[moving] = fixed;
      } else if (static_of_[moving] != fixed) {
        several_[moving] = 1;
        any = true;
      }
    }
  }
  if (!any) return;
  // the rows of the bodies that touch several, by body (in row order)
  sided_.erase(std::remove_if(sided_.begin(), sided_.end(),
                              [this](const std::pair<std::int64_t, std::size_t>& side) {
                                return !several_[static_cast<std::size_t>(side.first)];
                              }),
               sided_.end());
  std::sort(sided_.begin(), sided_.end());
  buried_sides_.clear();
  for (const auto& [moving, r] : sided_) {
    const int a = shape_of(out.body_a[r], out.piece_a[r]);
    const int b = shape_of(out.body_b[r], out.piece_b[r]);
    // the static shape, the witness point on it, the normal out of it
    const bool a_static = shapes_[a].is_static;
    const Vec3 n(out.normal[3 * r], out.normal[3 * r + 1], out.normal[3 * r + 2]);
    const Vec3 p(out.point[3 * r], out.point[3 * r + 1], out.point[3 * r + 2]);
    const Vec3 outward = a_static ? n : Vec3(-n);
    const Vec3 witness = p - 0.5 * out.separation[r] * outward;
    // the row's point on the moving body, carried back to the body's previous pose: how
    // far in front of the face's plane it was then (negative: behind it)
    const int mover = a_static ? b : a;
    const Body& body = bodies_[mover];
    const Vec3 on_body = p + 0.5 * out.separation[r] * outward;
    const Vec3 then = body.q0 * (body.r1.transpose() * (on_body - body.p1)) + body.p0;
    const double ahead = (then - witness).dot(outward);
    const bool behind = ahead < -kDeepFraction * shapes_[mover].thickness;
    buried_sides_.push_back({moving, a_static ? a : b, r, witness, then - ahead * outward,
                             outward, 0.0, behind});
  }
  any = false;
  for (std::size_t lo = 0; lo < buried_sides_.size();) {
    std::size_t hi = lo + 1;
    while (hi < buried_sides_.size() && buried_sides_[hi].moving == buried_sides_[lo].moving) {
      ++hi;
    }
    // how deep each row's point lies in another static shape whose row opposes it
    std::size_t least = lo;
    for (std::size_t i = lo; i < hi; ++i) {
      StaticSide& row = buried_sides_[i];
      row.depth = 0.0;
      for (std::size_t j = lo; j < hi; ++j) {
        const StaticSide& other = buried_sides_[j];
        if (shapes_[other.shape].body == shapes_[row.shape].body ||
            !(row.outward.dot(other.outward) < kOpposed)) {
          continue;
        }
        // a face the body was behind at its previous pose (beyond the depth EPA is trusted
        // to): reached only through the other shape (a ball driven through a corner of two
        // walls that end together, out to their ends' faces)
        // a face point buried now and where the body's point was at its previous pose: the
        // row of a body that touched a face and is now out past the corner into a third
        // wall (its point now, projected on the face, inside that wall) is not buried
        row.depth = std::max(row.depth, row.behind ? kInf
                                                   : std::min(buried_depth(other.shape, row.witness),
                                                              buried_depth(other.shape, row.then)));
      }
      if (row.depth < buried_sides_[least].depth) least = i;
    }
    // when every row of the body is buried, the least buried is its real surface
    if (buried_sides_[least].depth > 0.0) buried_sides_[least].depth = 0.0;
    for (std::size_t i = lo; i < hi; ++i) any = any || buried_sides_[i].depth > 0.0;
    lo = hi;
  }
  if (!any) return;
  buried_.assign(count, 0);
  for (const StaticSide& row : buried_sides_) buried_[row.row] = row.depth > 0.0 ? 1 : 0;
  std::vector<std::size_t> kept;
  kept.reserve(count);
  for (std::size_t r = 0; r < count; ++r) {
    if (!buried_[r]) kept.push_back(r);
  }
  out.keep(kept);
}

// m, how far apart the pair's bounding spheres are at s = 1 (negative: overlapping); for a
// half-space, how high the other body's sphere is above its surface
double Detector::sphere_gap(int a, int b) const {
  const bool plane_a = shapes_[a].kind == ShapeKind::plane;
  if (plane_a || shapes_[b].kind == ShapeKind::plane) {
    const int plane = plane_a ? a : b, other = plane_a ? b : a;
    const Body& p = bodies_[plane];
    const Vec3 normal = p.r1 * shapes_[plane].plane_normal;
    const double offset = shapes_[plane].plane_offset + normal.dot(p.p1);
    return normal.dot(bodies_[other].p1) - offset - radius_or_zero(other);
  }
  return (bodies_[b].p1 - bodies_[a].p1).norm() - shapes_[a].radius - shapes_[b].radius;
}

// m/s: the floor of A and B's resting speed, the solver's (StepSolver::reference_frame):
// restitution_threshold where the step's external change acts on one of the two
// (external_change_acts), else 0
double Detector::resting_floor(int a, int b) const {
  return bodies_[a].loaded || bodies_[b].loaded ? settings_.restitution_threshold : 0.0;
}

// Whether a point of B may approach A faster than its resting speed, the solver's rule
// (StepSolver::reference_frame): faster than its floor (resting_floor) and than
// resting_factor times the approach the step's external change alone brought it along
// its normal. `speed` bounds any point's approach (current twists); the external approach
// is bounded from below along `normal`, the current one (a bound only: a body carried past
// the middle of a thin one has its current normal turned away from its approach, so the
// approach itself is not taken along it). A pair that cannot is no impact.
bool Detector::may_bounce(int a, int b, const Vec3& normal, double speed) const {
  if (!(speed > resting_floor(a, b))) return false;
  const Body& A = bodies_[a];
  const Body& B = bodies_[b];
  const double external = -(B.external_linear - A.external_linear).dot(normal.normalized()) -
                          A.external_angular.norm() * radius_or_zero(a) -
                          B.external_angular.norm() * radius_or_zero(b);
  return speed > settings_.resting_factor * external;
}

// m, bound on how far any point of B moves relative to A over the step
double Detector::relative_motion(int a, int b) const {
  const Body& A = bodies_[a];
  const Body& B = bodies_[b];
  return (B.shift - A.shift).norm() + A.swing + B.swing;
}

// m, bound on how much the pair's distance changes over the step: with a half-space, how far
// any point of the other body moves along the half-space's normal relative to it (a motion
// along its surface, a box falling by a wall, changes no distance to it); else
// relative_motion
double Detector::approach_bound(int a, int b) const {
  const bool plane_a = shapes_[a].kind == ShapeKind::plane;
  if (!plane_a && shapes_[b].kind != ShapeKind::plane) return relative_motion(a, b);
  const int plane = plane_a ? a : b, other = plane_a ? b : a;
  const Body& P = bodies_[plane];
  const Body& O = bodies_[other];
  const Vec3 normal = P.r1 * shapes_[plane].plane_normal;
  return std::abs((O.shift - P.shift).dot(normal)) + P.swing + O.swing;
}

double Detector::pair_margin(int a, int b) const {
  const double margin = settings_.speculative_margin;
  return std::min(margin, resting_ + bodies_[a].moved + bodies_[b].moved);
}

// Only pairs that need a coal query count: bounding spheres farther apart than the margin
// and than the relative motion cannot touch (narrow_phase skips them unqueried).
void Detector::limit_pairs() {
  const auto keep = static_cast<std::size_t>(std::max(settings_.max_pairs, 0));
  if (pairs_.size() <= keep) return;
  depth_.clear();
  order_.clear();
  for (std::size_t k = 0; k < pairs_.size(); ++k) {
    const auto [a, b] = pairs_[k];
    const double gap = sphere_gap(a, b);
    if (gap > pair_margin(a, b) && gap >= relative_motion(a, b)) continue;
    order_.push_back(k);
    depth_.push_back(-gap);
  }
  if (order_.size() <= keep) return;
  // deepest first; equal depths by (a, b) order, so the choice is deterministic
  std::vector<std::size_t>& rank = rank_;
  rank.resize(order_.size());
  for (std::size_t i = 0; i < rank.size(); ++i) rank[i] = i;
  std::nth_element(rank.begin(), rank.begin() + keep, rank.end(),
                   [this](std::size_t i, std::size_t j) {
                     return depth_[i] > depth_[j] || (depth_[i] == depth_[j] && i < j);
                   });
  rank.resize(keep);
  std::sort(rank.begin(), rank.end());
  kept_pairs_.clear();
  for (const std::size_t i : rank) kept_pairs_.push_back(pairs_[order_[i]]);
  budget_.pairs_dropped = order_.size() - keep;
  pairs_.swap(kept_pairs_);
}

void Detector::limit_rows(ContactRows& out) {
  const std::size_t count = out.size();
  const auto keep = static_cast<std::size_t>(std::max(settings_.max_contacts, 0));
  order_.resize(count);
  for (std::size_t k = 0; k < count; ++k) order_[k] = k;
  const std::vector<double>& gap = out.separation;
  std::nth_element(order_.begin(), order_.begin() + keep, order_.end(),
                   [&gap](std::size_t i, std::size_t j) {
                     return gap[i] < gap[j] || (gap[i] == gap[j] && i < j);
                   });
  order_.resize(keep);
  std::sort(order_.begin(), order_.end());
  out.keep(order_);
  budget_.rows_dropped = count - keep;
}

COLLRES_CLONED_FLAT
bool Detector::reuse(Lane& lane, int a, int b, std::int64_t key, const ManifoldStore& store,
                     const StoredManifold& record, ContactRows& out) const {
  const Body& A = bodies_[a];
  const Body& B = bodies_[b];
  if (record.apart > 0.0) return still_apart(lane, key, a, b, record);
  if (shapes_[a].curved || shapes_[b].curved) return false;
  // the pair's own motion over the step, as the narrow phase classifies it: the motion
  // both share (a pile that its source integrated one long period under gravity) moves no
  // point of one relative to the other
  const double margin = pair_margin(a, b);
  const double relative = approach_bound(a, b);
  if (relative > margin) return false;
  const Vec3 rel_p = A.r1.transpose() * (B.p1 - A.p1);
  const Quat rel_q = A.q1.conjugate() * B.q1;
  const double shift = settings_.reuse_shift * std::min(shapes_[a].thickness,
                                                        shapes_[b].thickness);
  // the shift along the contact plane (A's frame): a shift along the manifold's normal
  // moves no point along either face, and each row's gap is measured again below
  const StoredRow* const rows = record.count > 0 ? &store.row(record.first) : nullptr;
  Vec3 moved = rel_p - record.rel_p;
  if (rows != nullptr) moved -= moved.dot(rows[0].normal_a) * rows[0].normal_a;
  if (moved.norm() > shift ||
      std::abs(rel_q.dot(record.rel_q)) < std::cos(0.5 * kReuseRotation)) {
    return false;
  }
  // a pair whose every point left the margin is no longer in contact (the rows of a
  // manifold share one normal); each row's points at the current poses give its row, added
  // at once and dropped again when the pair is not reused
  if (rows == nullptr) return true;
  const Vec3 normal = A.r1 * rows[0].normal_a;
  const std::size_t first = out.size();
  double gap = kInf;
  out.room(static_cast<std::size_t>(record.count));
  for (int k = 0; k < record.count; ++k) {
    const Vec3 on_a = A.r1 * rows[k].local_a + A.p1;
    const Vec3 on_b = B.r1 * rows[k].local_b + B.p1;
    const double separation = (on_b - on_a).dot(normal);
    gap = std::min(gap, separation);
    out.put(shapes_[a], shapes_[b], 0.5 * (on_a + on_b), normal, separation, 0.0,
            rows[k].feature);
  }
  if (gap > margin) {
    out.drop_from(first);
    return true;
  }
  // what the narrow phase would not call persistent goes to it: apart at the previous
  // state maybe (gap + relative motion beyond the margin), a hit that may bounce (a point
  // approaching faster than its resting speed along the normal), a deep overlap
  // (deep_persistent)
  const double deep = kDeepFraction * std::min(shapes_[a].thickness, shapes_[b].thickness);
  if (gap + relative > margin || -gap > deep ||
      (gap < 0.0 && gap + relative > 0.0 && may_bounce(a, b, normal, speed_bound(a, b)))) {
    out.drop_from(first);
    return false;
  }
  out.set_kind(first, ContactKind::persistent);
  lane.next.begin(key, record.rel_p, record.rel_q);
  lane.next.add_rows(rows, record.count);
  out.close_manifold(shapes_[a].body, shapes_[b].body, first);
  return true;
}

bool Detector::may_store_apart(int a, int b) const {
  auto gjk = [this](int k) {
    const ShapeKind kind = shapes_[k].kind;
    return kind != ShapeKind::sphere && kind != ShapeKind::triangle && kind != ShapeKind::plane;
  };
  return gjk(a) && gjk(b);
}

bool Detector::still_apart(Lane& lane, std::int64_t key, int a, int b,
                           const StoredManifold& stored) const {
  const Body& A = bodies_[a];
  const Body& B = bodies_[b];
  // how far any point of B moved in A's frame since the distance was measured: the shift of
  // B's origin, and the chord of the turn (2 sin(angle / 2)) times B's bounding radius
  const Vec3 rel_p = A.r1.transpose() * (B.p1 - A.p1);
  const Quat rel_q = A.q1.conjugate() * B.q1;
  const double cosine = std::min(1.0, std::abs(rel_q.dot(stored.rel_q)));
  const double drift = (rel_p - stored.rel_p).norm() +
                       2.0 * std::sqrt(1.0 - cosine * cosine) * shapes_[b].radius;
  // the distance of two convex shapes changes by no more than that drift
  const double least = stored.apart - drift - kApartSlack;
  if (!(least > pair_margin(a, b) && least >= relative_motion(a, b))) return false;
  lane.next.begin_apart(key, stored.rel_p, stored.rel_q, stored.apart);
  return true;
}

double Detector::speed_bound(int a, int b) const {
  const Body& A = bodies_[a];
  const Body& B = bodies_[b];
  return (B.linear - A.linear).norm() + A.angular.norm() * radius_or_zero(a) +
         B.angular.norm() * radius_or_zero(b);
}

double Detector::radius_or_zero(int body) const {
  const double r = shapes_[body].radius;
  return std::isfinite(r) ? r : 0.0;
}

Motion Detector::motion(int body) const {
  const Body& b = bodies_[body];
  return Motion(b.p0, b.p1, b.q0, b.q1, shapes_[body].offset, shapes_[body].rotation);
}

void Detector::narrow_phase(Lane& lane, int a, int b, double relative, ContactRows& out) const {
  const Body& A = bodies_[a];
  const Body& B = bodies_[b];
  const double margin = pair_margin(a, b);
  Vec3 normal;
  PointPair witness;
  const double distance = lane.query.signed_distance(*shapes_[a].geometry, A.pose1,
                                                 *shapes_[b].geometry, B.pose1, normal, witness);
  const bool near = distance <= margin;
  if (!near && distance > 0.0 && std::isfinite(distance) && may_store_apart(a, b)) {
    lane.next.begin_apart(static_cast<std::int64_t>(a) * pieces() + b,
                          A.r1.transpose() * (B.p1 - A.p1), A.q1.conjugate() * B.q1, distance);
  }
  // overlapping now, possibly apart before, and closing fast enough to bounce: its
  // previous state decides between a persistent contact and an impact
  const double approach = approach_bound(a, b);
  const bool may_have_hit = distance < 0.0 && distance + approach > 0.0 &&
                            may_bounce(a, b, normal, speed_bound(a, b));
  if (near && distance + approach <= margin && !may_have_hit) {
    // within the margin at the previous state for sure: a persistent contact
    const double deep = kDeepFraction * std::min(shapes_[a].thickness, shapes_[b].thickness);
    if (-distance > deep && deep_persistent(lane, a, b, deep, margin + relative, out)) return;
    lane.points.clear();
    if (shapes_[a].single_point || shapes_[b].single_point) {
      lane.points.push_back(witness);
    } else {
      lane.query.manifold(*shapes_[a].geometry, A.pose1, *shapes_[b].geometry, B.pose1,
                          settings_.linear_slop, lane.points);
    }
    emit(lane, a, b, normal, 0.0, ContactKind::persistent, kInf, A.r1, A.p1, B.r1, B.p1, out);
    const Vec3 unit = normal.normalized();
    speculate(lane, a, b, unit, deepest(lane.points, unit), true, 0.0, ContactKind::persistent, margin + relative,
              A.r1, A.p1, B.r1, B.p1, out);
    return;
  }
  if (near || (settings_.ccd && relative > distance)) {
    classify(lane, a, b, distance, normal, relative, speed_bound(a, b), near, out);
  }
}

void Detector::classify(Lane& lane, int a, int b, double distance_now, const Vec3& normal_now,
                        double relative, double speed, bool near, ContactRows& out) const {
  const coal::CollisionGeometry& ga = *shapes_[a].geometry;
  const coal::CollisionGeometry& gb = *shapes_[b].geometry;
  const Motion ma = motion(a), mb = motion(b);
  PointPair closest;
  const double margin = pair_margin(a, b);
  const double before = lane.query.distance(ga, ma.at(0.0), gb, mb.at(0.0), closest);
  if (before <= margin) {
    // touching at the previous state (within the slop): in contact from the start of the
    // step, never an impact within it
    const bool touched = before <= settings_.linear_slop;
    // apart before, overlapping now, fast: solved at its time of impact, not at the end
    if (distance_now < 0.0 && !touched && may_bounce(a, b, normal_now, speed) &&
        time_of_impact(lane, a, b, ma, mb, 0.0, 1.0, ContactKind::impact, distance_now, true, out)) {
      return;
    }
    // moved farther than both gaps: it may have passed through (a thin body at a low rate)
    const bool passed = relative > before + distance_now;
    // near at both ends but apart
    if (settings_.ccd && passed && !touched && distance_now >= 0.0 &&
        tunnelled(lane, a, b, ma, mb, relative, out)) {
      return;
    }
    // touching before and past each other now (a step of several periods after dropped
    // inputs: the source integrated a resting body through its floor; a ball driven at a
    // wall it touches, farther in a step than half the wall is thick, whose contact now
    // faces out of the wall's far side or its end): the contact of the previous state,
    // carried along with each body
    if (settings_.ccd && passed && touched) {
      const double deep = kDeepFraction * std::min(shapes_[a].thickness, shapes_[b].thickness);
      if (!near) {
        deep_persistent(lane, a, b, deep, settings_.speculative_margin, out);
        return;
      }
      if (deep_persistent(lane, a, b, deep, settings_.speculative_margin, out, &normal_now)) return;
    }
    if (near) current_manifold(lane, a, b, out);  // in contact at both ends
    return;
  }
  if (distance_now < 0.0) {  // apart before, overlapping now
    time_of_impact(lane, a, b, ma, mb, 0.0, 1.0, ContactKind::impact, distance_now, false, out);
    return;
  }
  if (settings_.ccd && tunnelled(lane, a, b, ma, mb, relative, out)) return;
  if (near) current_manifold(lane, a, b, out);  // approaching, not touching yet: speculative
}

bool Detector::tunnelled(Lane& lane, int a, int b, const Motion& ma, const Motion& mb,
                         double relative, ContactRows& out) const {
  const coal::CollisionGeometry& ga = *shapes_[a].geometry;
  const coal::CollisionGeometry& gb = *shapes_[b].geometry;
  const double tolerance = std::max(
      1e-9, std::min(settings_.toi_tolerance * relative, 0.5 * settings_.linear_slop));
  PointPair scratch;
  auto gap = [&](double s) { return lane.query.distance(ga, ma.at(s), gb, mb.at(s), scratch); };
  auto overlaps = [&](double s) { return lane.query.overlaps(ga, ma.at(s), gb, mb.at(s)); };
  const auto bracket = advance(gap, overlaps, relative, tolerance,
                               4 * settings_.toi_max_iterations);
  return bracket && time_of_impact(lane, a, b, ma, mb, bracket->first, bracket->second,
                                   ContactKind::tunnelled, kInf, false, out);
}

bool Detector::time_of_impact(Lane& lane, int a, int b, const Motion& ma, const Motion& mb,
                              double s0, double s1, ContactKind kind, double cap,
                              bool only_if_fast, ContactRows& out) const {
  const coal::CollisionGeometry& ga = *shapes_[a].geometry;
  const coal::CollisionGeometry& gb = *shapes_[b].geometry;
  auto overlaps = [&](double s) { return lane.query.overlaps(ga, ma.at(s), gb, mb.at(s)); };
  std::tie(s0, s1) = bisect(overlaps, s0, s1, settings_.toi_tolerance,
                            settings_.toi_max_iterations);
  double distance = 0.0;
  Vec3 normal;
  PointPair witness;
  if (!lane.query.contact(ga, ma.at(s1), gb, mb.at(s1), 0.0, distance, normal, witness)) {
    // only for a degenerate bracket: the end of the step overlaps
    s1 = 1.0;
    if (!lane.query.contact(ga, ma.at(s1), gb, mb.at(s1), 0.0, distance, normal, witness)) {
      return false;
    }
  }
  Vec3 used = normal;
  // (faces meeting faces: a curved surface's EPA answer, its normal through the curve, holds)
  const bool shallow = -distance < settings_.linear_slop && !shapes_[a].curved &&
                       !shapes_[b].curved;
  if (shallow ||
      -distance > kDeepFraction * std::min(shapes_[a].thickness, shapes_[b].thickness)) {
    // EPA is not trusted on a deep overlap, nor on a shallow one (faces just touching: a
    // cube landing flat on another got a normal 25-85 deg off the faces' and one corner's
    // impulse, a spin that sank it 9-17 mm into the other): the classic direction from the
    // closest points of the last separated configuration
    PointPair closest;
    const double gap = lane.query.distance(ga, ma.at(s0), gb, mb.at(s0), closest);
    const Vec3 direction = closest.on_b - closest.on_a;
    if (gap > 0.0 && direction.norm() > 0.0) used = direction.normalized();
  }
  lane.points.clear();
  if (shapes_[a].single_point || shapes_[b].single_point) {
    lane.points.push_back(witness);
  } else {
    if (shallow) lane.query.turn_loaded(used);   // its patch about that normal
    lane.query.manifold(ga, ma.at(s1), gb, mb.at(s1), settings_.linear_slop, lane.points);
  }
  const Mat3 ra = ma.rotation_at(s1), rb = mb.rotation_at(s1);
  const Vec3 pa = ma.position_at(s1), pb = mb.position_at(s1);
  if (only_if_fast) {
    // approach speed at each contact point (current twists): slower than its resting speed
    // at every point (the floor, resting_floor, or resting_factor times the approach the
    // step's external change brought there, as the solver's), the pair rests and stays a
    // persistent contact at the current state
    const Body& A = bodies_[a];
    const Body& B = bodies_[b];
    const Vec3 unit = used.normalized();
    const double floor = resting_floor(a, b);
    bool fast = false;
    for (const PointPair& p : lane.points) {
      const Vec3 point = 0.5 * (p.on_a + p.on_b);
      const Vec3 va = A.linear + A.angular.cross(point - pa);
      const Vec3 vb = B.linear + B.angular.cross(point - pb);
      const Vec3 ea = A.external_linear + A.external_angular.cross(point - pa);
      const Vec3 eb = B.external_linear + B.external_angular.cross(point - pb);
      const double resting = std::max(floor,
                                      settings_.resting_factor * std::max(-(eb - ea).dot(unit), 0.0));
      fast = fast || (vb - va).dot(unit) < -resting;
    }
    if (!fast) return false;
  }
  emit(lane, a, b, used, s1, kind, cap, ra, pa, rb, pb, out);
  // after the impact a corner may turn faster than anything moved before it (a fall
  // turned into a spin about the corner that hit): three times the motion of the rest
  const double reach = settings_.speculative_margin + 3.0 * (1.0 - s1) * relative_motion(a, b);
  const Vec3 unit = used.normalized();
  speculate(lane, a, b, unit, deepest(lane.points, unit), true, s1, kind, reach, ra, pa, rb, pb, out);
  return true;
}

const PointPair* Detector::deepest(const std::vector<PointPair>& points, const Vec3& normal) {
  const PointPair* pair = points.empty() ? nullptr : &points[0];
  for (const PointPair& p : points)
    if ((p.on_b - p.on_a).dot(normal) < (pair->on_b - pair->on_a).dot(normal)) pair = &p;
  return pair;
}

void Detector::speculate(Lane& lane, int a, int b, const Vec3& normal, const PointPair* plane,
                         bool skip_known, double toi, ContactKind kind, double reach,
                         const Mat3& ra, const Vec3& pa, const Mat3& rb, const Vec3& pb,
                         ContactRows& out) const {
  if (plane == nullptr) return;
  const double gap = (plane->on_b - plane->on_a).dot(normal);   // m, the deepest point's
  std::size_t first = out.size();
  for (int side = 0; side < 2; ++side) {
    // B's corners approach A along -n, A's approach B along +n; only a movable body's (a
    // sphere's one lowest point is its contact already, unless the contact is carried from
    // the previous state: !skip_known), only towards a flat-faced partner (a curved one
    // falls away from its tangent plane)
    const int body = side == 0 ? b : a, partner = side == 0 ? a : b;
    if (bodies_[body].fixed || (skip_known && shapes_[body].single_point) ||
        shapes_[partner].curved)
      continue;
    const Mat3& r = side == 0 ? rb : ra;
    const Vec3& p = side == 0 ? pb : pa;
    const Mat3& r_partner = side == 0 ? ra : rb;
    const Vec3& p_partner = side == 0 ? pa : pb;
    const Vec3 towards = side == 0 ? Vec3(-normal) : normal;       // world
    const Vec3 on_plane = side == 0 ? plane->on_a : plane->on_b;
    const BodyShape& shape = shapes_[body];
    lowest_points(shape, shape.rotation.transpose() * (r.transpose() * towards), lane.corners);
    for (Vec3& corner : lane.corners) corner = r * (shape.rotation * corner + shape.offset) + p;
    lane.heights.clear();
    for (std::size_t k = 0; k < lane.corners.size(); ++k) {
      const Vec3& q = lane.corners[k];   // world
      const double height = (on_plane - q).dot(towards);
      if (!(height <= reach)) continue;
      // within the patch's band about the deepest point's gap: a corner of the manifold
      // already, or one beside the partner's face (the patch holds the face's points)
      if (skip_known && std::fabs(height - gap) < kPatchTolerance) continue;
      // on the partner: its projection within the partner's box (grown by the margin); a
      // plane has no box (it is unbounded: every corner is over it), and a sphere's point
      // carried from the previous state touched it there (a ball driven through a corner
      // of two walls is beside both faces at the end of the step)
      auto within = [&] {
        const Vec3 local = r_partner.transpose() * (q + height * towards - p_partner);
        const Vec3 grow = Vec3::Constant(settings_.speculative_margin);
        return (local.array() >= (shapes_[partner].local_lo - grow).array()).all() &&
               (local.array() <= (shapes_[partner].local_hi + grow).array()).all();
      };
      if (shapes_[partner].kind == ShapeKind::plane || (!skip_known && shape.single_point) ||
          within()) {
        lane.heights.emplace_back(height, static_cast<int>(k));
      }
    }
    std::sort(lane.heights.begin(), lane.heights.end());
    if (lane.heights.size() > static_cast<std::size_t>(kMaxManifoldPoints))
      lane.heights.resize(kMaxManifoldPoints);
    const BodyShape& sa = shapes_[a];
    const BodyShape& sb = shapes_[b];
    if (!skip_known) lane.row_codes.clear();
    for (const auto& [height, k] : lane.heights) {
      // the point midway between the corner and the plane, as every contact's (the solver
      // finds each body's own point from it and the separation); a contact carried from
      // the previous state (!skip_known) gets the feature ids of a patch (its warm start
      // carries over), else one beyond every patch feature
      const Vec3 point = lane.corners[k] + 0.5 * height * towards;
      std::int64_t feature = 729 * 16 + 512 * side + k % 512 + kPiecePairFeature *
          (static_cast<std::int64_t>(sa.piece) * kMaxPieces + sb.piece);
      if (!skip_known) {
        const Vec3 on_plane = lane.corners[k] + height * towards;
        const Vec3& on_a = side == 0 ? on_plane : lane.corners[k];
        const Vec3& on_b = side == 0 ? lane.corners[k] : on_plane;
        feature = feature_of(lane, a, b, ra.transpose() * (on_a - pa), rb.transpose() * (on_b - pb));
      }
      out.add(sa, sb, point, normal, height, toi, kind, feature);
    }
    out.close_manifold(sa.body, sb.body, first);   // each body's corners: one manifold
    first = out.size();
  }
}

void Detector::current_manifold(Lane& lane, int a, int b, ContactRows& out) const {
  const Body& A = bodies_[a];
  const Body& B = bodies_[b];
  const coal::CollisionGeometry& ga = *shapes_[a].geometry;
  const coal::CollisionGeometry& gb = *shapes_[b].geometry;
  double distance = 0.0;
  Vec3 normal;
  PointPair witness;
  const double margin = pair_margin(a, b);
  if (!lane.query.contact(ga, A.pose1, gb, B.pose1, margin, distance, normal, witness)) return;
  const double reach = margin + relative_motion(a, b);
  const double deep = kDeepFraction * std::min(shapes_[a].thickness, shapes_[b].thickness);
  if (-distance > deep && deep_persistent(lane, a, b, deep, reach, out)) return;
  lane.points.clear();
  if (shapes_[a].single_point || shapes_[b].single_point) {
    lane.points.push_back(witness);
  } else {
    lane.query.manifold(ga, A.pose1, gb, B.pose1, settings_.linear_slop, lane.points);
  }
  emit(lane, a, b, normal, 0.0, ContactKind::persistent, kInf, A.r1, A.p1, B.r1, B.p1, out);
  const Vec3 unit = normal.normalized();
  speculate(lane, a, b, unit, deepest(lane.points, unit), true, 0.0, ContactKind::persistent, reach, A.r1, A.p1,
            B.r1, B.p1, out);
}

bool Detector::deep_persistent(Lane& lane, int a, int b, double deep, double reach,
                               ContactRows& out, const Vec3* facing) const {
  const Motion ma = motion(a), mb = motion(b);
  double distance = 0.0;
  Vec3 normal;
  PointPair witness;
  if (!lane.previous_query.contact(*shapes_[a].geometry, ma.at(0.0), *shapes_[b].geometry,
                               mb.at(0.0), settings_.speculative_margin, distance, normal,
                               witness) ||
      -distance > deep) {
    return false;   // the previous state is no shallow touch: EPA's answer now stands
  }
  // the previous state's normal and touching points, carried along with each body
  const Body& A = bodies_[a];
  const Body& B = bodies_[b];
  const Mat3 turn_a = A.r1 * ma.rotation_at(0.0).transpose();
  const Mat3 turn_b = B.r1 * mb.rotation_at(0.0).transpose();
  const Vec3 unit = (turn_a * normal).normalized();
  // past each other: the contact now faces more than 60 deg away from the one they touched
  // at (a ball driven into a wall's inner face out of its far face or its end)
  constexpr double kTurned = 0.5;   // cosine
  if (facing != nullptr && !(unit.dot(facing->normalized()) < kTurned)) return false;
  const PointPair plane{turn_a * (witness.on_a - ma.position_at(0.0)) + A.p1,
                        turn_b * (witness.on_b - mb.position_at(0.0)) + B.p1};
  const std::size_t first = out.size();
  speculate(lane, a, b, unit, &plane, false, 0.0, ContactKind::persistent, reach, A.r1, A.p1, B.r1,
            B.p1, out);
  return out.size() > first;
}

std::int64_t Detector::feature_of(Lane& lane, int a, int b, const Vec3& local_a,
                                  const Vec3& local_b) const {
  // the corner or face in each piece's own frame (a body's frame when it is one shape)
  const BodyShape& sa = shapes_[a];
  const BodyShape& sb = shapes_[b];
  const std::int64_t code =
      feature_code(sa.rotation.transpose() * (local_a - sa.frame_position), sa.half,
                   sb.rotation.transpose() * (local_b - sb.frame_position), sb.half);
  const std::int64_t rank = std::count(lane.row_codes.begin(), lane.row_codes.end(), code);
  lane.row_codes.push_back(code);
  return code + 729 * rank + kPiecePairFeature *
      (static_cast<std::int64_t>(sa.piece) * kMaxPieces + sb.piece);
}

void Detector::emit(Lane& lane, int a, int b, const Vec3& normal_in, double toi,
                    ContactKind kind, double cap, const Mat3& ra, const Vec3& pa,
                    const Mat3& rb, const Vec3& pb, ContactRows& out) const {
  const double length = normal_in.norm();
  const Vec3 normal = normal_in / std::max(length, 1e-300);
  // a persistent manifold is stored for `reuse`, which never reuses a curved body's points
  const bool store = kind == ContactKind::persistent && !shapes_[a].curved && !shapes_[b].curved;
  if (store) {
    const Body& A = bodies_[a];
    const Body& B = bodies_[b];
    lane.next.begin(static_cast<std::int64_t>(a) * pieces() + b,
                A.r1.transpose() * (B.p1 - A.p1), A.q1.conjugate() * B.q1);
  }
  lane.row_codes.clear();
  const std::size_t first = out.size();
  for (const PointPair& p : lane.points) {
    double separation = (p.on_b - p.on_a).dot(normal);
    if (std::isfinite(cap)) separation = std::min(separation, cap);
    const Vec3 local_a = ra.transpose() * (p.on_a - pa);
    const Vec3 local_b = rb.transpose() * (p.on_b - pb);
    const BodyShape& sa = shapes_[a];
    const BodyShape& sb = shapes_[b];
    const std::int64_t feature = feature_of(lane, a, b, local_a, local_b);
    out.add(sa, sb, 0.5 * (p.on_a + p.on_b), normal, separation, toi, kind, feature);
    if (store) lane.next.add_row({local_a, local_b, ra.transpose() * normal, feature});
  }
  out.close_manifold(shapes_[a].body, shapes_[b].body, first);
}

}  // namespace collres
