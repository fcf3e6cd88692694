// Participating media: homogeneous (Mitsuba 3's `homogeneous`) and
// heterogeneous with grid volumes (`heterogeneous` + `gridvolume`), RGB-varying
// extinction and albedo, with an isotropic or Henyey-Greenstein phase function.
// The volume rendering equation (Kajiya 1986; the seed's form):
//   (w . grad) L = sigma_a L_e - sigma_t L + sigma_s int p(w', w) L(w') dw',
// so along a ray through a homogeneous medium the transmittance is
// Tr(t) = exp(-sigma_t t) (Beer-Lambert) per colour channel, and in a
// heterogeneous one exp(-int sigma_t), estimated by ratio tracking against a
// majorant (Novak et al. 2014, "Residual ratio tracking"): per cell of a
// majorant grid (local majorants and minorants, residual ratio tracking)
// for a sigma_t grid with `accel` (the default), else one global majorant.
#pragma once
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "core/math.h"
#include "core/rng.h"
#include "core/spectrum.h"
#include "scene/desc.h"
#include "scene/phase.h"

namespace rm {

// A part [t0, t1] of a ray over which sigma_t lies in [mnr, maj], per
// channel (a minorant and a majorant).
struct MajorantSegment {
    float t0, t1;
    Color maj, mnr;
};

// The cells of a majorant grid along a ray, in order, as MajorantSegments:
// a 3D DDA (Amanatides and Woo 1987) in the grid's local unit cube, after
// pbrt-v4's DDAMajorantIterator (PBR4 sec. 11.4.3; our own code). Made by
// Grid::majorants.
class MajorantIterator {
public:
    bool next(MajorantSegment& seg) {
        if (!(t_ < t_max_)) return false;
        // The axis whose cell boundary the ray crosses first.
        int a = next_[0] < next_[1] ? (next_[0] < next_[2] ? 0 : 2) : (next_[1] < next_[2] ? 1 : 2);
        double exit = std::min(t_max_, std::max(t_, next_[a]));
        seg.t0 = float(t_);
        seg.t1 = float(exit);
        size_t i = (size_t(cell_[2]) * res_[1] + cell_[1]) * res_[0] + cell_[0];
        seg.maj = cells_[i];
        seg.mnr = min_cells_[i];
        t_ = exit;
        cell_[a] += step_[a];
        if (cell_[a] < 0 || cell_[a] >= res_[a]) t_ = t_max_;
        next_[a] += delta_[a];
        return true;
    }

private:
    friend class Grid;
    const Color* cells_ = nullptr;
    const Color* min_cells_ = nullptr;
    int res_[3] = {0, 0, 0}, cell_[3] = {0, 0, 0}, step_[3] = {0, 0, 0};
    double t_ = 0.0, t_max_ = 0.0, next_[3] = {0, 0, 0}, delta_[3] = {0, 0, 0};
};

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
    // The majorant grid: 16 cells per axis over the unit cube (1 where n = 1), each
    // the largest value times `scale` of every voxel that the trilinear
    // lookup at a point of the cell can weigh (its neighbours across the
    // cell's borders included), so that scale * eval(p) <= the cell's value
    // for every p in the cell (a convex combination of those voxels); padded
    // by 1e-6 relative against float rounding in eval(). With it the
    // smallest such value (padded down): a minorant, the control of
    // residual ratio tracking. Built once (Medium's constructor).
    void build_majorants(float scale);
    bool has_majorants() const { return !mcells_.empty(); }
    // The cells along o + d t, t in [t0, t1] (a part of ray_interval's).
    MajorantIterator majorants(const Vec3& o, const Vec3& d, float t0, float t1) const;
    // The majorant of the cell holding p (clamped to the grid; tests).
    Color majorant_at(const Vec3& p_world) const;

private:
    Color voxel(int x, int y, int z) const;
    int nx_, ny_, nz_, ch_;
    std::vector<float> data_;
    Transform xf_;
    Color max_;
    int mres_[3] = {0, 0, 0};
    std::vector<Color> mcells_, mincells_;
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
    Color transmittance(float t) const { return {tr1(sigma_t.x, t), tr1(sigma_t.y, t), tr1(sigma_t.z, t)}; }
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

    // Heterogeneous with a sigma_t grid whose `accel` is on: tracking runs
    // per cell of its majorant grid (local majorants) instead of against
    // `majorant`; the segments of [t0, t1] (from extent()).
    bool has_majorant_grid() const { return sigma_t_grid_ && sigma_t_grid_->has_majorants(); }
    MajorantIterator majorants(const Vec3& o, const Vec3& d, float t0, float t1) const {
        return sigma_t_grid_->majorants(o, d, t0, t1);
    }
    // Tests: the local majorant at p (the global one without a majorant grid).
    Color majorant_at(const Vec3& p) const { return has_majorant_grid() ? sigma_t_grid_->majorant_at(p) : majorant; }

    // Measurement (benchmarks/studies/majorant_grid.py): the number of sigma_t
    // lookups made by delta and ratio tracking in grid media, over all
    // threads since the last reset (counting starts with the first reset).
    static uint64_t tracking_lookups();
    static void reset_tracking_lookups();
    static void count_lookups(uint64_t n);

private:
    Color segment_transmittance_local(const Vec3& o, const Vec3& d, float t1, Sampler& sampler) const;
    static float tr1(float s, float t) { return s > 0.f ? std::exp(-s * t) : 1.f; }
    std::unique_ptr<Grid> sigma_t_grid_, albedo_grid_;
    Color sigma_t_const_, albedo_const_;
    float scale_ = 1.f;
};

}  // namespace rm
