// Film: per-pixel accumulation of the estimate, its variance and the effect
// classes of DESIGN section 3; reconstruction filters by filter importance
// sampling, so every sample lands in exactly one pixel and the per-pixel
// variance is the plain sample variance of independent samples
// (Ernst et al. 2006, "Filter Importance Sampling").
#pragma once
#include <algorithm>
#include <cmath>
#include <string>
#include <vector>

#include "core/spectrum.h"

namespace rm {

enum Effect : int { kEmission = 0, kDirect, kIndirect, kCaustic, kSpecular, kVolume, kSubsurface, kNumEffects };
const char* effect_name(int e);

// One camera sample's radiance, split by effect class.
struct EffectRadiance {
    Color by_effect[kNumEffects];
    void add(int effect, const Color& c) { by_effect[effect] += c; }
    Color total() const {
        Color t(0.f);
        for (const Color& c : by_effect) t += c;
        return t;
    }
};

// Samples pixel offsets with density proportional to the 1D filter (applied
// per axis, as Mitsuba 3's separable filters are), restricted to [lo, hi] so
// samples never leave the film: the estimate then matches a splatting
// renderer's normalised weighted average, borders included.
class FilterSampler {
public:
    FilterSampler(const std::string& type, float radius, float stddev);
    float radius() const { return radius_; }
    float eval(float x) const;
    float sample(float u, float lo, float hi) const;
    // Integral of the (tabulated) filter over [lo, hi]: the normaliser of a
    // splat's weight, so that splatting estimators match the sampled ones,
    // film borders included.
    double integral(float lo, float hi) const;

private:
    std::string type_;
    float radius_, stddev_;
    std::vector<double> cdf_;  // tabulated on [-radius, radius]
    std::vector<int> guide_;   // guide_[j]: first bin whose cdf reaches j / guide size (O(1) inversion)
    int find_bin(double target) const;
    double cdf_at(double x) const;
};

// Splatting a sample at a continuous film position (light tracing): each
// pixel (px, py) whose filter footprint covers (x, y) gets the weight
// f(x - cx) f(y - cy) / (N_x N_y), (cx, cy) its centre and N the filter's
// integral over the footprint's part inside the film (splat_norms), so
// that the expectation is the estimate of the camera-side estimators,
// whose filter importance sampling draws film positions with density f / N,
// borders included. for_each_splat_pixel calls fn(pixel, weight) for the
// pixels of rows [y0, y1) of a w-wide film. Shared by the light driver
// (light_render.cpp) and vcm's light tracing.
// splat_norms: N per column (or row) i of n, the film's sensitive part
// spanning [lo, hi] (the whole film: 0, n; a crop window: its bounds).
inline std::vector<double> splat_norms(const FilterSampler& filter, int n, int lo, int hi) {
    std::vector<double> norm(static_cast<size_t>(n));
    for (int i = 0; i < n; ++i) norm[size_t(i)] = filter.integral(float(lo - i) - 0.5f, float(hi - i) - 0.5f);
    return norm;
}
template <class Fn>
void for_each_splat_pixel(const FilterSampler& filter, const std::vector<double>& norm_x,
                          const std::vector<double>& norm_y, int w, int y0, int y1, float x, float y, Fn fn) {
    const float r = filter.radius();
    int py0 = std::max(y0, int(std::ceil(y - 0.5f - r))), py1 = std::min(y1 - 1, int(std::floor(y - 0.5f + r)));
    if (py0 > py1) return;
    int px0 = std::max(0, int(std::ceil(x - 0.5f - r))), px1 = std::min(w - 1, int(std::floor(x - 0.5f + r)));
    for (int py = py0; py <= py1; ++py) {
        double wy = filter.eval(y - float(py) - 0.5f) / norm_y[size_t(py)];
        if (!(wy > 0)) continue;
        for (int px = px0; px <= px1; ++px) {
            double wx = filter.eval(x - float(px) - 0.5f) / norm_x[size_t(px)];
            if (!(wx > 0)) continue;
            fn(size_t(py) * size_t(w) + size_t(px), wx * wy);
        }
    }
}

class Film {
public:
    // effect_squares: also sum each effect's squares, for per-effect
    // variances (develop_effect_variance); 21 more doubles per pixel.
    Film(int width, int height, bool effect_squares = false);
    int width() const { return w_; }
    int height() const { return h_; }
    void add(int pixel, const EffectRadiance& v);
    // Adds another film's sums (a finished pass) and clears that film.
    void merge_and_clear(Film& pass);
    // Mean, variance of the mean (per channel), and effect means after `spp` samples per pixel.
    void develop(int spp, std::vector<float>& image, std::vector<float>& variance,
                 std::vector<std::vector<float>>* effects) const;
    // Variance of each effect's mean (kNumEffects images), as develop's
    // variance of the total; empty when the film keeps no effect squares.
    void develop_effect_variance(int spp, std::vector<std::vector<float>>& variance) const;

private:
    int w_, h_;
    std::vector<double> sum_, sum_sq_, effects_, effects_sq_;
};

}  // namespace rm
