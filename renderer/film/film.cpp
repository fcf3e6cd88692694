#include "film/film.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>

namespace rm {

const char* effect_name(int e) {
    static const char* names[kNumEffects] = {"emission", "direct", "indirect",  "caustic",
                                             "specular", "volume", "subsurface"};
    return (e >= 0 && e < kNumEffects) ? names[e] : "?";
}

FilterSampler::FilterSampler(const std::string& type, float radius, float stddev)
    : type_(type), radius_(radius), stddev_(stddev) {
    if (type != "box" && type != "tent" && type != "gaussian")
        throw std::invalid_argument("rfilter: unknown type '" + type + "'");
    if (!(radius > 0.f) || !std::isfinite(radius)) throw std::invalid_argument("rfilter: radius must be positive");
    if (type == "gaussian" && !(stddev > 0.f)) throw std::invalid_argument("rfilter: stddev must be positive");
    const int n = 4096;
    cdf_.resize(n + 1);
    cdf_[0] = 0;
    double dx = 2.0 * radius_ / n;
    for (int i = 0; i < n; ++i) {
        // Midpoint rule per bin; the density is piecewise constant in 4096 bins.
        double x = -radius_ + (i + 0.5) * dx;
        cdf_[i + 1] = cdf_[i] + std::max(0.0, double(eval(float(x)))) * dx;
    }
    if (!(cdf_[n] > 0)) throw std::invalid_argument("rfilter: filter integrates to zero");
    // Guide table (Chen & Wu 1996 style cutpoints): a starting bin per cdf interval.
    const int g = 1024;
    guide_.resize(g + 1);
    int bin = 0;
    for (int j = 0; j <= g; ++j) {
        double t = cdf_[n] * j / g;
        while (bin < n - 1 && cdf_[bin + 1] <= t) ++bin;
        guide_[j] = bin;
    }
}

int FilterSampler::find_bin(double target) const {
    const int n = int(cdf_.size()) - 1;
    const int g = int(guide_.size()) - 1;
    int j = std::clamp(int(target / cdf_[n] * g), 0, g);
    int i = guide_[j];
    while (i < n - 1 && cdf_[i + 1] <= target) ++i;
    return i;
}

float FilterSampler::eval(float x) const {
    float ax = std::fabs(x);
    if (ax > radius_) return 0.f;
    if (type_ == "box") return 1.f;
    if (type_ == "tent") return 1.f - ax / radius_;
    // Mitsuba 3's gaussian: exp(-x^2 / (2 s^2)) shifted to reach 0 at the radius.
    float a = -1.f / (2.f * stddev_ * stddev_);
    return std::max(0.f, std::exp(a * x * x) - std::exp(a * radius_ * radius_));
}

// The tabulated CDF at x, linear within a bin (the density is piecewise constant).
double FilterSampler::cdf_at(double x) const {
    const int n = int(cdf_.size()) - 1;
    double f = (x + radius_) / (2.0 * radius_ / n);
    if (f <= 0) return 0.0;
    if (f >= n) return cdf_[n];
    int i = int(f);
    return cdf_[i] + (cdf_[i + 1] - cdf_[i]) * (f - i);
}

float FilterSampler::sample(float u, float lo, float hi) const {
    const int n = int(cdf_.size()) - 1;
    double dx = 2.0 * radius_ / n;
    // Interior pixels (the common case) use the whole filter.
    double c0 = lo <= -radius_ ? 0.0 : cdf_at(double(lo));
    double c1 = hi >= radius_ ? cdf_.back() : cdf_at(double(hi));
    if (!(c1 > c0)) return 0.5f * (std::max(lo, -radius_) + std::min(hi, radius_));
    double target = c0 + u * (c1 - c0);
    int i = find_bin(target);
    double width = cdf_[i + 1] - cdf_[i];
    double t = width > 0 ? (target - cdf_[i]) / width : 0.5;
    double x = -radius_ + (i + t) * dx;
    return float(std::clamp(x, double(lo), double(hi)));
}

double FilterSampler::integral(float lo, float hi) const {
    return std::max(0.0, cdf_at(double(hi)) - cdf_at(double(lo)));
}

Film::Film(int width, int height, bool effect_squares) : w_(width), h_(height) {
    size_t n = size_t(width) * size_t(height);
    sum_.assign(3 * n, 0.0);
    sum_sq_.assign(3 * n, 0.0);
    effects_.assign(3 * n * kNumEffects, 0.0);
    if (effect_squares) effects_sq_.assign(3 * n * kNumEffects, 0.0);
}

void Film::add(int pixel, const EffectRadiance& v) {
    Color t = v.total();
    double* s = &sum_[3 * size_t(pixel)];
    double* q = &sum_sq_[3 * size_t(pixel)];
    for (int c = 0; c < 3; ++c) {
        s[c] += t[c];
        q[c] += double(t[c]) * double(t[c]);
    }
    double* e = &effects_[3 * kNumEffects * size_t(pixel)];
    for (int k = 0; k < kNumEffects; ++k)
        for (int c = 0; c < 3; ++c) e[3 * k + c] += v.by_effect[k][c];
    if (!effects_sq_.empty()) {
        double* eq = &effects_sq_[3 * kNumEffects * size_t(pixel)];
        for (int k = 0; k < kNumEffects; ++k)
            for (int c = 0; c < 3; ++c) eq[3 * k + c] += double(v.by_effect[k][c]) * double(v.by_effect[k][c]);
    }
}

void Film::merge_and_clear(Film& pass) {
    for (size_t i = 0; i < sum_.size(); ++i) {
        sum_[i] += pass.sum_[i];
        sum_sq_[i] += pass.sum_sq_[i];
    }
    for (size_t i = 0; i < effects_.size(); ++i) effects_[i] += pass.effects_[i];
    for (size_t i = 0; i < effects_sq_.size() && i < pass.effects_sq_.size(); ++i)
        effects_sq_[i] += pass.effects_sq_[i];
    std::fill(pass.sum_.begin(), pass.sum_.end(), 0.0);
    std::fill(pass.sum_sq_.begin(), pass.sum_sq_.end(), 0.0);
    std::fill(pass.effects_.begin(), pass.effects_.end(), 0.0);
    std::fill(pass.effects_sq_.begin(), pass.effects_sq_.end(), 0.0);
}

// Unbiased sample variance divided by n: the variance of the mean. One
// sample says nothing about its variance: NaN, never a fake 0.
static float mean_variance(double sum, double sum_sq, int spp, double inv) {
    if (spp <= 1) return std::numeric_limits<float>::quiet_NaN();
    double mean = sum * inv;
    double var = std::max(0.0, (sum_sq - spp * mean * mean) / (spp - 1.0));
    return float(var * inv);
}

void Film::develop(int spp, std::vector<float>& image, std::vector<float>& variance,
                   std::vector<std::vector<float>>* effects) const {
    size_t n = size_t(w_) * size_t(h_);
    image.assign(3 * n, 0.f);
    variance.assign(3 * n, 0.f);
    if (effects) effects->assign(kNumEffects, std::vector<float>(3 * n, 0.f));
    if (spp <= 0) return;
    double inv = 1.0 / spp;
    for (size_t i = 0; i < 3 * n; ++i) {
        image[i] = float(sum_[i] * inv);
        variance[i] = mean_variance(sum_[i], sum_sq_[i], spp, inv);
    }
    if (effects)
        for (size_t p = 0; p < n; ++p)
            for (int k = 0; k < kNumEffects; ++k)
                for (int c = 0; c < 3; ++c)
                    (*effects)[k][3 * p + c] = float(effects_[3 * kNumEffects * p + 3 * k + c] * inv);
}

void Film::develop_effect_variance(int spp, std::vector<std::vector<float>>& variance) const {
    variance.clear();
    if (effects_sq_.empty() || spp <= 0) return;
    size_t n = size_t(w_) * size_t(h_);
    variance.assign(kNumEffects, std::vector<float>(3 * n, 0.f));
    double inv = 1.0 / spp;
    for (size_t p = 0; p < n; ++p)
        for (int k = 0; k < kNumEffects; ++k)
            for (int c = 0; c < 3; ++c) {
                size_t i = 3 * kNumEffects * p + 3 * k + c;
                variance[k][3 * p + c] = mean_variance(effects_[i], effects_sq_[i], spp, inv);
            }
}

}  // namespace rm
