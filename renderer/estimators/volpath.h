// The media-aware camera-ray loop shared by `path` and `volpath` (volpath.cpp).
#pragma once
#include "render/integrator.h"

namespace rm {

struct VolPathParams {
    int max_depth = -1, rr_depth = 5;
    bool hide = false;
    // The truncation probe (path's surface loop): the fraction of the paths
    // that max_depth stops which go on past it, with Russian roulette and
    // weight 1 / probe, to estimate the light max_depth cuts off
    // (ThreadStats::truncated, res.error_budget's truncation term) without
    // changing the image. 0: off. The media loop does not probe yet.
    float truncation_probe = 0.f;
    // Equiangular distance sampling in homogeneous media, combined with
    // free flight by MIS (volpath.cpp); false: free flight alone.
    bool equiangular = false;
};

// Radiance along one camera ray through a scene with media, split by effect class.
void volpath_sample(const Scene& scene, Sampler& sampler, const Ray& camera_ray, EffectRadiance& out,
                    ThreadStats& stats, const VolPathParams& prm, const EffectMask& mask);

// `path`'s twin for scenes with media (Integrator::for_scene).
std::unique_ptr<Integrator> make_volpath_integrator(const VolPathParams& prm);

}  // namespace rm
