// PCG32 random number generator (O'Neill 2014, "PCG: A Family of Simple Fast
// Space-Efficient Statistically Good Algorithms for Random Number Generation",
// the pcg32 XSH-RR 64/32 variant). A generator is seeded per (seed, pixel,
// sample) so results are identical whatever the thread count or tile order.
#pragma once
#include <cstdint>
#include "core/math.h"

namespace rm {

class Pcg32 {
public:
    Pcg32() { seed(0x853c49e6748fea9bULL, 0xda3e39cb94b95bdbULL); }
    Pcg32(uint64_t initstate, uint64_t initseq) { seed(initstate, initseq); }
    void seed(uint64_t initstate, uint64_t initseq) {
        state_ = 0u;
        inc_ = (initseq << 1u) | 1u;
        next_u32();
        state_ += initstate;
        next_u32();
    }
    uint32_t next_u32() {
        uint64_t old = state_;
        state_ = old * 6364136223846793005ULL + inc_;
        uint32_t xorshifted = uint32_t(((old >> 18u) ^ old) >> 27u);
        uint32_t rot = uint32_t(old >> 59u);
        return (xorshifted >> rot) | (xorshifted << ((~rot + 1u) & 31));
    }
    // Uniform float in [0, 1): 24 random mantissa bits, never returns 1.
    float next_float() { return float(next_u32() >> 8) * 0x1p-24f; }

private:
    uint64_t state_, inc_;
};

// SplitMix64 finaliser, used to decorrelate seeds (Steele et al. 2014).
inline uint64_t mix64(uint64_t z) {
    z += 0x9e3779b97f4a7c15ULL;
    z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ULL;
    z = (z ^ (z >> 27)) * 0x94d049bb133111ebULL;
    return z ^ (z >> 31);
}

// Where sample values come from when they are not the independent PCG
// stream: a sampler with structure across samples (stratified, Sobol) or
// Metropolis' primary sample space, whose values are mutated between
// samples. `dim` counts the values the path has drawn so far (a 2D draw
// takes two), so a source sees the path's dimensions in the order the
// estimator consumes them.
class SampleSource {
public:
    virtual ~SampleSource() = default;
    virtual float get_1d(uint32_t dim) = 0;
    virtual Vec2 get_2d(uint32_t dim) { return {get_1d(dim), get_1d(dim + 1)}; }
    // Dimensions reserved per bounce (Sampler::start_bounce), 0: none, the
    // dimensions follow the draws one after another.
    virtual uint32_t bounce_stride() const { return 0; }
};

// The PCG stream of (seed, pixel, sample) that Sampler draws from without a SampleSource.
inline Pcg32 independent_stream(uint64_t seed, uint64_t pixel, uint64_t sample_index) {
    return Pcg32(mix64(seed ^ mix64(sample_index + 0x632be59bd9b4e019ULL)), mix64(pixel + (seed << 1)));
}

// Sampler: what estimators ask for 1D/2D samples. By default the
// independent PCG stream of (seed, pixel, sample); given a SampleSource
// (not owned; it outlives the sampler) the values come from it instead.
// The independent stream pays one predictable branch per draw for that.
class Sampler {
public:
    Sampler(uint64_t seed, uint64_t pixel, uint64_t sample_index)
        : rng_(independent_stream(seed, pixel, sample_index)) {}
    explicit Sampler(SampleSource* source) : source_(source), stride_(source ? source->bounce_stride() : 0) {}
    float next_1d() {
        if (source_) return source_->get_1d(dim_++);
        return rng_.next_float();
    }
    Vec2 next_2d() {
        if (source_) {
            Vec2 v = source_->get_2d(dim_);
            dim_ += 2;
            return v;
        }
        float a = rng_.next_float();
        float b = rng_.next_float();
        return {a, b};
    }
    // Values drawn so far through a source (0 for the independent stream).
    uint32_t dimension() const { return dim_; }
    // Called by an estimator at the start of bounce `depth` (before its
    // light sample): with a source that reserves dimensions per bounce,
    // bounce `depth` starts at dimension kCameraDims + depth * stride, so
    // that a bounce drawing fewer values than the same bounce of another
    // sample (no light sample at a specular vertex) does not shift the
    // dimensions of the bounces after it. The counter never moves back, so
    // no dimension is drawn twice along a path; a no-op otherwise.
    void start_bounce(int depth) {
        if (stride_ == 0) return;
        uint32_t at = kCameraDims + uint32_t(depth) * stride_;
        if (at > dim_) dim_ = at;
    }
    // The dimensions a camera sample takes first (camera_sample.h draws 7).
    static constexpr uint32_t kCameraDims = 8;

private:
    Pcg32 rng_;
    SampleSource* source_ = nullptr;
    uint32_t stride_ = 0;
    uint32_t dim_ = 0;
};

// Sampler's independent stream alone (the same numbers as Sampler(seed,
// pixel, sample)), for loops that never take a SampleSource: no branch per
// draw, and a local one stays in registers (photon tracing).
class IndependentSampler {
public:
    IndependentSampler(uint64_t seed, uint64_t pixel, uint64_t sample_index)
        : rng_(independent_stream(seed, pixel, sample_index)) {}
    float next_1d() { return rng_.next_float(); }
    Vec2 next_2d() {
        float a = rng_.next_float();
        float b = rng_.next_float();
        return {a, b};
    }

private:
    Pcg32 rng_;
};

}  // namespace rm
