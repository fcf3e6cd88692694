// Structured samplers behind Sampler (rng.h), with Mitsuba 3's names and
// parameters: `independent` (the PCG stream, rng.h), `stratified` and
// `multijitter` (sample_count, jitter), and two scrambled Sobol samplers,
// `sobol` (per pixel) and `zsobol` (one sequence over the image in Z order).
//
// Every sampler is a function of (seed, pixel, sample index, dimension): a
// value never depends on which thread draws it or in which order pixels are
// rendered. `dimension` is the Sampler's counter of values drawn along the
// path (a 2D draw takes two), so every estimator gets its dimensions in the
// order it consumes them; the structure is across the samples of a pixel
// (or, for zsobol, of neighbouring pixels) in each dimension or 2D pair.
// Pattern size N: the render's spp (the sampler's sample_count under a time
// budget); sample index s uses pattern s / N with a fresh scramble, s mod N
// within it, so a render past N samples stays unbiased.
//
// Citations:
// - stratified: jittered sampling with strata shuffled per dimension
//   (Mitsuba 3 src/samplers/stratified.cpp: 1D strata of N, 2D a sqrt N grid,
//   N rounded up to a square);
// - multijitter: Kensler 2013, "Correlated Multi-Jittered Sampling", Pixar
//   TM 13-01, Section 3 (x = (i + (sy + jx) / n) / m, y = (j + (sx + jy) / m) / n)
//   with hashed permutations by cycle walking (ibid. Section 4);
// - sobol: Burley 2020, "Practical Hash-based Owen Scrambling", JCGT 9(4):
//   nested uniform scrambling by hashing (Section 3, the Laine-Karras style
//   hash with its four constants), shuffled (Section 4) and padded in 2D
//   pairs, so only Sobol dimensions 1 and 2 are used;
// - zsobol: Ahmed and Wonka 2020, "Screen-Space Blue-Noise Diffusion of
//   Monte Carlo Sampling Error via Hierarchical Ordering of Pixels", ACM TOG
//   39(6) (index = Morton code of the pixel, then the sample; base-4 digits
//   permuted by hashing of the higher digits, Section 4), as pbrt-v4 builds
//   it in src/pbrt/samplers.h ZSobolSampler;
// - Sobol dimension 2's direction numbers: Joe and Kuo 2008, "Constructing
//   Sobol sequences with better two-dimensional projections", SIAM J. Sci.
//   Comput. 30(5), file new-joe-kuo-6.21201, the row "2 1 0 1" (s = 1,
//   a = 0, m_1 = 1), expanded by their recurrence m_k = 2 m_{k-1} xor m_{k-1}.
#pragma once
#include <cstdint>
#include <string>
#include <vector>

#include "core/rng.h"

