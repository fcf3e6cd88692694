// The primary sample space of Metropolis light transport (Kelemen,
// Szirmay-Kalos, Antal and Csonka 2002, "A Simple and Robust Mutation
// Strategy for the Metropolis Light Transport Algorithm"): a path is the
// image of a point u of the unit hypercube under the estimator's own
// sampling (every next_1d / next_2d of a Sampler built on this source reads
// one coordinate), and the Markov chain mutates u:
//   - a large step replaces every coordinate by a fresh uniform number;
//   - a small step moves each coordinate by a symmetric perturbation,
//     wrapped around [0, 1) (here a normal of standard deviation sigma, the
//     kernel pbrt-v4's MLTSampler uses in place of Kelemen's exponential
//     one; both are symmetric, which is all the acceptance rule needs).
// Coordinates are made lazily (Kelemen 2002, sec. 4.1): a coordinate the
// path did not read since the last accepted large step is still a uniform
// number nobody has seen, so it is drawn fresh when first read; one read
// after n small steps takes all n at once (the sum of n normals of variance
// sigma^2 is a normal of variance n sigma^2). A rejected proposal restores
// every coordinate it touched. pbrt-v4's MLTSampler (samplers.h) has the
// same structure (EnsureReady, Accept, Reject); its names are kept where
// they fit.
#pragma once
#include <cmath>
#include <cstdint>
#include <vector>

#include "core/rng.h"

namespace rm {

class PssSampler final : public SampleSource {
public:
    PssSampler(float sigma, float large_step_probability) : sigma_(sigma), large_p_(large_step_probability) {}

    // A fresh point: every coordinate unread, fresh values from stream
    // (a, b) (a bootstrap sample, or its replay as a chain's start).
    // With `dim` >= 0, that coordinate reads `value` instead of its fresh
    // draw (the draw is still made, so the others keep theirs): the same
    // point with one coordinate moved (mmlt's bootstrap over strategies).
    void restart(uint64_t a, uint64_t b, int dim = -1, float value = 0.f) {
        x_.clear();
        iteration_ = 0;
        last_large_ = 0;
        large_ = true;
        rng_.seed(a, b);
        fixed_dim_ = dim;
        fixed_value_ = value;
    }
    // From here on, fresh values and mutations come from stream (a, b)
    // (the chain's own, after its start was replayed from the bootstrap's).
    void reseed(uint64_t a, uint64_t b) {
        rng_.seed(a, b);
        fixed_dim_ = -1;
    }
    // Coordinate `dim`'s current value (0 if it was never read).
    float value(uint32_t dim) const { return dim < x_.size() ? x_[dim].value : 0.f; }

    // Begins the next proposal: a large step with the large-step
    // probability, else a small one (the choice is the chain's stream's).
    void start_iteration() {
        ++iteration_;
        large_ = uniform() < large_p_;
    }
    bool large_step() const { return large_; }

    // The proposal becomes the chain's state.
    void accept() {
        if (large_) last_large_ = iteration_;
    }
    // The proposal is dropped: every coordinate it changed gets its old
    // value back.
    void reject() {
        for (Coord& c : x_)
            if (c.last_modified == iteration_) {
                c.value = c.backup;
                c.last_modified = c.backup_modified;
            }
        --iteration_;
    }

    // A uniform number of the chain's stream (acceptance tests, bootstrap
    // resampling).
    float uniform() { return rng_.next_float(); }

    float get_1d(uint32_t dim) override {
        if (dim >= x_.size()) x_.resize(size_t(dim) + 1);
        Coord& c = x_[dim];
        if (c.last_modified == iteration_) return c.value;
        c.backup = c.value;
        c.backup_modified = c.last_modified;
        if (large_ || c.last_modified < last_large_ || c.last_modified < 0) {
            // Unread since the last accepted large step: still uniform.
            c.value = uniform();
            if (int64_t(dim) == fixed_dim_ && iteration_ == 0) c.value = fixed_value_;
        } else {
            const int64_t n = iteration_ - c.last_modified;
            c.value += normal() * sigma_ * std::sqrt(float(n));
            c.value -= std::floor(c.value);
            if (!(c.value < 1.f)) c.value = 0.f;  // rounding of a tiny negative value
        }
        c.last_modified = iteration_;
        return c.value;
    }

private:
    struct Coord {
        float value = 0.f, backup = 0.f;
        int64_t last_modified = -1, backup_modified = -1;  // -1: never read
    };
    // A standard normal number (Box and Muller 1958).
    float normal() {
        float u1 = uniform(), u2 = uniform();
        return std::sqrt(-2.f * std::log(1.f - u1)) * std::cos(2.f * kPi * u2);
    }

    float sigma_, large_p_;
    std::vector<Coord> x_;
    int64_t iteration_ = 0, last_large_ = 0, fixed_dim_ = -1;
    float fixed_value_ = 0.f;
    bool large_ = true;
    Pcg32 rng_;
};

}  // namespace rm
