// Detection bindings: collres::Detector over numpy arrays (no logic here); poses may be
// strided views (float_rows, bindings.h).
#include <pybind11/numpy.h>
#include <pybind11/stl.h>

#include <array>
#include <memory>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "bindings.h"
#include "detection.h"
#include "shapes.h"

namespace py = pybind11;

namespace {

using Mask = py::array_t<std::uint8_t, py::array::c_style>;

// A numpy array that owns a moved-in std::vector (no copy).
template <class T>
py::array owned(std::vector<T>&& data, std::vector<py::ssize_t> shape) {
  auto* holder = new std::vector<T>(std::move(data));
  py::capsule free(holder, [](void* p) { delete static_cast<std::vector<T>*>(p); });
  return py::array_t<T>(shape, holder->data(), free);
}

// A step's poses and twists: float64 (N, 3) / (N, 4) rows, C-contiguous or strided views
// gathered into `scratch` (float_rows, bindings.h), and the (N,) uint8 active mask.
struct Poses {
  collres::StepPoses poses;
  RowScratch scratch[8];
};

void poses_of(const collres::Detector& detector, const py::array& p0, const py::array& q0,
              const py::array& p1, const py::array& q1, const py::array& linear,
              const py::array& angular, const py::array& linear0, const py::array& angular0,
              const std::optional<py::array>& active, Poses& out) {
  const py::ssize_t n = detector.count();
  collres::StepPoses& poses = out.poses;
  poses.count = detector.count();
  poses.p0 = float_rows(p0, n, 3, "p0", out.scratch[0]);
  poses.q0 = float_rows(q0, n, 4, "q0", out.scratch[1]);
  poses.p1 = float_rows(p1, n, 3, "p1", out.scratch[2]);
  poses.q1 = float_rows(q1, n, 4, "q1", out.scratch[3]);
  poses.linear = float_rows(linear, n, 3, "linear", out.scratch[4]);
  poses.angular = float_rows(angular, n, 3, "angular", out.scratch[5]);
  poses.linear0 = float_rows(linear0, n, 3, "linear0", out.scratch[6]);
  poses.angular0 = float_rows(angular0, n, 3, "angular0", out.scratch[7]);
  if (active) {
    if (!py::isinstance<Mask>(*active) || active->ndim() != 1 || active->shape(0) != n) {
      throw py::value_error("active: expected a C-contiguous uint8 array of shape (N,)");
    }
    poses.active = static_cast<const std::uint8_t*>(active->data());
  }
}

}  // namespace

