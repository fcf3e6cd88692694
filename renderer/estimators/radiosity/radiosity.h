// `radiosity`: the finite-element estimator's solution, for tests and
// studies (bindings/test_hooks.cpp). See radiosity.cpp and docs/radiosity.md.
#pragma once
#include <string>
#include <utility>
#include <vector>

#include "render/integrator.h"

namespace rm {

// The solved patches of `radiosity` on a scene: per patch its centre,
// front normal (3 each), area and shape; per element (patch p's front side
// is element 2p, its back 2p + 1; 3 channels each) the emitted radiosity E
// and the reflected radiosity split by bounce (direct: one reflection of
// the emission; indirect: more), and the solver's statistics (the same as
// res.stats gets).
struct RadiositySolution {
    std::vector<double> centre, normal, area;
    std::vector<double> corners;  // 4 x 3 per patch (a triangle repeats its last corner)
    std::vector<int> shape;
    std::vector<double> emitted, direct, indirect;
    std::vector<std::pair<std::string, double>> stats;
};

// Solves `scene` with `integrator` (which must be a `radiosity`) on `threads` threads.
RadiositySolution radiosity_solution(const Scene& scene, const Integrator& integrator, int threads);

}  // namespace rm
