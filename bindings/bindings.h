// The binding files of radiometer._core, registered from module.cpp.
#pragma once
#include <pybind11/pybind11.h>

#include "scene/scene.h"

namespace rm::bind {

// _core.IntegratorDesc, estimators(), planned_estimators(),
// resolve_integrator(); ParamError -> radiometer.SceneError (estimators.cpp).
void bind_estimators(pybind11::module_& m);
// Test-only hooks into production code (test_hooks.cpp).
void bind_test_hooks(pybind11::module_& m, pybind11::class_<Scene>& scene);

// Spherical harmonics (core/sh.h), the projection of a scene's distant
// lighting (estimators/prt.h) and an estimator's refusal of a scene (prt.cpp).
void bind_prt(pybind11::module_& m);

}  // namespace rm::bind
