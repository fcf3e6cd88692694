#include "scene/medium.h"

#include <atomic>
#include <stdexcept>

namespace rm {

namespace {
// Counting is off until a measurement asks for it (reset_tracking_lookups):
// a render otherwise only reads the flag, so its threads never contend for
// the counter's cache line.
std::atomic<bool> g_counting{false};
std::atomic<uint64_t> g_tracking_lookups{0};
}  // namespace

uint64_t Medium::tracking_lookups() { return g_tracking_lookups.load(std::memory_order_relaxed); }
void Medium::reset_tracking_lookups() {
    g_tracking_lookups.store(0, std::memory_order_relaxed);
    g_counting.store(true, std::memory_order_relaxed);
}
void Medium::count_lookups(uint64_t n) {
    if (g_counting.load(std::memory_order_relaxed)) g_tracking_lookups.fetch_add(n, std::memory_order_relaxed);
}

Grid::Grid(const GridDesc& d, const std::string& who) : nx_(d.nx), ny_(d.ny), nz_(d.nz), ch_(d.channels) {
    if (nx_ < 1 || ny_ < 1 || nz_ < 1 || (ch_ != 1 && ch_ != 3))
        throw std::invalid_argument(who + ": grid needs a positive resolution and 1 or 3 channels");
    size_t n = size_t(nx_) * size_t(ny_) * size_t(nz_) * size_t(ch_);
    if (d.data.size() != n)
        throw std::invalid_argument(who + ": grid has " + std::to_string(d.data.size()) + " values, expected " +
                                    std::to_string(n));
    data_ = d.data;
    max_ = Color(0.f);
    for (size_t i = 0; i < n; ++i) {
        float v = data_[i];
        if (!(v >= 0.f) || !std::isfinite(v))
            throw std::invalid_argument(who + ": grid values must be finite and >= 0, got " + std::to_string(v));
        int c = ch_ == 1 ? -1 : int(i % 3);
        if (c < 0)
            max_ = vmax(max_, Color(v));
        else
            max_[c] = std::max(max_[c], v);
    }
    if (!xf_.set(d.to_world.data())) throw std::invalid_argument(who + ": singular grid to_world");
}

Color Grid::voxel(int x, int y, int z) const {
    x = std::min(std::max(x, 0), nx_ - 1);
    y = std::min(std::max(y, 0), ny_ - 1);
    z = std::min(std::max(z, 0), nz_ - 1);
    size_t i = ((size_t(z) * ny_ + y) * nx_ + x) * ch_;
    return ch_ == 1 ? Color(data_[i]) : Color(data_[i], data_[i + 1], data_[i + 2]);
}

bool Grid::ray_interval(const Vec3& o, const Vec3& d, float t_max, float& t0, float& t1) const {
    // Slab test in the grid's local space (an affine map keeps the ray parameter).
    Vec3 lo = xf_.inv_point(o), ld = xf_.inv_vector(d);
    double a = 0.0, b = double(t_max);
    const double oo[3] = {lo.x, lo.y, lo.z}, dd[3] = {ld.x, ld.y, ld.z};
    for (int k = 0; k < 3; ++k) {
        if (dd[k] == 0.0) {
            if (oo[k] < 0.0 || oo[k] > 1.0) return false;
            continue;
        }
        double ta = (0.0 - oo[k]) / dd[k], tb = (1.0 - oo[k]) / dd[k];
        if (ta > tb) std::swap(ta, tb);
        a = std::max(a, ta);
        b = std::min(b, tb);
    }
    if (!(a < b)) return false;
    t0 = float(a);
    t1 = float(b);
    return true;
}

void Grid::build_majorants(float scale) {
    const int n[3] = {nx_, ny_, nz_};
    int lo[3][16], hi[3][16];
    for (int k = 0; k < 3; ++k) {
        // 16 cells per axis (pbrt-v4's 16^3), finer than the voxels of a
        // small grid: a cell then meets 2 voxels' trilinear support per axis
        // instead of the 3 of a voxel-sized cell. One cell for a flat axis.
        mres_[k] = n[k] == 1 ? 1 : 16;
        for (int i = 0; i < mres_[k]; ++i) {
            // eval() at local coordinate u weighs voxels floor(f) and
            // floor(f) + 1, f = u n - 0.5 (clamped to [-1, n]); over the
            // cell's [i / R, (i + 1) / R] that is floor(a) .. ceil(b) (f = b
            // exactly weighs floor(b) + 1 by 0). The 1e-4 voxels of slack make
            // a cell border on a voxel centre take both sides.
            double a = double(i) * n[k] / mres_[k] - 0.5 - 1e-4, b = double(i + 1) * n[k] / mres_[k] - 0.5 + 1e-4;
            lo[k][i] = std::max(int(std::floor(a)), 0);
            hi[k][i] = std::min(int(std::ceil(b)), n[k] - 1);
        }
    }
    mcells_.assign(size_t(mres_[0]) * mres_[1] * mres_[2], Color(0.f));
    mincells_.assign(mcells_.size(), Color(0.f));
    for (int cz = 0; cz < mres_[2]; ++cz)
        for (int cy = 0; cy < mres_[1]; ++cy)
            for (int cx = 0; cx < mres_[0]; ++cx) {
                Color m(0.f), mn(kInf);
                for (int z = lo[2][cz]; z <= hi[2][cz]; ++z)
                    for (int y = lo[1][cy]; y <= hi[1][cy]; ++y)
                        for (int x = lo[0][cx]; x <= hi[0][cx]; ++x) {
                            Color v = voxel(x, y, z);
                            m = vmax(m, v);
                            mn = vmin(mn, v);
                        }
                size_t i = (size_t(cz) * mres_[1] + cy) * mres_[0] + cx;
                mcells_[i] = m * scale * (1.f + 1e-6f);
                mincells_[i] = mn * scale * (1.f - 1e-6f);
            }
}

MajorantIterator Grid::majorants(const Vec3& o, const Vec3& d, float t0, float t1) const {
    MajorantIterator it;
    it.cells_ = mcells_.data();
    it.min_cells_ = mincells_.data();
    Vec3 lo = xf_.inv_point(o), ld = xf_.inv_vector(d);
    const double oo[3] = {lo.x, lo.y, lo.z}, dd[3] = {ld.x, ld.y, ld.z};
    it.t_ = t0;
    it.t_max_ = t1;
    for (int k = 0; k < 3; ++k) {
        const int r = mres_[k];
        it.res_[k] = r;
        double p = oo[k] + dd[k] * double(t0);  // the entry point, local
        int c = std::min(std::max(int(std::floor(p * r)), 0), r - 1);
        it.cell_[k] = c;
        if (dd[k] > 0.0) {
            it.step_[k] = 1;
            it.next_[k] = double(t0) + (double(c + 1) / r - p) / dd[k];
            it.delta_[k] = 1.0 / (dd[k] * r);
        } else if (dd[k] < 0.0) {
            it.step_[k] = -1;
            it.next_[k] = double(t0) + (double(c) / r - p) / dd[k];
            it.delta_[k] = -1.0 / (dd[k] * r);
        } else {  // parallel to this axis's cell borders: never crosses one
            it.step_[k] = 0;
            it.next_[k] = double(kInf);
            it.delta_[k] = 0.0;
        }
    }
    return it;
}

Color Grid::majorant_at(const Vec3& p_world) const {
    Vec3 u = xf_.inv_point(p_world);
    const float uu[3] = {u.x, u.y, u.z};
    int c[3];
    for (int k = 0; k < 3; ++k) c[k] = std::min(std::max(int(std::floor(double(uu[k]) * mres_[k])), 0), mres_[k] - 1);
    return mcells_[(size_t(c[2]) * mres_[1] + c[1]) * mres_[0] + c[0]];
}

Color Grid::eval(const Vec3& p_world) const {
    Vec3 u = xf_.inv_point(p_world);
    // Clamped before the integer conversion (far outside the grid the
    // border value holds, and int() of a huge float is undefined).
    float fx = std::min(std::max(u.x * nx_ - 0.5f, -1.f), float(nx_)),
          fy = std::min(std::max(u.y * ny_ - 0.5f, -1.f), float(ny_)),
          fz = std::min(std::max(u.z * nz_ - 0.5f, -1.f), float(nz_));
    float x0 = std::floor(fx), y0 = std::floor(fy), z0 = std::floor(fz);
    float tx = fx - x0, ty = fy - y0, tz = fz - z0;
    int ix = int(x0), iy = int(y0), iz = int(z0);
    Color c00 = lerp(tx, voxel(ix, iy, iz), voxel(ix + 1, iy, iz));
    Color c10 = lerp(tx, voxel(ix, iy + 1, iz), voxel(ix + 1, iy + 1, iz));
    Color c01 = lerp(tx, voxel(ix, iy, iz + 1), voxel(ix + 1, iy, iz + 1));
    Color c11 = lerp(tx, voxel(ix, iy + 1, iz + 1), voxel(ix + 1, iy + 1, iz + 1));
    return lerp(tz, lerp(ty, c00, c10), lerp(ty, c01, c11));
}

Medium::Medium(const MediumDesc& d) : id(d.id) {
    const std::string who = "medium '" + d.id + "'";
    if (d.type != "homogeneous" && d.type != "heterogeneous")
        throw std::invalid_argument(who + ": unknown type '" + d.type + "' (known: homogeneous, heterogeneous)");
    for (int c = 0; c < 3; ++c) {
        if (!(d.sigma_t[c] >= 0.f) || !std::isfinite(d.sigma_t[c]))
            throw std::invalid_argument(who + ": sigma_t must be finite and >= 0, got " + std::to_string(d.sigma_t[c]));
        if (!(d.albedo[c] >= 0.f && d.albedo[c] <= 1.f))
            throw std::invalid_argument(who + ": albedo must lie in [0, 1], got " + std::to_string(d.albedo[c]));
    }
    if (!(d.scale >= 0.f) || !std::isfinite(d.scale))
        throw std::invalid_argument(who + ": scale must be finite and >= 0");
    sigma_t = d.sigma_t;
    sigma_s = d.sigma_t * d.albedo;
    homogeneous = d.type == "homogeneous";
    if (!homogeneous) {
        sigma_t_const_ = d.sigma_t;
        albedo_const_ = d.albedo;
        scale_ = d.scale;
        if (d.sigma_t_grid.nx > 0) sigma_t_grid_ = std::make_unique<Grid>(d.sigma_t_grid, who + " sigma_t");
        if (d.albedo_grid.nx > 0) {
            albedo_grid_ = std::make_unique<Grid>(d.albedo_grid, who + " albedo");
            if (max_component(albedo_grid_->max_value()) > 1.f)
                throw std::invalid_argument(who + ": albedo grid values must lie in [0, 1]");
        }
        majorant = sigma_t_grid_ ? sigma_t_grid_->max_value() * scale_ : sigma_t_const_;
        if (sigma_t_grid_ && d.sigma_t_grid.accel) sigma_t_grid_->build_majorants(scale_);
    } else {
        majorant = sigma_t;
    }
    try {
        phase = make_phase(d.phase, d.g);
    } catch (const std::invalid_argument& e) {
        throw std::invalid_argument(who + ": " + e.what());
    }
}

void Medium::coefficients(const Vec3& p, Color& sig_t, Color& sig_s) const {
    if (homogeneous) {
        sig_t = sigma_t;
        sig_s = sigma_s;
        return;
    }
    sig_t = sigma_t_grid_ ? sigma_t_grid_->eval(p) * scale_ : sigma_t_const_;
    // Interpolation never exceeds the largest voxel, so sig_t <= majorant.
    sig_t = vmin(sig_t, majorant);
    Color a = albedo_grid_ ? albedo_grid_->eval(p) : albedo_const_;
    sig_s = sig_t * a;
}

Color Medium::segment_transmittance(const Vec3& o, const Vec3& d, float t1, Sampler& sampler) const {
    if (homogeneous) return transmittance(t1);
    // Ratio tracking (Novak et al. 2014, eq. 6) with one scalar majorant for
    // all channels: T = prod_i (1 - sigma_t(x_i) / mu) over the tentative
    // collisions x_i of a free flight of density mu exp(-mu t).
    if (has_majorant_grid()) return segment_transmittance_local(o, d, t1, sampler);
    float mu = max_component(majorant);
    Color tr(1.f);
    if (!(mu > 0.f)) return tr;
    float t, t_end;  // the segment's part inside the grid's box: vacuum elsewhere
    if (!extent(o, d, t1, t, t_end)) return tr;
    uint64_t lookups = 0;
    for (int i = 0; i < (1 << 20); ++i) {
        t += -std::log1p(-sampler.next_1d()) / mu;
        if (!(t < t_end)) break;
        Color st, ss;
        coefficients(o + d * t, st, ss);
        ++lookups;
        tr *= Color(1.f) - st / mu;
        // Russian roulette once the estimate is small (unbiased: survivors x2).
        if (max_component(tr) < 0.1f) {
            if (sampler.next_1d() < 0.5f) {
                tr = Color(0.f);
                break;
            }
            tr *= 2.f;
        }
        if (i + 1 == (1 << 20)) tr = Color(0.f);
    }
    count_lookups(lookups);
    return tr;
}

Color Medium::segment_transmittance_local(const Vec3& o, const Vec3& d, float t1, Sampler& sampler) const {
    // Residual ratio tracking (Novak et al. 2014, sec. 4) per cell of the
    // majorant grid: in a cell whose sigma_t lies in [mnr, maj] (per
    // channel), exp(-int sigma_t) = exp(-mnr len) exp(-int (sigma_t - mnr)),
    // the first factor exact, the second ratio-tracked against the residual
    // majorant mu = max over channels of (maj - mnr): tentative collisions
    // of rate mu (a Poisson process restarted at each cell border,
    // memoryless), each weighing 1 - (sigma_t - mnr) / mu. A cell of
    // constant sigma_t (mu = 0) is exact: no collisions, no random numbers;
    // so is an empty one. The control keeps the variance of a cell whose
    // majorant is tight low (plain ratio tracking against mu = sigma_t would
    // weigh 0 or 1).
    float t0, t_end;
    if (!extent(o, d, t1, t0, t_end)) return Color(1.f);
    MajorantIterator cells = majorants(o, d, t0, t_end);
    MajorantSegment seg;
    double tau[3] = {0.0, 0.0, 0.0};  // the controls' optical depth
    Color w(1.f);                     // the ratio-tracked residual transmittance
    uint64_t lookups = 0;
    int n = 0;
    bool dead = false;
    while (!dead && cells.next(seg)) {
        const float len = seg.t1 - seg.t0;
        for (int c = 0; c < 3; ++c) tau[c] += double(seg.mnr[c]) * len;
        const Color res = seg.maj - seg.mnr;
        const float mu = max_component(res);
        if (!(mu > 0.f)) continue;
        float t = seg.t0;
        for (;;) {
            if (++n > (1 << 20)) {
                dead = true;
                break;
            }
            t += -std::log1p(-sampler.next_1d()) / mu;
            if (!(t < seg.t1)) break;
            Color st, ss;
            coefficients(o + d * t, st, ss);
            ++lookups;
            // mnr <= sigma_t <= maj up to float rounding (Grid::build_majorants).
            Color r = vmin(vmax(st - seg.mnr, Color(0.f)), res);
            w *= Color(1.f) - r / mu;
            // Russian roulette once the estimate is small (unbiased: survivors x2).
            if (max_component(w) < 0.1f) {
                if (sampler.next_1d() < 0.5f) {
                    dead = true;
                    break;
                }
                w *= 2.f;
            }
        }
    }
    count_lookups(lookups);
    if (dead) return Color(0.f);
    return w * Color(float(std::exp(-tau[0])), float(std::exp(-tau[1])), float(std::exp(-tau[2])));
}

}  // namespace rm
