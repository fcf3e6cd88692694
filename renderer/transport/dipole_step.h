// The camera-path step at a shape with a dipole BSSRDF (scene/dipole.h),
// shared by the surface loop (path.cpp) and the media loop (volpath.cpp).
#pragma once
#include "render/integrator.h"

namespace rm {

struct DipoleStep {
    enum Kind { kFailed, kReflected, kSubsurface };
    Kind kind = kFailed;
    BsdfSample reflection;  // kReflected: the specular sample (local frame of the entry point)
    Color weight{0.f};      // kSubsurface: Rd(|xi - xo|) / pdf of the exit point
};

// At a camera-path hit `it` on a dipole shape (light arriving from outside,
// it.wi on the normal's side): with the Fresnel reflectance Fr(wi) as
// probability, specular reflection (weight 1); else the subsurface term,
// whose Ft(wi) cancels against that choice: an exit point xi is drawn by
// importance sampling the dipole profile (dipole_step.cpp), `it` becomes
// xi (its wi along the outward shading normal) and the weight is
// Rd(|xi - xo|) over the exit point's density. The caller then does next
// event estimation at xi and continues the path with Dipole::exit_lobe().
DipoleStep dipole_step(const Scene& scene, const Dipole& dp, Interaction& it, Sampler& sampler, ThreadStats& stats);

// A camera path's vertex on a dipole shape (path.cpp step 4a, volpath.cpp
// step 7a): one function, so that the surface and the media loop stay one
// estimator. Runs dipole_step and folds its outcome into the path state:
// on specular reflection `bs` is that sample and `sampled` is set (no next
// event estimation, no BSDF sampling); on an exit point, `it` is xi, `beta`
// takes the weight, the path class is marked subsurface, and `bsdf` / `wi`
// become the exit lobe and its local incident direction (the normal).
// Returns false when the path ends (light from inside, or no exit point).
bool camera_dipole_vertex(const Scene& scene, const Dipole& dp, Interaction& it, Sampler& sampler, ThreadStats& stats,
                          Color& beta, PathClass& pc, const Bsdf*& bsdf, Vec3& wi, BsdfSample& bs, bool& sampled);

// The exit-point proposal on its own (tests): from `xo` on shape `shape`,
// with the random numbers given; returns false on failure, else the exit
// point and the weight Rd / pdf.
bool dipole_sample_exit(const Scene& scene, const Dipole& dp, const Interaction& xo, float u_ch, float u_axis,
                        Vec2 u_rphi, float u_sel, Interaction& xi, Color& weight, ThreadStats& stats);

}  // namespace rm
