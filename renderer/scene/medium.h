// Participating media: homogeneous (Mitsuba 3's `homogeneous`) and
// heterogeneous with grid volumes (`heterogeneous` + `gridvolume`), RGB-varying
// extinction and albedo, with an isotropic or Henyey-Greenstein phase function.
// The volume rendering equation (Kajiya 1986; the seed's form):
//   (w . grad) L = sigma_a L_e - sigma_t L + sigma_s int p(w', w) L(w') dw',
// so along a ray through a homogeneous medium the transmittance is
// Tr(t) = exp(-sigma_t t) (Beer-Lambert) per colour channel, and in a
// heterogeneous one exp(-int sigma_t), estimated by ratio tracking against a
// majorant (Novak et al. 2014, "Residual ratio tracking").
#pragma once
#include <cmath>
#include <memory>
#include <string>
#include <vector>

#include "core/math.h"
#include "core/rng.h"
#include "core/spectrum.h"
#include "scene/desc.h"
#include "scene/phase.h"

namespace rm {

// A trilinearly interpolated grid over the unit cube of its local space
// (voxel centres at (i + 0.5) / n, values clamped at the border, as
// Mitsuba 3's gridvolume with its defaults).
class Grid {
public:
    Grid(const GridDesc& d, const std::string& who);
    Color eval(const Vec3& p_world) const;
    Color max_value() const { return max_; }
    // The part [t0, t1] of the ray o + d t, t in [0, t_max], inside the
    // grid's box (its local unit cube); false when the ray misses it.
    bool ray_interval(const Vec3& o, const Vec3& d, float t_max, float& t0, float& t1) const;

private:
    Color voxel(int x, int y, int z) const;
    int nx_, ny_, nz_, ch_;
    std::vector<float> data_;
    Transform xf_;
    Color max_;
};

class Medium {
public:
    // Throws std::invalid_argument naming the medium for a bad parameter.
    explicit Medium(const MediumDesc& d);
    std::string id;
    bool homogeneous = true;
    Color sigma_t, sigma_s;  // homogeneous
    Color majorant;          // heterogeneous: >= sigma_t everywhere, per channel
    std::unique_ptr<PhaseFunction> phase;

    // Beer-Lambert transmittance over a distance t (t may be infinite: a
    // channel with sigma_t = 0 keeps 1 there, the others 0). Homogeneous only.
    Color transmittance(float t) const {
        return {tr1(sigma_t.x, t), tr1(sigma_t.y, t), tr1(sigma_t.z, t)};
    }
    static Color exp_neg(const Color& sigma, float t) { return {tr1(sigma.x, t), tr1(sigma.y, t), tr1(sigma.z, t)}; }
    // Heterogeneous: the coefficients at a point.
    void coefficients(const Vec3& p, Color& sig_t, Color& sig_s) const;
    // The part [t0, t1] of the ray o + d t, t in [0, t_max], where the medium
    // is: a grid medium fills its grid's box and is vacuum outside (as
    // Mitsuba 3's heterogeneous medium, Medium::intersect_aabb); homogeneous
    // media and constant volumes fill everything. False when it is empty.
    bool extent(const Vec3& o, const Vec3& d, float t_max, float& t0, float& t1) const {
        if (homogeneous || !sigma_t_grid_) {
            t0 = 0.f;
            t1 = t_max;
            return true;
        }
        return sigma_t_grid_->ray_interval(o, d, t_max, t0, t1);
    }
    // Transmittance of the segment o + d t, t in [0, t1): exact for a
    // homogeneous medium, an unbiased ratio-tracking estimate in [0, 1] for a
    // heterogeneous one (consumes random numbers of `sampler`).
    Color segment_transmittance(const Vec3& o, const Vec3& d, float t1, Sampler& sampler) const;

private:
    static float tr1(float s, float t) { return s > 0.f ? std::exp(-s * t) : 1.f; }
    std::unique_ptr<Grid> sigma_t_grid_, albedo_grid_;
    Color sigma_t_const_, albedo_const_;
    float scale_ = 1.f;
};

}  // namespace rm
