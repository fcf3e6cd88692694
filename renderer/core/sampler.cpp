#include "core/sampler.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <stdexcept>

namespace rm {

namespace {

uint32_t reverse_bits32(uint32_t v) {
    v = ((v >> 1) & 0x55555555u) | ((v & 0x55555555u) << 1);
    v = ((v >> 2) & 0x33333333u) | ((v & 0x33333333u) << 2);
    v = ((v >> 4) & 0x0f0f0f0fu) | ((v & 0x0f0f0f0fu) << 4);
    return __builtin_bswap32(v);
}

// Direction numbers of Sobol dimension 2 (Joe and Kuo's row "2 1 0 1"):
// v_k = m_k / 2^k, m_1 = 1, m_k = 2 m_{k-1} xor m_{k-1}, as 32-bit fractions;
// kept, bit-reversed (as owen_reversed takes them), as the xor of the v_k of
// every byte value at each of the index's four bytes, so a point takes four
// lookups instead of a loop over its bits.
struct Sobol2Directions {
    std::array<std::array<uint32_t, 256>, 4> byte{};
    Sobol2Directions() {
        std::array<uint32_t, 32> v{};
        uint64_t m = 1;
        for (int k = 1; k <= 32; ++k) {
            if (k > 1) m = (m << 1) ^ m;
            v[size_t(k - 1)] = uint32_t(m << (32 - k));
        }
        for (int b = 0; b < 4; ++b)
            for (uint32_t x = 0; x < 256; ++x) {
                uint32_t acc = 0;
                for (int k = 0; k < 8; ++k)
                    if (x >> k & 1u) acc ^= v[size_t(8 * b + k)];
                byte[size_t(b)][x] = reverse_bits32(acc);
            }
    }
};
const Sobol2Directions kSobol2;

// The 24 permutations of {0, 1, 2, 3}, in lexicographic order.
struct Perm4 {
    std::array<std::array<uint8_t, 4>, 24> p{};
    Perm4() {
        std::array<uint8_t, 4> a{0, 1, 2, 3};
        for (auto& row : p) {
            row = a;
            std::next_permutation(a.begin(), a.end());
        }
    }
};
const Perm4 kPerm4;

// 24 random bits of a 32-bit value as a float in [0, 1) (as Pcg32::next_float).
float to_float(uint32_t v) { return float(v >> 8) * 0x1p-24f; }

// A uniform float of (key, i).
float hash_float(uint64_t key, uint32_t i) { return to_float(uint32_t(mix64(key ^ (uint64_t(i) << 32 | i)) >> 32)); }

// a / n for 32-bit a by a multiply (Lemire, Kaser and Kurz 2019, "Faster
// Remainder by Direct Computation", Software: Practice and Experience 49(6),
// fastdiv: with c = floor(2^64 / n) + 1, floor(a c / 2^64) = floor(a / n)
// for every 32-bit a, n > 1).
uint32_t div_by(uint32_t a, const SizeConstants& d) {
    return d.n == 1 ? a : uint32_t((static_cast<unsigned __int128>(d.magic) * a) >> 64);
}

// Sobol dimension 2 of index i, bit-reversed.
uint32_t sobol2_reversed(uint32_t i) {
    const auto& t = kSobol2.byte;
    return t[0][i & 255u] ^ t[1][(i >> 8) & 255u] ^ t[2][(i >> 16) & 255u] ^ t[3][i >> 24];
}

// Burley 2020, Section 3: a hash in which every bit depends only on the
// bits below it (adds and multiplies carry upwards), applied to the
// reversed bits of a value, is a nested uniform scramble of its digits from
// the top. Takes the reversed bits, returns the scrambled value.
uint32_t owen_reversed(uint32_t x, uint32_t seed) {
    x += seed;
    x ^= x * 0x6c50b47cu;
    x ^= x * 0xb82f1e52u;
    x ^= x * 0xc7afe638u;
    x ^= x * 0x8d22f6e6u;
    return reverse_bits32(x);
}

// A uniform integer in [0, n) from the top 32 bits of a hash (multiply and
// shift, no division).
uint32_t below(uint64_t hash, uint32_t n) { return uint32_t((uint64_t(uint32_t(hash >> 32)) * n) >> 32); }

uint64_t morton2(uint32_t x, uint32_t y) {
    auto spread = [](uint64_t v) {
        v &= 0xffffffffULL;
        v = (v | (v << 16)) & 0x0000ffff0000ffffULL;
        v = (v | (v << 8)) & 0x00ff00ff00ff00ffULL;
        v = (v | (v << 4)) & 0x0f0f0f0f0f0f0f0fULL;
        v = (v | (v << 2)) & 0x3333333333333333ULL;
        v = (v | (v << 1)) & 0x5555555555555555ULL;
        return v;
    };
    return spread(x) | (spread(y) << 1);
}

// Ahmed and Wonka 2020, Section 4: the `bits`-bit index m with each base-4
// digit (from the top) replaced by its image under one of the 24
// permutations, chosen by hashing the digits above it with the dimension's
// key; an odd lowest bit is flipped by a hashed coin. The map is a
// bijection that keeps every aligned block of 4^k indices a block, so the
// samples of a pixel stay one Sobol net while the pixels' order is
// randomised hierarchically. The digit at bit `at` (at = bits - 2, bits -
// 4, ...) is a function of m's bits from `at` up and of the key.
//
// zorder_perm: the permutation (of kPerm4) of the digit at bit `at` under
// the digits above it.
uint32_t zorder_perm(uint64_t above, int at, uint64_t key) {
    return below(mix64((above | (uint64_t(at + 1) << 58)) ^ key), 24u);
}

uint32_t zorder_digit(uint64_t m, int at, uint64_t key) {
    const uint64_t above = (at + 2 >= 64) ? 0 : (m >> (at + 2));
    return kPerm4.p[zorder_perm(above, at, key)][uint32_t(m >> at) & 3u];
}

// The low 32 bits of the map's digits below bit `top` (a digit boundary:
// top = bits - 2k), the coin included; digits wholly above bit 31 are
// skipped, as the sampler keeps 32 bits.
uint32_t zorder_low32(uint64_t m, int top, uint64_t key) {
    uint64_t out = 0;
    int b = top > 33 ? 32 + (top & 1) : top;
    for (; b >= 2; b -= 2) out |= uint64_t(zorder_digit(m, b - 2, key)) << (b - 2);
    if (b == 1) out |= (m & 1u) ^ (mix64((m >> 1) ^ key) & 1u);
    return uint32_t(out);
}

// permute_index with its constants worked out (SizeConstants). A keyed
// bijection of [0, 2^bits) (xors with the key, multiplies by odd numbers
// and xor-shifts, each invertible modulo 2^bits), walked until it lands in
// [0, n) (cycle walking, Kensler 2013 Section 4), then a keyed rotation,
// which makes every element's image uniform over keys.
inline uint32_t permute(uint32_t i, const SizeConstants& pw, uint64_t key) {
    const uint32_t n = pw.n, w = pw.mask;
    if (n <= 1) return 0;
    const uint32_t k0 = uint32_t(key), k1 = uint32_t(key >> 32);
    const uint32_t x0 = k0 & w, m0 = k1 | 1u, x1 = (k1 >> 7) & w, m1 = (k0 >> 3) | 1u;
    do {
        i ^= x0;
        i = (i * m0) & w;
        i ^= i >> pw.s1;
        i = (i * 0x9e3779b1u) & w;
        i ^= x1;
        i ^= i >> pw.s2;
        i = (i * m1) & w;
        i ^= i >> pw.s1;
    } while (i >= n);
    i += below(mix64(key), n);
    return i >= n ? i - n : i;
}

// The key of pattern `block` of a render's seed, and the key of dimension
// `dim` under a pixel's (or, for zsobol, the film's) key.
uint64_t pattern_key(uint64_t seed, uint64_t block) { return mix64(seed ^ mix64(block + 0x5a6f5b1d3e2c4a97ULL)); }
uint64_t dimension_key(uint64_t key, uint32_t dim) { return mix64(key + 0x9e3779b97f4a7c15ULL * (dim + 1)); }

int ceil_log2(uint64_t n) {
    int k = 0;
    while ((uint64_t(1) << k) < n) ++k;
    return k;
}

}  // namespace

// (stratum + offset) / n, kept below 1 whatever the rounding: the float
// nearest to the double nearest to the quotient. The numerator is exact in
// a double (stratum < 2^24, offset a multiple of 2^-24), and so is its
// product by 1 / n when n is a power of two. Otherwise the product by the
// rounded 1 / n is within 2^-51.9 of the quotient, relatively, as the
// rounded quotient is within 2^-53: both round to the same float unless a
// float rounding midpoint lies within that of them, which the product
// shows by its 29 bits below the float's (2^28 at a midpoint: within 16 of
// it, 2 x the error or more to spare). Then (a quotient on a midpoint, or
// by chance once in about 10^7 values) the division itself decides.
float stratum_value(uint32_t stratum, float offset, const SizeConstants& d) {
    const double num = double(stratum) + double(offset);
    double q = num * d.inv;
    uint64_t bits;
    std::memcpy(&bits, &q, sizeof bits);
    if (d.mask + 1 != d.n && (uint32_t(bits) & 0x1fffffffu) - (0x10000000u - 16u) <= 32u) q = num / double(d.n);
    return std::min(float(q), 0x1.fffffep-1f);
}

uint32_t sobol_u32(uint32_t i, int dim) { return reverse_bits32(dim == 0 ? i : sobol2_reversed(i)); }

uint32_t owen_scramble(uint32_t v, uint32_t seed) { return owen_reversed(reverse_bits32(v), seed); }

SizeConstants::SizeConstants(uint32_t n_) : n(n_), inv(1.0 / double(n_)) {
    if (n <= 1) return;
    magic = ~uint64_t(0) / n + 1;
    uint32_t w = n - 1;
    w |= w >> 1;
    w |= w >> 2;
    w |= w >> 4;
    w |= w >> 8;
    w |= w >> 16;
    int bits = 0;
    while (bits < 32 && (w >> bits) != 0) ++bits;
    mask = w;
    s1 = std::max(1, bits / 2);
    s2 = std::max(1, bits / 3);
}

uint32_t permute_index(uint32_t i, uint32_t n, uint64_t key) { return permute(i, SizeConstants(n), key); }

const char* sampler_names() { return "independent, stratified, multijitter, sobol, zsobol"; }

SamplerPlan::SamplerPlan(const SamplerDesc& desc, int spp, int width, int height, uint64_t seed)
    : name_(desc.type), jitter_(desc.jitter), seed_(seed), width_(std::max(width, 1)) {
    const std::string& t = desc.type;
    if (t == "independent")
        type_ = SamplerType::Independent;
    else if (t == "stratified")
        type_ = SamplerType::Stratified;
    else if (t == "multijitter")
        type_ = SamplerType::Multijitter;
    else if (t == "sobol")
        type_ = SamplerType::Sobol;
    else if (t == "zsobol")
        type_ = SamplerType::ZSobol;
    else
        throw std::invalid_argument("sampler: unknown type '" + t + "' (known: " + sampler_names() + ")");
    const int64_t want = spp > 0 ? spp : desc.sample_count;
    if (want < 1 || want > (int64_t(1) << 24))
        throw std::invalid_argument("sampler '" + t + "': sample_count must be in 1..2^24, got " +
                                    std::to_string(want));
    switch (type_) {
        case SamplerType::Independent:
        case SamplerType::Sobol:  // one infinite sequence per pixel: no pattern size
            n_ = uint32_t(want);
            break;
        case SamplerType::Stratified: {  // rounded up to a square, as Mitsuba 3 does
            uint32_t r = uint32_t(std::ceil(std::sqrt(double(want))));
            while (uint64_t(r) * r < uint64_t(want)) ++r;
            while (r > 1 && uint64_t(r - 1) * (r - 1) >= uint64_t(want)) --r;
            res_x_ = res_y_ = r;
            n_ = r * r;
            break;
        }
        case SamplerType::Multijitter: {  // rows = floor(sqrt N), columns to cover N
            uint32_t rows = std::max<uint32_t>(1, uint32_t(std::floor(std::sqrt(double(want)))));
            while (uint64_t(rows + 1) * (rows + 1) <= uint64_t(want)) ++rows;
            while (uint64_t(rows) * rows > uint64_t(want)) --rows;
            uint32_t cols = uint32_t((uint64_t(want) + rows - 1) / rows);
            res_x_ = cols;
            res_y_ = rows;
            n_ = cols * rows;
            break;
        }
        case SamplerType::ZSobol: {
            log2_n_ = ceil_log2(uint64_t(want));
            n_ = uint32_t(1) << log2_n_;
            zbits_ = 2 * ceil_log2(uint64_t(std::max({width, height, 1})));
            if (zbits_ + log2_n_ > 56)
                throw std::invalid_argument("sampler 'zsobol': film of " + std::to_string(width) + " x " +
                                            std::to_string(height) + " at " + std::to_string(n_) +
                                            " samples per pixel needs more than 56 index bits");
            build_zsobol_tables(uint64_t(std::max(width, 1)) * uint64_t(std::max(height, 1)));
            break;
        }
    }
    size_n_ = SizeConstants(n_);
    size_x_ = SizeConstants(res_x_);
    size_y_ = SizeConstants(res_y_);
}

void SamplerPlan::build_zsobol_tables(uint64_t pixels) {
    // Dimensions with tables: the camera's and 16 bounces of path
    // (Sampler::start_bounce, PixelSampleSource::bounce_stride). Top digits:
    // the pixel's highest, as many as fit kTopDigits and a table of at most
    // 4 entries per sample of the render (a render of few samples would
    // spend more on the table than it saves), and none when they would all
    // lie above the 32 bits kept. At most 4^6 x 264 entries (2.1 MiB).
    constexpr uint32_t kDims = Sampler::kCameraDims + 16 * 16;
    constexpr int kTopDigits = 6;
    const int bits = zbits_ + log2_n_;
    const uint64_t budget = 4 * pixels * n_;
    zdims_ = kDims;
    ztop_digits_ = 0;
    while (ztop_digits_ < std::min(zbits_ / 2, kTopDigits) && (uint64_t(kDims) << (2 * ztop_digits_ + 2)) <= budget)
        ++ztop_digits_;
    if (bits - 2 * ztop_digits_ >= 32) ztop_digits_ = 0;
    ztop_shift_ = bits - 2 * ztop_digits_;
    const uint64_t seed_key = pattern_key(seed_, 0);
    const size_t rows = size_t(1) << (2 * ztop_digits_);
    zkeys_.resize(2 * size_t(zdims_));
    if (ztop_digits_ > 0) ztop_.resize(rows * zdims_);
    std::vector<uint16_t> level, next;
    for (uint32_t d = 0; d < zdims_; ++d) {
        const uint64_t h = dimension_key(seed_key, d);
        zkeys_[2 * size_t(d)] = h;
        zkeys_[2 * size_t(d) + 1] = mix64(h + 1);
        if (ztop_digits_ == 0) continue;
        // Digit by digit from the top: digit k (at bit bits - 2k) of every
        // index whose digits above are `a` is zorder_digit's permutation
        // p(a) of it, so each level takes one hash per prefix.
        level.assign(1, 0);
        for (int k = 1; k <= ztop_digits_; ++k) {
            const int at = bits - 2 * k;
            next.resize(level.size() * 4);
            for (size_t a = 0; a < level.size(); ++a) {
                const uint32_t p = zorder_perm(a, at, h);
                for (uint32_t digit = 0; digit < 4; ++digit)
                    next[4 * a + digit] = uint16_t(uint32_t(level[a]) << 2 | kPerm4.p[p][digit]);
            }
            level.swap(next);
        }
        for (size_t r = 0; r < rows; ++r) ztop_[r * zdims_ + d] = level[r];
    }
}

void SamplerPlan::drop_tables() {
    zdims_ = 0;
    ztop_digits_ = 0;
    zkeys_.clear();
    ztop_.clear();
}

PixelSampleSource::PixelSampleSource(const SamplerPlan& plan, uint64_t pixel, uint64_t sample) : plan_(plan) {
    // Pattern `block` of the pixel; sobol is one sequence, never repeated.
    const bool unbounded = plan.type_ == SamplerType::Sobol;
    const uint64_t block = unbounded ? 0 : sample / plan.n_;
    j_ = uint32_t(unbounded ? sample : sample % plan.n_);
    const uint64_t seed_key = pattern_key(plan.seed_, block);
    if (plan.type_ == SamplerType::ZSobol) {
        // One scramble for the whole film: the pixel is in the index.
        pixel_key_ = seed_key;
        const uint64_t x = pixel % uint64_t(plan.width_), y = pixel / uint64_t(plan.width_);
        zindex_ = (morton2(uint32_t(x), uint32_t(y)) << plan.log2_n_) | j_;
        if (block == 0 && plan.zdims_ > 0) {
            zkeys_ = plan.zkeys_.data();
            if (plan.ztop_digits_ > 0) ztop_ = plan.ztop_.data() + size_t(zindex_ >> plan.ztop_shift_) * plan.zdims_;
        }
    } else {
        pixel_key_ = mix64(seed_key ^ mix64(pixel + 0x243f6a8885a308d3ULL));
        rj_ = reverse_bits32(j_);
    }
}

uint64_t PixelSampleSource::dim_key(uint32_t dim) const { return dimension_key(pixel_key_, dim); }

// zsobol's scrambled index (the z-order scramble's low 32 bits): its top
// digits from the plan's table where it has one, the rest hashed.
uint32_t PixelSampleSource::zsobol_index(uint32_t dim, uint64_t key) const {
    if (ztop_ && dim < plan_.zdims_)
        return uint32_t(uint64_t(ztop_[dim]) << plan_.ztop_shift_) | zorder_low32(zindex_, plan_.ztop_shift_, key);
    return zorder_low32(zindex_, plan_.zbits_ + plan_.log2_n_, key);
}

float PixelSampleSource::get_1d(uint32_t dim) {
    switch (plan_.type_) {
        case SamplerType::Stratified:
        case SamplerType::Multijitter: {
            const uint64_t h = dim_key(dim);
            uint32_t stratum = permute(j_, plan_.size_n_, h);
            return stratum_value(stratum, plan_.jitter_ ? hash_float(h, j_) : 0.5f, plan_.size_n_);
        }
        case SamplerType::Sobol: {
            const uint64_t h = dim_key(dim);
            uint32_t idx = owen_reversed(rj_, uint32_t(h));          // Burley's shuffle: owen_scramble(j, h)
            return to_float(owen_reversed(idx, uint32_t(h >> 32)));  // dimension 1 reversed is the index
        }
        case SamplerType::ZSobol: {
            const uint64_t h = zkeys_ && dim < plan_.zdims_ ? zkeys_[2 * size_t(dim)] : dim_key(dim);
            return to_float(owen_reversed(zsobol_index(dim, h), uint32_t(h >> 32)));
        }
        case SamplerType::Independent:
            break;
    }
    throw std::logic_error("PixelSampleSource: the independent sampler has no source");
}

Vec2 PixelSampleSource::get_2d(uint32_t dim) {
    switch (plan_.type_) {
        case SamplerType::Stratified: {
            const uint64_t h = dim_key(dim), h1 = mix64(h + 1), h2 = mix64(h + 2);
            uint32_t p = permute(j_, plan_.size_n_, h);
            uint32_t cy = div_by(p, plan_.size_x_), cx = p - cy * plan_.res_x_;
            float jx = plan_.jitter_ ? hash_float(h1, j_) : 0.5f, jy = plan_.jitter_ ? hash_float(h2, j_) : 0.5f;
            return {stratum_value(cx, jx, plan_.size_x_), stratum_value(cy, jy, plan_.size_y_)};
        }
        case SamplerType::Multijitter: {
            // Kensler 2013, Section 3: cell (col, row) of an m x n grid, and
            // within it sub-cell (sy, sx) of the n x m grid of the cell, with
            // the sub-cell permutations shared by every row and column, so
            // both projections are stratified into N (N-rooks).
            const uint64_t h = dim_key(dim), h1 = mix64(h + 1), h2 = mix64(h + 2);
            const uint32_t m = plan_.res_x_, n = plan_.res_y_;
            uint32_t s = permute(j_, plan_.size_n_, h);
            uint32_t row = div_by(s, plan_.size_x_), col = s - row * m;
            uint32_t sx = permute(col, plan_.size_x_, h1), sy = permute(row, plan_.size_y_, h2);
            float jx = plan_.jitter_ ? hash_float(h1, j_) : 0.5f, jy = plan_.jitter_ ? hash_float(h2, j_) : 0.5f;
            float x = stratum_value(col * n + sy, jx, plan_.size_n_);  // m n = N
            float y = stratum_value(row * m + sx, jy, plan_.size_n_);
            return {x, y};
        }
        case SamplerType::Sobol: {
            const uint64_t h = dim_key(dim), h1 = mix64(h + 1);
            uint32_t idx = owen_reversed(rj_, uint32_t(h));
            return {to_float(owen_reversed(idx, uint32_t(h >> 32))),
                    to_float(owen_reversed(sobol2_reversed(idx), uint32_t(h1)))};
        }
        case SamplerType::ZSobol: {
            uint64_t h, h1;
            if (zkeys_ && dim < plan_.zdims_) {
                h = zkeys_[2 * size_t(dim)];
                h1 = zkeys_[2 * size_t(dim) + 1];
            } else {
                h = dim_key(dim);
                h1 = mix64(h + 1);
            }
            const uint32_t idx = zsobol_index(dim, h);
            return {to_float(owen_reversed(idx, uint32_t(h >> 32))),
                    to_float(owen_reversed(sobol2_reversed(idx), uint32_t(h1)))};
        }
        case SamplerType::Independent:
            break;
    }
    throw std::logic_error("PixelSampleSource: the independent sampler has no source");
}

}  // namespace rm
