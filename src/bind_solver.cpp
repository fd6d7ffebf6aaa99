// Solver bindings: combine rules, the contact cache and the solver step.
//
// Arrays are taken as they are (no conversion, no copy): each must be a C-contiguous
// numpy array of the documented dtype and shape, outputs writable, or a TypeError /
// ValueError names it; body states may be strided views (float_rows, bindings.h). The step
// releases the GIL while it runs.
#include <pybind11/numpy.h>
#include <pybind11/stl.h>

#include <cstdint>
#include <initializer_list>
#include <string>
#include <vector>

#include "bindings.h"
#include "contact_cache.h"
#include "contact_solver.h"
#include "step.h"

namespace py = pybind11;
using namespace collres;

namespace {

// The data pointer of `array`, checked: dtype T, C-contiguous, this shape (-1: any size,
// the same for every array given `count`), writable if `out`.
template <class T>
T* checked(const py::array& array, const char* name, std::initializer_list<py::ssize_t> shape,
           bool out = false) {
  if (!array.dtype().is(py::dtype::of<T>()))
    throw py::type_error(std::string(name) + ": wrong dtype " +
                         py::str(array.dtype()).cast<std::string>());
  if (!(array.flags() & py::array::c_style))
    throw py::value_error(std::string(name) + ": not C-contiguous");
  if (out && !array.writeable()) throw py::value_error(std::string(name) + ": read-only");
  bool ok = array.ndim() == static_cast<py::ssize_t>(shape.size());
  py::ssize_t d = 0;
  for (const py::ssize_t size : shape) ok = ok && array.shape(d++) == size;
  if (!ok) throw py::value_error(std::string(name) + ": wrong shape");
  return static_cast<T*>(const_cast<void*>(array.data()));
}


// Body states (position, orientation, linear, angular), each float64 rows of (n, width):
// C-contiguous, or strided views gathered into `scratch` (float_rows; written back after the
// step for `out`).
struct States {
  py::array arrays[4];
  double* data[4] = {nullptr, nullptr, nullptr, nullptr};
  RowScratch scratch[4];
};

void states_of(const py::tuple& t, py::ssize_t n, const char* name, States& s, bool out) {
  if (t.size() != 4) throw py::value_error(std::string(name) + ": (position, orientation, "
                                           "linear, angular) expected");
  const py::ssize_t width[4] = {3, 4, 3, 3};
  for (int i = 0; i < 4; ++i) {
    s.arrays[i] = py::array(py::object(t[i]));
    s.data[i] = float_rows(s.arrays[i], n, width[i], name, s.scratch[i], out);
  }
}

BodyStatesView states_view(const States& s) {
  return BodyStatesView{s.data[0], s.data[1], s.data[2], s.data[3]};
}

py::tuple solver_step(StepSolver& solver, const py::tuple& previous, const py::tuple& current,
                      const py::tuple& out_states, const py::array& inv_mass,
                      const py::array& inv_inertia_body, const py::array& movable,
                      const py::array& held, const py::array& restitution,
                      const py::array& static_friction, const py::array& kinetic_friction,
                      const py::array& rolling_resistance,
                      const py::array& torsional_friction, const py::array& radius,
                      const py::array& a, const py::array& b, const py::array& point,
                      const py::array& normal, const py::array& separation,
                      const py::array& toi, const py::array& kind, const py::array& feature,
                      const py::array& manifolds, double dt, bool warm, const SolverParams& params,
                      const py::array& normal_impulse, const py::array& friction_impulse,
                      const py::array& state, const py::array& reported_toi,
                      const py::array& reported_kind) {
  const py::ssize_t n = inv_mass.ndim() == 1 ? inv_mass.shape(0) : -1;
  const py::ssize_t m = a.ndim() == 1 ? a.shape(0) : -1;
  States previous_states, current_states, out_states_;
  states_of(previous, n, "previous", previous_states, false);
  states_of(current, n, "current", current_states, false);
  states_of(out_states, n, "out", out_states_, true);
  const BodyStatesView prev = states_view(previous_states);
  const BodyStatesView cur = states_view(current_states);
  BodyStatesOut out{out_states_.data[0], out_states_.data[1], out_states_.data[2],
                    out_states_.data[3]};
  BodyProperties bodies;
  bodies.count = n;
  bodies.inv_mass = checked<double>(inv_mass, "inv_mass", {n});
  bodies.inv_inertia_body = checked<double>(inv_inertia_body, "inv_inertia_body", {n, 3, 3});
  bodies.movable = reinterpret_cast<const uint8_t*>(checked<bool>(movable, "movable", {n}));
  bodies.held = reinterpret_cast<const uint8_t*>(checked<bool>(held, "held", {n}));
  bodies.restitution = checked<double>(restitution, "restitution", {n});
  bodies.static_friction = checked<double>(static_friction, "static_friction", {n});
  bodies.kinetic_friction = checked<double>(kinetic_friction, "kinetic_friction", {n});
  bodies.rolling_resistance = checked<double>(rolling_resistance, "rolling_resistance", {n});
  bodies.torsional_friction = checked<double>(torsional_friction, "torsional_friction", {n});
  bodies.radius = checked<double>(radius, "radius", {n});
  ContactsView c;
  c.count = m;
  c.a = checked<int64_t>(a, "body_a", {m});
  c.b = checked<int64_t>(b, "body_b", {m});
  c.point = checked<double>(point, "point", {m, 3});
  c.normal = checked<double>(normal, "normal", {m, 3});
  c.separation = checked<double>(separation, "separation", {m});
  c.toi = checked<double>(toi, "toi", {m});
  c.kind = checked<int8_t>(kind, "kind", {m});
  c.feature = checked<int64_t>(feature, "feature", {m});
  for (py::ssize_t k = 0; k < m; ++k)
    if (c.a[k] < 0 || c.a[k] >= n || c.b[k] < 0 || c.b[k] >= n)
      throw py::index_error("contact body index out of range");
  c.manifold_count = manifolds.ndim() == 2 ? manifolds.shape(0) : -1;
  c.manifolds = checked<int64_t>(manifolds, "manifolds", {c.manifold_count, kManifoldFields});
  // the manifolds tile the rows in order, each of one pair (its rows' a and b)
  int64_t next = 0;
  for (int64_t s = 0; s < c.manifold_count; ++s) {
    const int64_t* span = c.manifolds + kManifoldFields * s;
    bool ok = span[2] == next && span[3] >= 1 && span[2] + span[3] <= m;
    for (int64_t k = span[2]; ok && k < span[2] + span[3]; ++k)
      ok = c.a[k] == span[0] && c.b[k] == span[1];
    if (!ok) throw py::value_error("manifolds: not (a, b, first, count) spans tiling the rows");
    next = span[2] + span[3];
  }
  if (next != m) throw py::value_error("manifolds: not (a, b, first, count) spans tiling the rows");
  ContactsOut r;
  r.normal_impulse = checked<double>(normal_impulse, "normal_impulse", {m}, true);
  r.friction_impulse = checked<double>(friction_impulse, "friction_impulse", {m, 3}, true);
  r.state = checked<uint8_t>(state, "state", {m}, true);
  r.toi = checked<double>(reported_toi, "reported_toi", {m}, true);
  r.kind = checked<int8_t>(reported_kind, "reported_kind", {m}, true);
  StepStats stats;
  {
    py::gil_scoped_release release;
    stats = solver.step(prev, cur, bodies, c, dt, warm, params, out, r);
  }
  for (int i = 0; i < 4; ++i) scatter_rows(out_states_.arrays[i], out_states_.data[i]);
  return py::make_tuple(stats.sweeps, stats.rows, stats.substeps);
}

void cache_store(ContactCache& cache, const py::array& a, const py::array& b,
                 const py::array& feature, const py::array& normal,
                 const py::array& friction, const py::array& point) {
  const py::ssize_t m = a.ndim() == 1 ? a.shape(0) : -1;
  cache.store(m, checked<int64_t>(a, "a", {m}), checked<int64_t>(b, "b", {m}),
              checked<int64_t>(feature, "feature", {m}), checked<double>(normal, "normal", {m}),
              checked<double>(friction, "friction", {m, 3}),
              checked<double>(point, "point", {m, 3}));
}

py::tuple cache_lookup(ContactCache& cache, const py::array& a, const py::array& b,
                       const py::array& feature, const py::array& point, double radius) {
  const py::ssize_t m = a.ndim() == 1 ? a.shape(0) : -1;
  py::array_t<double> normal(m), friction({m, static_cast<py::ssize_t>(3)});
  py::array_t<bool> found(m);
  cache.lookup(m, checked<int64_t>(a, "a", {m}), checked<int64_t>(b, "b", {m}),
               checked<int64_t>(feature, "feature", {m}), checked<double>(point, "point", {m, 3}),
               radius, normal.mutable_data(), friction.mutable_data(),
               reinterpret_cast<uint8_t*>(found.mutable_data()));
  return py::make_tuple(normal, friction, found);
}

}  // namespace

