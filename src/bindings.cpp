// collres_ros.core._native: the compiled contact core.
#include "bindings.h"

PYBIND11_MODULE(_native, m) {
  m.doc() = "collres_ros compiled contact core (detection and sequential-impulse solver)";
  bind_solver(m);
  bind_detection(m);
  bind_islands(m);
  bind_input_check(m);
}
