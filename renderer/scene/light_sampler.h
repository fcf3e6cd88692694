// Emitter selection: which emitter a light sample or a light path starts
// from, and with what probability. Three samplers, named as the light
// samplers of pbrt-v4 (lightsamplers.h) and chosen by every estimator's
// `light_sampler` parameter (render/registry.h, docs/light_sampler.md):
//   uniform  every emitter with probability 1 / N (Mitsuba 3's
//            Scene::sample_emitter; the default);
//   power    in proportion to its power (luminance of its flux), from a
//            cumulative table;
//   tree     a bounding volume hierarchy of the finite emitters whose
//            nodes bound position, power and emitted directions (a cone of
//            normals widened by the spread of emission), descended from the
//            root by each child's importance seen from the shading point
//            (Estevez and Kulla 2018, "Importance Sampling of Many Lights
//            with Adaptive Tree Splitting", sec. 4; the importance and the
//            build cost as pbrt-v4's LightBounds::Importance and
//            BVHLightSampler::EvaluateCost). Emitters at infinity sit beside
//            the tree, each picked with probability 1 / (N_inf + 1).
// Selection seen from a point (next event estimation, and the MIS weights
// that need its density) depends on the point and its normal for `tree`;
// light paths start without a point, so they select by power under both
// `power` and `tree` (uniformly under `uniform`).
#pragma once
#include <algorithm>
#include <cstdint>
#include <string>
#include <vector>

#include "core/math.h"

namespace rm {

enum class LightSamplerKind { Uniform, Power, Tree };
// "uniform", "power", "tree"; anything else: std::invalid_argument naming it.
LightSamplerKind parse_light_sampler(const std::string& name);
const char* light_sampler_name(LightSamplerKind kind);

// A cone of directions about the unit axis w, of half-angle acos(cos_theta)
// (cos_theta = -1: the whole sphere).
struct DirectionCone {
    Vec3 w{0.f, 0.f, 1.f};
    float cos_theta = 1.f;
    bool empty = true;
};
// The smallest cone holding both (pbrt-v4's Union(DirectionCone, DirectionCone)).
DirectionCone cone_union(const DirectionCone& a, const DirectionCone& b);
DirectionCone cone_of(const Vec3& w);

// What bounds an emitter's (or a cluster's) light: its box, power phi,
// the cone of its normals (axis w, half-angle theta_o) and how far beyond
// them it emits (theta_e: pi / 2 for a cosine emitter).
struct LightBounds {
    Vec3 lo{kInf}, hi{-kInf};
    float phi = 0.f;
    Vec3 w{0.f, 0.f, 1.f};
    float cos_o = 1.f, cos_e = 1.f;
    bool two_sided = false;
    // An upper estimate of the light reaching p (on a surface of normal n;
    // n = 0: a point in a medium, no cosine there): phi times the cosine of
    // the smallest angle between an emitting direction and p, over the
    // squared distance clamped as pbrt-v4 does (Estevez and Kulla eq. 3;
    // LightBounds::Importance). 0 only where no emitter inside emits
    // towards p.
    double importance(const Vec3& p, const Vec3& n) const;
};
LightBounds bounds_union(const LightBounds& a, const LightBounds& b);

class LightSampler {
public:
    // Over lights 0 .. N-1: `bounds[i]` (phi the power) for the finite
    // ones, `infinite[i]` true for emitters at infinity (their bounds only
    // give their power).
    LightSampler(LightSamplerKind kind, std::vector<LightBounds> bounds, std::vector<bool> infinite);
    LightSamplerKind kind() const { return kind_; }
    size_t size() const { return n_; }

    // Selection seen from p (normal n, zero in a medium): the light that u
    // in [0, 1) picks, -1 when none (no emitters, or none lights p), and its
    // probability `pmf`.
    int sample(const Vec3& p, const Vec3& n, float u, float& pmf) const {
        return kind_ == LightSamplerKind::Tree ? sample_tree(p, n, u, pmf) : sample_start(u, pmf);
    }
    // The probability that sample(p, n, .) picks `light`.
    float pmf(const Vec3& p, const Vec3& n, int light) const;
    // Selection without a point (a light path's start); the uniform case inline.
    int sample_start(float u, float& pmf) const {
        if (kind_ != LightSamplerKind::Uniform || n_ == 0) return sample_start_weighted(u, pmf);
        pmf = 1.f / float(n_);
        return int(std::min(size_t(u * float(n_)), n_ - 1));
    }
    float pmf_start(int light) const;

    // The tree's figures (0 for the other samplers): nodes, depth, bytes.
    size_t node_count() const { return nodes_.size(); }
    int depth() const { return depth_; }
    size_t memory_bytes() const;

private:
    struct Node {
        LightBounds b;
        uint32_t child = 0;  // interior: the second child (the first is this + 1); leaf: the light
        bool leaf = false;
    };
    int sample_tree(const Vec3& p, const Vec3& n, float u, float& pmf) const;
    int sample_start_weighted(float u, float& pmf) const;
    int build(std::vector<uint32_t>& idx, size_t lo, size_t hi, int parent, int depth);
    float prob_infinite() const;

    LightSamplerKind kind_;
    size_t n_ = 0;
    std::vector<LightBounds> bounds_;
    // power: the cumulative power (double), cdf_[i + 1] - cdf_[i] = phi_i;
    // empty when the total is 0 (then uniform).
    std::vector<double> cdf_;
    // tree
    std::vector<Node> nodes_;
    std::vector<int32_t> parent_;   // per node; -1 for the root
    std::vector<int32_t> leaf_of_;  // per light: its leaf, -1 outside the tree
    std::vector<uint32_t> infinite_;
    int depth_ = 0;
};

}  // namespace rm