void bind_solver(py::module_& m) {
  py::enum_<CombineRule>(m, "CombineRule")
      .value("average", CombineRule::kAverage)
      .value("min", CombineRule::kMin)
      .value("max", CombineRule::kMax)
      .value("multiply", CombineRule::kMultiply)
      .value("geometric", CombineRule::kGeometric)
      .value("per_object", CombineRule::kPerObject);
  m.def("combine", py::vectorize(&combine), py::arg("a"), py::arg("b"), py::arg("rule"),
        "One coefficient per contact from the two bodies' (per_object: the mean).");

  py::class_<SolverParams>(m, "SolverParams", "The solver's settings (units: see step.h).")
      .def(py::init<>())
      .def_readwrite("velocity_iterations", &SolverParams::velocity_iterations)
      .def_readwrite("impact_stages", &SolverParams::impact_stages)
      .def_readwrite("impact_sweeps", &SolverParams::impact_sweeps)
      .def_readwrite("impact_converged", &SolverParams::impact_converged)
      .def_readwrite("position_iterations", &SolverParams::position_iterations)
      .def_readwrite("fixed_sweeps", &SolverParams::fixed_sweeps)
      .def_readwrite("deep_sweeps", &SolverParams::deep_sweeps)
      .def_readwrite("deep_overlap", &SolverParams::deep_overlap)
      .def_readwrite("support_cosine", &SolverParams::support_cosine)
      .def_readwrite("shock_sweeps", &SolverParams::shock_sweeps)
      .def_readwrite("shock_ratio", &SolverParams::shock_ratio)
      .def_readwrite("depth_sweeps", &SolverParams::depth_sweeps)
      .def_readwrite("restitution_threshold", &SolverParams::restitution_threshold)
      .def_readwrite("resting_factor", &SolverParams::resting_factor)
      .def_readwrite("sticking_speed", &SolverParams::sticking_speed)
      .def_readwrite("linear_slop", &SolverParams::linear_slop)
      .def_readwrite("position_correction", &SolverParams::position_correction)
      .def_readwrite("max_correction", &SolverParams::max_correction)
      .def_readwrite("converged", &SolverParams::converged)
      .def_readwrite("activation_margin", &SolverParams::activation_margin)
      .def_readwrite("row_bound", &SolverParams::row_bound)
      .def_readwrite("cold_extra", &SolverParams::cold_extra)
      .def_readwrite("balanced_friction", &SolverParams::balanced_friction)
      .def_readwrite("warm_start_ratio", &SolverParams::warm_start_ratio)
      .def_readwrite("match_radius", &SolverParams::match_radius)
      .def_readwrite("threads", &SolverParams::threads)
      .def_readwrite("parallel_wave", &SolverParams::parallel_wave)
      .def_readwrite("wide_rows", &SolverParams::wide_rows)
      .def_readwrite("max_substep", &SolverParams::max_substep)
      .def_readwrite("max_substeps", &SolverParams::max_substeps)
      .def_readwrite("landing_substeps", &SolverParams::landing_substeps)
      .def_readwrite("landing_sweeps", &SolverParams::landing_sweeps)
      .def_readwrite("substep_sink", &SolverParams::substep_sink)
      .def_readwrite("stack_sink", &SolverParams::stack_sink)
      .def_readwrite("later_impact", &SolverParams::later_impact)
      .def_readwrite("behind_cosine", &SolverParams::behind_cosine)
      .def_readwrite("exact_rows", &SolverParams::exact_rows)
      .def_readwrite("exact_rounds", &SolverParams::exact_rounds)
      .def_readwrite("exact_work", &SolverParams::exact_work)
      .def_readwrite("exact_hold", &SolverParams::exact_hold)
      .def_readwrite("exact_quiet", &SolverParams::exact_quiet)
      .def_readwrite("exact_tolerance", &SolverParams::exact_tolerance)
      .def_readwrite("exact_regularise", &SolverParams::exact_regularise)
      .def_readwrite("aim_turn", &SolverParams::aim_turn)
      .def_readwrite("restitution_rule", &SolverParams::restitution_rule)
      .def_readwrite("friction_rule", &SolverParams::friction_rule);

  py::class_<ContactCache>(m, "ContactCache", "Last step's impulses by pair and feature.")
      .def(py::init<>())
      .def("store", &cache_store, py::arg("a"), py::arg("b"), py::arg("feature"),
           py::arg("normal"), py::arg("friction"), py::arg("point"))
      .def("lookup", &cache_lookup, py::arg("a"), py::arg("b"), py::arg("feature"),
           py::arg("point"), py::arg("match_radius") = 0.02,
           "(normal (M,), friction (M, 3), found (M,) bool); zeros where absent.")
      .def("forget", [](ContactCache& cache, const py::array& bodies) {
        const py::ssize_t k = bodies.ndim() == 1 ? bodies.shape(0) : -1;
        cache.forget(k, checked<int64_t>(bodies, "bodies", {k}));
      }, py::arg("bodies"), "Drop every entry that involves one of these body indices.")
      .def("clear", &ContactCache::clear)
      .def("__len__", &ContactCache::size);

  py::class_<StepSolver>(m, "StepSolver", "The per-contact work of one step (see step.h).")
      .def(py::init<>())
      .def_property_readonly("cache", &StepSolver::cache, py::return_value_policy::reference_internal)
      .def_property_readonly("waves", [](const StepSolver& solver) {
        py::list waves;
        for (const SweepWave& w : solver.plan().waves)
          waves.append(py::make_tuple(w.first, w.wide_end, w.lone, w.end, w.side, w.after,
                                      w.spin_after, w.seam));
        return waves;
      }, "The last step's sweep waves, in order, each cut in its sides' parts: (first, "
         "wide_end, lone, end, side, after, spin_after, seam) each; manifolds [first, "
         "wide_end) in wide groups of 4, [wide_end, lone) in wide groups of 2 or 3 (one per "
         "row count 1 to 4, padded with idle lanes), [lone, end) one by one (the one left of "
         "a row count, then more than 4 rows); no two manifolds of a wave share a movable "
         "body; side 0 or 1 (1 only where the waves are large enough: parallel_wave, and "
         "with two threads whose cost model runs the sweeps paired: else a wave's sides "
         "are one part); seam: "
         "a part of the seam's waves (manifolds joining the sides). The sweep: the rows of "
         "the parts before the seam's, their spin rows, then the seam's rows and spin rows "
         "(the parts' rows numbered i, their spin rows len(waves) + i); after: the part of "
         "the other side last in that order to move one of its bodies before its rows (-1: "
         "none), spin_after: the same for its spin rows.")
      .def_property_readonly("sweep_bodies", [](const StepSolver& solver) {
        const std::vector<Manifold>& manifolds = solver.manifolds();
        py::array_t<int32_t> out({static_cast<py::ssize_t>(manifolds.size()),
                                  static_cast<py::ssize_t>(4)});
        auto view = out.mutable_unchecked<2>();
        for (size_t m = 0; m < manifolds.size(); ++m) {
          view(m, 0) = manifolds[m].a;
          view(m, 1) = manifolds[m].b;
          view(m, 2) = manifolds[m].count;
          view(m, 3) = manifolds[m].first;
        }
        return out;
      }, "The last step's swept manifolds (those its active set let in) in sweep order: "
         "(body a, body b, rows, first row) each; the first rows give the solve's order.")
      .def_property_readonly("helped", [](const StepSolver& solver) {
        return py::make_tuple(solver.helped(), solver.chunks_run());
      }, "Chunks of the waves' second halves run so far: (by the second thread, in all).")
      .def_property_readonly("runs", [](const StepSolver& solver) {
        return py::make_tuple(solver.paired_runs(), solver.runs());
      }, "Runs posted for two threads so far: (run paired, in all); the others the cost "
         "model ran on the calling thread alone.")
      .def_property_readonly("redone", &StepSolver::redone,
                             "Steps solved again so far: a contact without a row (prepare's "
                             "row_bound) escaped and got one.")
      .def("step", &solver_step, py::kw_only(), py::arg("previous"), py::arg("current"),
           py::arg("out"), py::arg("inv_mass"), py::arg("inv_inertia_body"),
           py::arg("movable"), py::arg("held"), py::arg("restitution"),
           py::arg("static_friction"), py::arg("kinetic_friction"),
           py::arg("rolling_resistance"), py::arg("torsional_friction"), py::arg("radius"),
           py::arg("body_a"),
           py::arg("body_b"), py::arg("point"), py::arg("normal"), py::arg("separation"),
           py::arg("toi"), py::arg("kind"), py::arg("feature"), py::arg("manifolds"),
           py::arg("dt"),
           py::arg("warm"), py::arg("params"), py::arg("normal_impulse"),
           py::arg("friction_impulse"), py::arg("state"), py::arg("reported_toi"),
           py::arg("reported_kind"),
           "Solve one step in place of `out` (a copy of `current`) and the per-contact "
           "outputs; returns (velocity sweeps, solver rows, substeps).");
}