namespace rm {

enum class SamplerType { Independent, Stratified, Multijitter, Sobol, ZSobol };

// What the scene (or render()) asks for. sample_count: the pattern size
// when the render has no spp (time budget).
struct SamplerDesc {
    std::string type = "independent";
    int sample_count = 4;
    bool jitter = true;
};

// The sampler names the renderer knows, in one place ("a, b, c").
const char* sampler_names();

// What the samplers work out once per plan for a size n (a pattern, a
// grid's side): permute_index's mask 2^bits - 1 (the smallest power of two
// >= n) and the two shifts of its bijection of [0, 2^bits), and n's
// reciprocals, so that dividing by n takes a multiply.
struct SizeConstants {
    SizeConstants() = default;
    explicit SizeConstants(uint32_t n);
    uint32_t n = 1, mask = 0;
    int s1 = 1, s2 = 1;
    uint64_t magic = 0;  // floor(2^64 / n) + 1 (0 for n = 1): a / n = (a magic) >> 64 for 32-bit a
    double inv = 1.0;    // 1 / n, rounded
};

// A render's sampler, resolved once: type, pattern size, film size (zsobol).
class SamplerPlan {
public:
    // Throws std::invalid_argument naming an unknown type or a bad parameter.
    SamplerPlan(const SamplerDesc& desc, int spp, int width, int height, uint64_t seed);
    SamplerType type() const { return type_; }
    bool independent() const { return type_ == SamplerType::Independent; }
    // The pattern size N the samples of a pixel are structured over.
    uint32_t pattern_size() const { return n_; }
    const std::string& name() const { return name_; }
    // For the tests: drops the plan's tables (zsobol's keys and top digits),
    // so that every value is hashed as the definition states; the values
    // must not change.
    void drop_tables();

private:
    friend class PixelSampleSource;
    void build_zsobol_tables(uint64_t pixels);
    SamplerType type_;
    std::string name_;
    bool jitter_;
    uint64_t seed_;
    uint32_t n_ = 1;                          // pattern size
    uint32_t res_x_ = 1, res_y_ = 1;          // multijitter: columns x rows; stratified: the 2D grid side
    int log2_n_ = 0;                          // zsobol: N = 2^log2_n
    int width_ = 1;                           // film width: pixel index -> (x, y)
    int zbits_ = 0;                           // zsobol: bits of the Morton index of a pixel
    SizeConstants size_n_, size_x_, size_y_;  // the constants of n_, res_x_, res_y_
    // zsobol, pattern 0 (samples [0, N)), dimensions [0, zdims_): the keys
    // of a dimension and of its second value (PixelSampleSource::dim_key,
    // film-wide as the pixel is in the index), two a dimension, and the top
    // ztop_digits_ base-4 digits of the index scrambled (sampler.cpp's z-order scramble,
    // all above the sample's digits: a function of the dimension and those
    // digits alone), for each of the 4^ztop_digits_ values of those digits
    // a row of zdims_ (so a sample reads its dimensions one after another).
    // The other digits are hashed per value.
    int ztop_digits_ = 0;
    int ztop_shift_ = 0;  // bit where the tabled digits end: the index's bits - 2 ztop_digits_
    uint32_t zdims_ = 0;
    std::vector<uint64_t> zkeys_;
    std::vector<uint16_t> ztop_;
};

// The values of sample `sample` of pixel `pixel` under `plan`, for
// Sampler(SampleSource*); lives on the stack of the sample it serves.
class PixelSampleSource final : public SampleSource {
public:
    PixelSampleSource(const SamplerPlan& plan, uint64_t pixel, uint64_t sample);
    float get_1d(uint32_t dim) override;
    Vec2 get_2d(uint32_t dim) override;
    // path's bounce draws 8 values on a diffuse vertex (light sample 4,
    // BSDF sample 3, roulette 1); room for a dipole or media step beside.
    uint32_t bounce_stride() const override { return 16; }

private:
    uint64_t dim_key(uint32_t dim) const;
    uint32_t zsobol_index(uint32_t dim, uint64_t key) const;
    const SamplerPlan& plan_;
    uint64_t pixel_key_;               // the seed, pixel and pattern hashed together (zsobol: seed and pattern)
    uint32_t j_;                       // the sample's index within its pattern
    uint32_t rj_ = 0;                  // sobol: j's bits reversed
    uint64_t zindex_ = 0;              // zsobol: Morton index of the pixel, then j
    const uint64_t* zkeys_ = nullptr;  // zsobol, pattern 0: the plan's dimension keys
    const uint16_t* ztop_ = nullptr;   // zsobol, pattern 0: the plan's row of this index's top digits
};

// Building blocks, exposed for the tests (test_hooks.cpp).
// Sobol dimension 1 (van der Corput) and 2 of index i, 32 bits, unscrambled.
uint32_t sobol_u32(uint32_t i, int dim);
// Burley 2020's nested uniform (Owen) scramble of the bits of v by seed.
uint32_t owen_scramble(uint32_t v, uint32_t seed);
// A pseudo-random permutation of [0, n) (n >= 1) chosen by key: element i.
uint32_t permute_index(uint32_t i, uint32_t n, uint64_t key);
// (stratum + offset) / d.n as a float below 1: the float of the double
// quotient, by a multiply where that is provably the same.
float stratum_value(uint32_t stratum, float offset, const SizeConstants& d);

}  // namespace rm
