// Islands bindings: the sleep state of the bodies (islands.h).
//
// Arrays are taken as they are (no conversion, no copy): C-contiguous numpy arrays of the
// documented dtype and shape, outputs writable, or a TypeError / ValueError names it; body
// states may be strided views (float_rows, bindings.h).
#include <pybind11/numpy.h>
#include <pybind11/stl.h>

#include <cstdint>
#include <string>
#include <vector>

#include "bindings.h"
#include "islands.h"

namespace py = pybind11;
using namespace collres;

namespace {

template <class T>
T* array_data(const py::array& array, const char* name, std::vector<py::ssize_t> shape,
              bool out = false) {
  if (!array.dtype().is(py::dtype::of<T>()))
    throw py::type_error(std::string(name) + ": wrong dtype " +
                         py::str(array.dtype()).cast<std::string>());
  if (!(array.flags() & py::array::c_style))
    throw py::value_error(std::string(name) + ": not C-contiguous");
  if (out && !array.writeable()) throw py::value_error(std::string(name) + ": read-only");
  bool ok = array.ndim() == static_cast<py::ssize_t>(shape.size());
  for (size_t d = 0; ok && d < shape.size(); ++d) ok = shape[d] < 0 || array.shape(d) == shape[d];
  if (!ok) throw py::value_error(std::string(name) + ": wrong shape");
  return static_cast<T*>(const_cast<void*>(array.data()));
}

// Body states (position, orientation, linear, angular), each float64 rows of (n, width):
// C-contiguous, or strided views gathered into `scratch` (float_rows).
struct StatesIn {
  SleepStates view;
  RowScratch scratch[4];
};

void sleep_states(const py::tuple& t, py::ssize_t n, const char* name, StatesIn& in) {
  if (t.size() != 4) throw py::value_error(std::string(name) + ": (position, orientation, "
                                           "linear, angular) expected");
  in.view.position = float_rows(t[0], n, 3, name, in.scratch[0]);
  in.view.orientation = float_rows(t[1], n, 4, name, in.scratch[1]);
  in.view.linear = float_rows(t[2], n, 3, name, in.scratch[2]);
  in.view.angular = float_rows(t[3], n, 3, name, in.scratch[3]);
}

}  // namespace

void bind_islands(py::module_& m) {
  py::class_<SleepSettings>(m, "SleepSettings", "Sleep settings (units: see islands.h).")
      .def(py::init<>())
      .def_readwrite("threshold", &SleepSettings::threshold)
      .def_readwrite("time_to_sleep", &SleepSettings::time_to_sleep)
      .def_readwrite("margin", &SleepSettings::margin)
      .def_readwrite("late_steps", &SleepSettings::late_steps)
      .def_readwrite("rise_time", &SleepSettings::rise_time)
      .def_readwrite("rise_step", &SleepSettings::rise_step);

  py::class_<Islands>(m, "Islands", "Islands and sleep timers of N bodies (see islands.h).")
      .def(py::init<std::vector<double>, std::vector<std::uint8_t>>(), py::arg("radius"),
           py::arg("dynamic"))
      .def_property("settings", &Islands::settings, &Islands::set_settings)
      .def_property_readonly("asleep", [](const Islands& islands) {
             return py::array_t<std::uint8_t>(islands.count(), islands.asleep().data());
           }, "(N,) uint8, 1 where the body is asleep (a copy)")
      .def_property_readonly("still_time", &Islands::still_time,
                             "(N,) s each body has been still")
      .def("wake_all", &Islands::wake_all)
      .def("wake", [](Islands& islands, const py::tuple& previous, const py::tuple& current,
                      const py::array& active, const py::array& kinematic, double dt) {
             const py::ssize_t n = islands.count();
             StatesIn p, c;
             sleep_states(previous, n, "previous", p);
             sleep_states(current, n, "current", c);
             const auto* act = array_data<std::uint8_t>(active, "active", {n});
             const auto* kin = array_data<std::uint8_t>(kinematic, "kinematic", {n});
             py::gil_scoped_release release;
             return islands.wake(p.view, c.view, act, kin, dt);
           }, py::arg("previous"), py::arg("current"), py::arg("active"),
           py::arg("kinematic"), py::arg("dt"))
      .def("update", [](Islands& islands, const py::array& out_linear,
                        const py::array& out_angular, const py::array& movable,
                        const py::array& a, const py::array& b,
                        const py::array& normal_impulse, double dt) {
             const py::ssize_t n = islands.count();
             RowScratch scratch[2];
             double* lin = float_rows(out_linear, n, 3, "out_linear", scratch[0], true);
             double* ang = float_rows(out_angular, n, 3, "out_angular", scratch[1], true);
             const auto* mov = array_data<std::uint8_t>(movable, "movable", {n});
             const py::ssize_t m = a.ndim() == 1 ? a.shape(0) : -1;
             const auto* pa = array_data<std::int64_t>(a, "body_a", {m});
             const auto* pb = array_data<std::int64_t>(b, "body_b", {m});
             const auto* pi = array_data<double>(normal_impulse, "normal_impulse", {m});
             int fell;
             {
               py::gil_scoped_release release;
               fell = islands.update(lin, ang, mov, pa, pb, pi, m, dt);
             }
             if (fell) {   // only the bodies that fell asleep were written (zero twist)
               scatter_rows(out_linear, lin);
               scatter_rows(out_angular, ang);
             }
             return fell;
           }, py::arg("out_linear"), py::arg("out_angular"), py::arg("movable"),
           py::arg("body_a"), py::arg("body_b"), py::arg("normal_impulse"), py::arg("dt"))
      .def_property_readonly("sleeping_bodies", &Islands::sleeping_bodies)
      .def_property_readonly("sleeping_islands", &Islands::sleeping_islands)
      .def_property_readonly("awake_islands", &Islands::awake_islands);
}
