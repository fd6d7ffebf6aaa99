// Collision shapes of the detection half: coal geometries built from plain numbers.
//
// Frames and units: the body frame is the shape frame and its origin is the centre of mass
// (m). Every coal geometry is centred on its own origin, which sits at `offset` in the body
// frame (non-zero only for cones: coal centres a cone on the middle of its axis, our cone's
// origin is its centre of mass, a quarter of the length above the base). Planes are coal
// half-spaces n.x <= d (body frame, n unit); they are never put in a tree (their bounds
// are infinite) and are tested against every finite body directly. Triangles are the
// pieces of a static triangle-mesh body (scenery that stays concave: a bin, a shelf), one
// coal TriangleP each, in the body frame; a triangle is one-sided: its front is the side
// its corners a, b, c turn counter-clockwise about ((b - a) x (c - a)), and its contacts
// take its face's normal unless they touch an active edge (manifold.h).
#pragma once

#include <array>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include <coal/collision_object.h>
#include <coal/shape/geometric_shapes.h>

#include "detection_types.h"

namespace collres {

// Shape codes: the index of the shape name in collres_ros.core.types.SHAPE_KINDS.
enum class ShapeKind : int { sphere = 0, box = 1, capsule = 2, cylinder = 3, cone = 4,
                             plane = 5, convex = 6, triangle = 7 };

// A triangle of a triangle mesh: coal's TriangleP (collision queries see only that) and
// which of its edges a-b, b-c, c-a are active: on the mesh's boundary or a convex crease
// (mark_active_edges). An edge between coplanar triangles or in a concave crease is
// inactive: it never gives a contact its normal (manifold.h), so a box sliding over a
// flat floor of many triangles does not catch on the edges between them.
struct MeshTriangle : coal::TriangleP {
  MeshTriangle(const Vec3& a, const Vec3& b, const Vec3& c) : coal::TriangleP(a, b, c) {}
  MeshTriangle* clone() const override { return new MeshTriangle(*this); }
  std::array<bool, 3> active{{true, true, true}};
};

// An edge is a convex crease when the neighbour's far corner lies behind the triangle's
// plane by more than this fraction of its distance (sin of about 1 deg); flatter, it is
// inactive.
constexpr double kCreaseSine = 0.0175;

// One collision shape: a body's only shape, or one piece of a compound body (as Box2D's and
// Jolt's shapes: each with its body and a pose in that body's frame). A piece's frame sits
// at `frame_position` with `rotation` in the body frame (zero and identity for a body of
// one shape); the coal geometry is turned by `rotation` and centred at `offset`.
struct BodyShape {
  ShapeKind kind = ShapeKind::sphere;
  std::shared_ptr<coal::CollisionGeometry> geometry;
  int body = 0;                    // the body it belongs to
  int piece = 0;                   // its index among that body's pieces
  Vec3 frame_position = Vec3::Zero();  // m, the piece frame's origin in the body frame
  Mat3 rotation = Mat3::Identity();    // piece (and geometry) axes in the body frame
  Vec3 offset = Vec3::Zero();      // m, geometry origin in the body frame
  Vec3 local_lo = Vec3::Zero();    // m, body-frame box of the shape (offset included)
  Vec3 local_hi = Vec3::Zero();
  Vec3 half = Vec3::Zero();        // m, half extents of the geometry's own box (+inf planes)
  double radius = 0.0;             // m, origin-centred bounding sphere (+inf for planes)
  double thickness = 0.0;          // m, smallest half extent (+inf for planes and
                                   // triangles: one-sided, their normal is their face's)
  Vec3 plane_normal = Vec3::UnitZ();  // planes: unit normal, body frame
  double plane_offset = 0.0;          // planes: d (m), the solid is n.x <= d
  bool is_static = false;          // static or a plane: never moved by the solver
  bool curved = false;             // a curved surface (sphere, capsule, cylinder, cone):
                                   // its contact points slide over it as it rolls
  bool single_point = false;       // touches at one point only (sphere)
  std::vector<Vec3> vertices;      // m, geometry frame: a box's corners, a convex's points,
                                   // a triangle's corners
  double round = 0.0;              // m: capsule, cylinder, cone radius; sphere radius
  double axis = 0.0;               // m: capsule segment, cylinder, cone length along z
};

// The points of a shape that come first along `down` (unit, the coal geometry's frame):
// a polytope's vertices (all of them), a sphere's lowest point, a capsule's two cap
// points, a cylinder's two rim points and a cone's apex and rim point, each the lowest of
// its cap or rim along `down` (four rim points when `down` is along the axis). In the
// geometry's frame (body frame: rotation * point + offset), m; `out` is cleared first.
// The corners that speculative contacts watch (detection.h).
void lowest_points(const BodyShape& shape, const Vec3& down, std::vector<Vec3>& out);

// Convex vertices must span a volume: the thickness of the first simplex qhull would build
// (its height over the plane of three extreme points) above this fraction of the points'
// extent. qhull reports a flatter set (and other invalid input) through an error stream
// coal leaves unset, and the process dies; measured: a 1 m square with an apex 1e-8 m above
// it kills it, 3e-8 m does not. Refused well before that, with a reason.
constexpr double kHullFlatness = 1e-6;
// |vertex coordinate| (m, body frame) at most this: far beyond any size the params allow, low
// enough that the products qhull forms stay finite.
constexpr double kHullCoordinateLimit = 1e9;

// Why no hull can be built of these vertices (K x 3, row-major, m), or "" when one can:
// fewer than 4 points, not x, y, z triples, a non-finite or too large coordinate, all
// points at one spot, on one line or in one plane (within kHullFlatness of their extent).
std::string hull_problem(const std::vector<double>& points);

// A triangle's corners (3 x 3, row-major, m) must be finite, within kHullCoordinateLimit
// and span an area: twice its area above kHullFlatness times its longest edge squared.
// Why not, or "" when they do.
std::string triangle_problem(const std::vector<double>& corners);

// Indices (increasing) of at most `count` vertices (K x 3, row-major) that are extreme along
// `count` directions spread evenly over the sphere (a Fibonacci lattice, about the centre of
// the points' box): vertices of the hull whose own hull approximates it from inside. How a
// hull of many vertices is simplified to a vertex budget (as PhysX caps a convex mesh at 255
// vertices); O(K count).
std::vector<std::int64_t> extreme_vertices(const std::vector<double>& points, int count);

// A shape from its code, sizes (sphere [r]; box [x, y, z] full edges; capsule, cylinder,
// cone [r, length] along z; plane [nx, ny, nz, d]) and, for convex, its vertices (K x 3,
// row-major, body frame); for a triangle its corners a, b, c (3 x 3, body frame, static
// only; see triangle_problem). `radius` is the bounding radius about the body origin (m), as
// collres_ros.core.shapes.bounding_radius gives it. Sizes are validated by the caller;
// std::invalid_argument for any input no coal geometry can be made of (never a crash).
BodyShape make_shape(int kind, const std::vector<double>& size,
                     const std::vector<double>& points, double radius, bool is_static);

// The active edges of every body's triangles (shapes in body order): an edge shared by two
// triangles of one body (the same corners, exactly) is inactive unless it is a convex
// crease; an edge of one triangle, or of more than two, stays active.
void mark_active_edges(std::vector<BodyShape>& shapes);

// Put a finite shape into a compound body as its piece `piece` of body `body`: its frame at
// `position` (m) turned by the unit quaternion `orientation` in the body frame; the body-frame
// box grows to hold the turned geometry. `radius` stays as given (about the body origin).
void place_piece(BodyShape& shape, int body, int piece, const Vec3& position,
                 const Quat& orientation);

// coal 3's box support function (getShapeSupport of a Box) keeps a function-local
// `static const inflate`, set once per process (one per SupportOptions) by the direction of
// its first call: 1 + 1e-10 when that direction has a zero component, else 1; every later
// support point of every box (GJK, EPA, contact patches) pushes the box's faces that the
// direction does not point at outwards by that factor. So one process's contacts depended on
// which box query it ran first (a box on a plane asks along an axis: 1e-11 m of separation,
// then other patch points and feature ids). pin_box_support makes those first calls
// itself, along a direction free of zeros (inflate 1: the exact box), and returns the
// factors then in force, [NoSweptSphere, WithSweptSphere], read back from support points
// along -x-y-z (-inflate times the half sides). The module calls it at import, before any
// query; a factor other than 1 says a coal query of a box ran earlier in the process (the
// import then warns and exposes the factors as _native.BOX_SUPPORT_INFLATE).
std::array<double, 2> pin_box_support();

}  // namespace collres
