// The Python bindings of collres_ros/core/_native, one function per half of the core.
//
// Bindings only bind: every function they expose is implemented in the stage sources
// (contact_solver, step, broad_phase, manifold, time_of_impact, islands). Arrays cross as numpy
// arrays without copies (C-contiguous float64 / int64, checked, never converted), and
// the GIL is released while C++ works on them.
#pragma once

#include <pybind11/pybind11.h>

// The solver half: combine rules, the contact cache and the solver step (bind_solver.cpp).
void bind_solver(pybind11::module_& m);

// The detection half: broad phase, narrow phase, manifolds, time of impact
// (bind_detection.cpp).
void bind_detection(pybind11::module_& m);

// Islands and sleep timers (bind_islands.cpp).
void bind_islands(pybind11::module_& m);
