// What `prt` (prt.cpp) shares with the bindings: the projection of a
// scene's distant lighting onto real spherical harmonics (core/sh.h).
#pragma once
#include <string>
#include <vector>

#include "core/spectrum.h"
#include "scene/scene.h"

namespace rm {

// Throws std::invalid_argument naming the emitter when `scene` has a light
// that is not at infinity (area, point, spot): PRT transfers distant light.
// `who` starts the message ("integrator 'prt'").
void check_distant_lighting(const Scene& scene, const std::string& who);

// The SH coefficients (sh_count(bands) RGB values) of the radiance arriving
// from the scene's emitters at infinity, L_i = int L(w) y_i(w) dw over
// the directions w towards the light: environments (constant, envmap) by
// the product quadrature of sphere_quadrature(n_theta), a directional light
// of irradiance E towards d exactly, E y_i(d) (the projection of E delta(w - d)).
std::vector<Color> project_distant_lighting(const Scene& scene, int bands, int n_theta);

}  // namespace rm