void bind_detection(py::module_& m) {
  // before any query of this process's core: coal's box support fixes its inflate factor on
  // its first call (shapes.h); one that is not 1 was fixed by an earlier coal query
  const std::array<double, 2> inflate = collres::pin_box_support();
  m.attr("BOX_SUPPORT_INFLATE") = py::make_tuple(inflate[0], inflate[1]);
  if (inflate[0] != 1.0 || inflate[1] != 1.0) {
    // a user's own coal query came first: this process's boxes are grown by ~1e-10 relative
    // (physically nothing, but contacts then differ bit for bit from a fresh process's)
    if (PyErr_WarnEx(PyExc_RuntimeWarning,
                     "coal's box support was first called before collres_ros.core was "
                     "imported and now inflates boxes by about 1e-10 (relative) in this "
                     "process: contacts differ at that level from a fresh process's; import "
                     "collres_ros.core before any coal query for reproducible results",
                     1) < 0) {
      throw py::error_already_set();
    }
  }
  m.attr("HULL_FLATNESS") = collres::kHullFlatness;
  m.attr("RESTING_MARGIN") = collres::kRestingMargin;
  m.def("extreme_vertices",
        [](const py::array_t<double, py::array::c_style | py::array::forcecast>& points,
           int count) {
          if (points.ndim() != 2 || points.shape(1) != 3) {
            throw py::value_error("points: expected an array of shape (K, 3)");
          }
          const std::vector<double> flat(points.data(), points.data() + points.size());
          std::vector<std::int64_t> chosen;
          {
            py::gil_scoped_release release;
            chosen = collres::extreme_vertices(flat, count);
          }
          return chosen;
        },
        py::arg("points"), py::arg("count"),
        "Indices of at most `count` vertices of (K, 3) points extreme along `count` evenly "
        "spread directions (shapes.h: a hull simplified to a vertex budget).");
  m.def("triangle_problem", &collres::triangle_problem, py::arg("corners"),
        "Why these three corners (flat x, y, z, m) make no triangle, or '' when they do "
        "(shapes.h: not finite, beyond 1e9 m, no area).");
  m.def("hull_problem", &collres::hull_problem, py::arg("points"),
        "Why no convex hull can be built of these vertices (flat x, y, z, m), or '' when one "
        "can (shapes.h: too few, not finite, coincident, collinear or flat points).");
  py::class_<collres::DetectionSettings>(
      m, "DetectionSettings",
      "What detection reads, each field named as in collres_ros.core.config.SolverSettings "
      "(see there for units and ranges); handed over by name (detection.py).")
      .def(py::init<>())
      .def_readwrite("speculative_margin", &collres::DetectionSettings::speculative_margin)
      .def_readwrite("toi_tolerance", &collres::DetectionSettings::toi_tolerance)
      .def_readwrite("toi_max_iterations", &collres::DetectionSettings::toi_max_iterations)
      .def_readwrite("ccd", &collres::DetectionSettings::ccd)
      .def_readwrite("linear_slop", &collres::DetectionSettings::linear_slop)
      .def_readwrite("restitution_threshold",
                     &collres::DetectionSettings::restitution_threshold)
      .def_readwrite("resting_factor", &collres::DetectionSettings::resting_factor)
      .def_readwrite("reuse_shift", &collres::DetectionSettings::reuse_shift)
      .def_readwrite("margin_speed", &collres::DetectionSettings::margin_speed)
      .def_readwrite("max_pairs", &collres::DetectionSettings::max_pairs)
      .def_readwrite("max_contacts", &collres::DetectionSettings::max_contacts)
      .def_readwrite("max_contacts_per_pair",
                     &collres::DetectionSettings::max_contacts_per_pair);
  py::class_<collres::Detector>(m, "Detector", "Broad phase, narrow phase, manifolds and "
                                "time of impact of a fixed list of bodies (detection.h).")
      .def(py::init([](const std::vector<int>& kinds, const std::vector<std::vector<double>>& sizes,
                       const std::vector<std::vector<double>>& points,
                       const std::vector<double>& radius, const std::vector<bool>& fixed,
                       std::vector<int> body, std::vector<int> piece,
                       std::vector<std::vector<double>> pose, int bodies) {
             const std::size_t n = kinds.size();
             if (body.empty() && piece.empty() && pose.empty() && bodies < 0) {
               // one shape per body, each on its body's frame
               for (std::size_t k = 0; k < n; ++k) body.push_back(static_cast<int>(k));
               piece.assign(n, 0);
               pose.assign(n, {0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0});
               bodies = static_cast<int>(n);
             }
             if (sizes.size() != n || points.size() != n || radius.size() != n ||
                 fixed.size() != n || body.size() != n || piece.size() != n ||
                 pose.size() != n) {
               throw py::value_error("kinds, sizes, points, radius, static, body, piece, "
                                     "pose: one per shape");
             }
             std::vector<collres::BodyShape> shapes;
             for (std::size_t k = 0; k < n; ++k) {
               shapes.push_back(collres::make_shape(kinds[k], sizes[k], points[k], radius[k],
                                                    fixed[k]));
               if (pose[k].size() != 7) throw py::value_error("pose: x, y, z, qx, qy, qz, qw");
               const collres::Vec3 position(pose[k][0], pose[k][1], pose[k][2]);
               const collres::Quat turn(pose[k][6], pose[k][3], pose[k][4], pose[k][5]);
               const bool placed = !position.isZero(0.0) || !turn.coeffs().isApprox(
                   collres::Quat::Identity().coeffs(), 0.0);
               if (placed || piece[k] != 0) {
                 if (!position.allFinite() || !turn.coeffs().allFinite() || turn.norm() < 0.5) {
                   throw py::value_error("pose: a finite position and a unit quaternion");
                 }
                 collres::place_piece(shapes.back(), body[k], piece[k], position, turn);
               } else {
                 shapes.back().body = body[k];
               }
             }
             return std::make_unique<collres::Detector>(std::move(shapes), bodies);
           }),
           py::arg("kinds"), py::arg("sizes"), py::arg("points"), py::arg("radius"),
           py::arg("static"), py::arg("body") = std::vector<int>{},
           py::arg("piece") = std::vector<int>{},
           py::arg("pose") = std::vector<std::vector<double>>{}, py::arg("bodies") = -1,
           "Per shape, in body order: shape code (index in SHAPE_KINDS), sizes, convex "
           "vertices or a triangle's corners (flat, m, piece frame), bounding radius about the body origin (m), "
           "static, its body, its index among that body's pieces, the piece frame's pose in "
           "the body frame (x, y, z m, qx, qy, qz, qw); the number of bodies. Without the "
           "last four: one shape per body.")
      .def_property(
          "settings",
          [](const collres::Detector& d) { return collres::DetectionSettings(d.settings()); },
          &collres::Detector::set_settings,
          "The DetectionSettings (a copy; assign a whole one: it takes effect at the next "
          "step, a new margin forgets the manifolds).")
      .def("budget",
           [](const collres::Detector& d) {
             return py::make_tuple(d.budget().pairs_dropped, d.budget().rows_dropped);
           },
           "What the budget dropped in the last detect: (pairs never queried, contact rows "
           "beyond max_contacts).")
      .def_property_readonly("helped", [](const collres::Detector& d) {
        return py::make_tuple(d.helped(), d.chunks_run());
      }, "Chunks of the pairs' second halves run so far: (by the second thread, in all).")
      .def_property_readonly("runs", [](const collres::Detector& d) {
        return py::make_tuple(d.paired_runs(), d.runs());
      }, "Detects posted for two threads so far: (run paired, in all); the others the cost "
         "model ran on the calling thread alone.")
      .def("set_filter", &collres::Detector::set_filter, py::arg("group"), py::arg("mask"),
           py::arg("ignored"),
           "Collision filter for the next step: per body group and mask bits, ignored "
           "pairs (a, b) of body indices; a pair collides when (group[a] & mask[b]) and "
           "(group[b] & mask[a]) are non-zero and it is not ignored.")
      .def("detect",
           [](collres::Detector& d, const py::array& p0, const py::array& q0,
              const py::array& p1, const py::array& q1, const py::array& linear,
              const py::array& angular, const py::array& linear0,
              const py::array& angular0, const std::optional<py::array>& active,
              int threads, double dt) {
             if (threads < 1 || threads > 2) throw py::value_error("threads: 1 or 2");
             if (!(dt >= 0.0)) throw py::value_error("dt: a period >= 0 s");
             Poses in;
             poses_of(d, p0, q0, p1, q1, linear, angular, linear0, angular0, active, in);
             in.poses.dt = dt;
             const collres::StepPoses& poses = in.poses;
             collres::ContactRows rows;
             {
               py::gil_scoped_release release;
               d.set_threads(threads);
               d.detect(poses, rows);
             }
             const auto m_rows = static_cast<py::ssize_t>(rows.size());
             const auto k_manifolds = static_cast<py::ssize_t>(rows.manifolds.size() /
                                                               collres::kManifoldFields);
             return py::make_tuple(
                 owned(std::move(rows.body_a), {m_rows}), owned(std::move(rows.body_b), {m_rows}),
                 owned(std::move(rows.point), {m_rows, 3}),
                 owned(std::move(rows.normal), {m_rows, 3}),
                 owned(std::move(rows.separation), {m_rows}), owned(std::move(rows.toi), {m_rows}),
                 owned(std::move(rows.kind), {m_rows}), owned(std::move(rows.feature), {m_rows}),
                 owned(std::move(rows.manifolds), {k_manifolds, collres::kManifoldFields}),
                 owned(std::move(rows.piece_a), {m_rows}), owned(std::move(rows.piece_b), {m_rows}));
           },
           py::arg("p0"), py::arg("q0"), py::arg("p1"), py::arg("q1"), py::arg("linear"),
           py::arg("angular"),
           py::arg("linear0"), py::arg("angular0"), py::arg("active") = py::none(),
           py::arg("threads") = 1, py::arg("dt") = 0.0,
           "Contacts of the step: (body_a, body_b, point, normal, separation, toi, kind, "
           "feature, manifolds, piece_a, piece_b), the fields of ContactSet; the same bits "
           "with `threads` 1 or 2. `dt` (s) the step's period, which sets the least margin "
           "of a pair at rest (0: kRestingMargin's alone).")
      .def("hold_back",
           [](collres::Detector& d, const py::array& p0, const py::array& q0,
              const py::array& p1, const py::array& q1, const py::array& linear,
              const py::array& angular, const py::array& linear0,
              const py::array& angular0, const std::optional<py::array>& active) {
             Poses in;
             poses_of(d, p0, q0, p1, q1, linear, angular, linear0, angular0, active, in);
             const collres::StepPoses& poses = in.poses;
             std::vector<double> fraction;
             {
               py::gil_scoped_release release;
               d.hold_back(poses, fraction);
             }
             const auto n = static_cast<py::ssize_t>(fraction.size());
             return owned(std::move(fraction), {n});
           },
           py::arg("p0"), py::arg("q0"), py::arg("p1"), py::arg("q1"), py::arg("linear"),
           py::arg("angular"),
           py::arg("linear0"), py::arg("angular0"), py::arg("active") = py::none(),
           "Per body, the fraction of its motion from the previous pose (p0, q0) to the "
           "answer (p1, q1) it may keep against fixed shapes (1: all of it; Detector::"
           "hold_back).")
      .def("candidate_pairs",
           [](collres::Detector& d, const py::array& p0, const py::array& q0,
              const py::array& p1, const py::array& q1, const py::array& linear,
              const py::array& angular, const py::array& linear0,
              const py::array& angular0, const std::optional<py::array>& active) {
             Poses in;
             poses_of(d, p0, q0, p1, q1, linear, angular, linear0, angular0, active, in);
             const collres::StepPoses& poses = in.poses;
             std::vector<std::pair<int, int>> pairs;
             {
               py::gil_scoped_release release;
               d.candidate_pairs(poses, pairs);
             }
             return pairs;
           },
           py::arg("p0"), py::arg("q0"), py::arg("p1"), py::arg("q1"), py::arg("linear"),
           py::arg("angular"),
           py::arg("linear0"), py::arg("angular0"), py::arg("active") = py::none(),
           "Broad-phase pairs (a < b), sorted.")
      .def("reset", &collres::Detector::reset, "Forget the stored manifolds.");
}
