#include "scene/light_sampler.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace rm {

LightSamplerKind parse_light_sampler(const std::string& name) {
    if (name == "uniform") return LightSamplerKind::Uniform;
    if (name == "power") return LightSamplerKind::Power;
    if (name == "tree") return LightSamplerKind::Tree;
    throw std::invalid_argument("light_sampler: expected 'uniform', 'power' or 'tree', got '" + name + "'");
}

const char* light_sampler_name(LightSamplerKind kind) {
    switch (kind) {
        case LightSamplerKind::Power:
            return "power";
        case LightSamplerKind::Tree:
            return "tree";
        default:
            return "uniform";
    }
}

namespace {

constexpr double kPiD = 3.14159265358979323846;

struct DVec {
    double x = 0, y = 0, z = 0;
};
DVec dv(const Vec3& v) { return {v.x, v.y, v.z}; }
DVec sub(const DVec& a, const DVec& b) { return {a.x - b.x, a.y - b.y, a.z - b.z}; }
double ddot(const DVec& a, const DVec& b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
double safe_sqrt_d(double v) { return std::sqrt(std::max(v, 0.0)); }

// Angle between unit vectors, accurate near 0 and pi.
double angle_between(const Vec3& a, const Vec3& b) {
    if (dot(a, b) < 0.f) return kPiD - 2.0 * std::asin(std::min(1.0, double(length(a + b)) / 2.0));
    return 2.0 * std::asin(std::min(1.0, double(length(b - a)) / 2.0));
}

// cos(a - b) and sin(a - b) clamped at a - b = 0 (pbrt-v4's cosSubClamped,
// sinSubClamped inside LightBounds::Importance).
double cos_sub_clamped(double sin_a, double cos_a, double sin_b, double cos_b) {
    return cos_a > cos_b ? 1.0 : cos_a * cos_b + sin_a * sin_b;
}
double sin_sub_clamped(double sin_a, double cos_a, double sin_b, double cos_b) {
    return cos_a > cos_b ? 0.0 : sin_a * cos_b - cos_a * sin_b;
}

// The two children's importances, made usable as selection weights: NaN
// counts 0, and an infinite one (a point light at the shading point) takes
// all the weight.
void sanitize(double& a, double& b) {
    if (!(a > 0.0)) a = 0.0;
    if (!(b > 0.0)) b = 0.0;
    if (std::isinf(a) || std::isinf(b)) {
        a = std::isinf(a) ? 1.0 : 0.0;
        b = std::isinf(b) ? 1.0 : 0.0;
    }
}

// The build cost of a cluster (pbrt-v4's BVHLightSampler::EvaluateCost,
// the "surface area orientation heuristic" of Estevez and Kulla sec. 4.4):
// power times the solid-angle measure of its emitted directions times its
// box's area, stretched by kr for thin splits. A small diagonal term keeps
// clusters of collinear points (zero area) apart.
double cluster_cost(const LightBounds& b, double kr) {
    double theta_o = std::acos(std::clamp(double(b.cos_o), -1.0, 1.0));
    double theta_e = std::acos(std::clamp(double(b.cos_e), -1.0, 1.0));
    double theta_w = std::min(theta_o + theta_e, kPiD);
    double sin_o = safe_sqrt_d(1.0 - double(b.cos_o) * b.cos_o);
    double m_omega =
        2.0 * kPiD * (1.0 - b.cos_o) +
        kPiD / 2.0 * (2.0 * theta_w * sin_o - std::cos(theta_o - 2.0 * theta_w) - 2.0 * theta_o * sin_o + b.cos_o);
    DVec d = sub(dv(b.hi), dv(b.lo));
    double area = 2.0 * (d.x * d.y + d.y * d.z + d.z * d.x) + 1e-3 * ddot(d, d);
    return double(b.phi) * m_omega * kr * area;
}

Vec3 centroid(const LightBounds& b) { return (b.lo + b.hi) * 0.5f; }

}  // namespace

DirectionCone cone_of(const Vec3& w) {
    DirectionCone c;
    c.w = w;
    c.cos_theta = 1.f;
    c.empty = false;
    return c;
}

DirectionCone cone_union(const DirectionCone& a, const DirectionCone& b) {
    if (a.empty) return b;
    if (b.empty) return a;
    double theta_a = std::acos(std::clamp(double(a.cos_theta), -1.0, 1.0));
    double theta_b = std::acos(std::clamp(double(b.cos_theta), -1.0, 1.0));
    double theta_d = angle_between(a.w, b.w);
    if (std::min(theta_d + theta_b, kPiD) <= theta_a) return a;
    if (std::min(theta_d + theta_a, kPiD) <= theta_b) return b;
    double theta_o = (theta_a + theta_d + theta_b) / 2.0;
    DirectionCone sphere;
    sphere.empty = false;
    sphere.cos_theta = -1.f;
    if (theta_o >= kPiD) return sphere;
    // Rotate a.w towards b.w by theta_o - theta_a about their common normal (Rodrigues).
    Vec3 axis = cross(a.w, b.w);
    float len = length(axis);
    if (!(len > 0.f)) return sphere;
    axis = axis / len;
    double theta_r = theta_o - theta_a;
    float c = float(std::cos(theta_r)), s = float(std::sin(theta_r));
    Vec3 w = a.w * c + cross(axis, a.w) * s + axis * (dot(axis, a.w) * (1.f - c));
    DirectionCone out;
    out.empty = false;
    out.w = normalize(w);
    // Rounded outwards a little, so that the cone still holds both.
    out.cos_theta = float(std::cos(std::min(theta_o * (1.0 + 1e-6) + 1e-7, kPiD)));
    return out;
}

LightBounds bounds_union(const LightBounds& a, const LightBounds& b) {
    if (!(a.phi > 0.f)) return b;
    if (!(b.phi > 0.f)) return a;
    LightBounds u;
    u.lo = vmin(a.lo, b.lo);
    u.hi = vmax(a.hi, b.hi);
    u.phi = a.phi + b.phi;
    DirectionCone ca, cb;
    ca.w = a.w;
    ca.cos_theta = a.cos_o;
    ca.empty = false;
    cb.w = b.w;
    cb.cos_theta = b.cos_o;
    cb.empty = false;
    DirectionCone c = cone_union(ca, cb);
    u.w = c.w;
    u.cos_o = c.cos_theta;
    u.cos_e = std::min(a.cos_e, b.cos_e);
    u.two_sided = a.two_sided || b.two_sided;
    return u;
}

double LightBounds::importance(const Vec3& p, const Vec3& n) const {
    if (!(phi > 0.f)) return 0.0;
    DVec pc = dv(centroid(*this));
    DVec pd = dv(p);
    DVec v = sub(pd, pc);
    double dist2 = ddot(v, v);
    DVec diag = sub(dv(hi), dv(lo));
    // Clamped as pbrt-v4 does (half the diagonal), and away from 0.
    double d2 = std::max({dist2, std::sqrt(ddot(diag, diag)) / 2.0, 1e-30});
    double len = std::sqrt(dist2);
    DVec wi = len > 0.0 ? DVec{v.x / len, v.y / len, v.z / len} : dv(w);
    double cos_w = ddot(dv(w), wi);
    if (two_sided) cos_w = std::fabs(cos_w);
    double sin_w = safe_sqrt_d(1.0 - cos_w * cos_w);
    // The cone of directions from p that the box subtends (pbrt-v4's
    // BoundSubtendedDirections): its bounding sphere's.
    double cos_b = -1.0;
    bool inside = p.x >= lo.x && p.y >= lo.y && p.z >= lo.z && p.x <= hi.x && p.y <= hi.y && p.z <= hi.z;
    if (!inside) {
        DVec h = sub(dv(hi), pc);
        double r2 = ddot(h, h);
        if (dist2 > r2) cos_b = safe_sqrt_d(1.0 - r2 / dist2);
    }
    double sin_b = safe_sqrt_d(1.0 - cos_b * cos_b);
    double sin_o = safe_sqrt_d(1.0 - double(cos_o) * cos_o);
    double cos_x = cos_sub_clamped(sin_w, cos_w, sin_o, cos_o);
    double sin_x = sin_sub_clamped(sin_w, cos_w, sin_o, cos_o);
    double cos_p = cos_sub_clamped(sin_x, cos_x, sin_b, cos_b);
    if (cos_p <= double(cos_e)) return 0.0;
    double imp = double(phi) * cos_p / d2;
    if (n.x != 0.f || n.y != 0.f || n.z != 0.f) {
        double cos_i = std::fabs(ddot(wi, dv(n))) / std::max(double(length(n)), 1e-30);
        double sin_i = safe_sqrt_d(1.0 - cos_i * cos_i);
        imp *= cos_sub_clamped(sin_i, cos_i, sin_b, cos_b);
    }
    return std::max(imp, 0.0);
}

LightSampler::LightSampler(LightSamplerKind kind, std::vector<LightBounds> bounds, std::vector<bool> infinite)
    : kind_(kind), n_(bounds.size()), bounds_(std::move(bounds)) {
    if (infinite.size() != n_) throw std::invalid_argument("LightSampler: one 'infinite' flag per light");
    if (kind_ == LightSamplerKind::Uniform || n_ == 0) {
        bounds_.clear();
        bounds_.shrink_to_fit();
        return;
    }
    cdf_.assign(n_ + 1, 0.0);
    for (size_t i = 0; i < n_; ++i) {
        double phi = double(bounds_[i].phi);
        cdf_[i + 1] = cdf_[i] + (phi > 0.0 && std::isfinite(phi) ? phi : 0.0);
    }
    if (!(cdf_[n_] > 0.0) || !std::isfinite(cdf_[n_])) cdf_.clear();
    if (kind_ == LightSamplerKind::Tree) {
        leaf_of_.assign(n_, -1);
        std::vector<uint32_t> idx;
        for (size_t i = 0; i < n_; ++i) {
            if (infinite[i])
                infinite_.push_back(uint32_t(i));
            else if (bounds_[i].phi > 0.f && std::isfinite(bounds_[i].phi))
                idx.push_back(uint32_t(i));
        }
        if (!idx.empty()) {
            nodes_.reserve(2 * idx.size() - 1);
            parent_.reserve(2 * idx.size() - 1);
            build(idx, 0, idx.size(), -1, 1);
        }
    }
    bounds_.clear();
    bounds_.shrink_to_fit();
}

int LightSampler::build(std::vector<uint32_t>& idx, size_t lo, size_t hi, int parent, int depth) {
    const int me = int(nodes_.size());
    nodes_.emplace_back();
    parent_.push_back(parent);
    depth_ = std::max(depth_, depth);
    if (hi - lo == 1) {
        nodes_[me].leaf = true;
        nodes_[me].child = idx[lo];
        nodes_[me].b = bounds_[idx[lo]];
        leaf_of_[idx[lo]] = me;
        return me;
    }
    LightBounds all;
    Vec3 clo(kInf), chi(-kInf);
    for (size_t i = lo; i < hi; ++i) {
        all = bounds_union(all, bounds_[idx[i]]);
        Vec3 c = centroid(bounds_[idx[i]]);
        clo = vmin(clo, c);
        chi = vmax(chi, c);
    }
    // Split: the cheapest of 12 buckets per axis (pbrt-v4's buildBVH);
    // below 64 levels only, then (and where every centroid coincides) at
    // the median, so the depth stays under 64 + log2(N).
    constexpr int kBuckets = 12;
    double best = kInf;
    int best_dim = -1, best_split = -1;
    Vec3 ext = all.hi - all.lo;
    float ext_max = std::max({ext.x, ext.y, ext.z});
    if (depth < 64)
        for (int dim = 0; dim < 3; ++dim) {
            if (!(chi[dim] > clo[dim])) continue;
            LightBounds bucket[kBuckets];
            int count[kBuckets] = {};
            for (size_t i = lo; i < hi; ++i) {
                float c = centroid(bounds_[idx[i]])[dim];
                int b = std::min(int(kBuckets * ((c - clo[dim]) / (chi[dim] - clo[dim]))), kBuckets - 1);
                b = std::max(b, 0);
                bucket[b] = bounds_union(bucket[b], bounds_[idx[i]]);
                ++count[b];
            }
            double kr = ext[dim] > 0.f ? double(ext_max) / double(ext[dim]) : 1.0;
            // Prefix and suffix unions: buckets 0..s and s+1..B-1.
            LightBounds left[kBuckets], right[kBuckets];
            int nl[kBuckets], nr[kBuckets];
            for (int b = 0; b < kBuckets; ++b) {
                left[b] = b > 0 ? bounds_union(left[b - 1], bucket[b]) : bucket[0];
                nl[b] = (b > 0 ? nl[b - 1] : 0) + count[b];
            }
            for (int b = kBuckets - 1; b >= 0; --b) {
                right[b] = b < kBuckets - 1 ? bounds_union(right[b + 1], bucket[b]) : bucket[b];
                nr[b] = (b < kBuckets - 1 ? nr[b + 1] : 0) + count[b];
            }
            for (int s = 0; s < kBuckets - 1; ++s) {
                if (nl[s] == 0 || nr[s + 1] == 0) continue;
                double cost = cluster_cost(left[s], kr) + cluster_cost(right[s + 1], kr);
                if (cost < best) {
                    best = cost;
                    best_dim = dim;
                    best_split = s;
                }
            }
        }
    size_t mid = lo;
    if (best_dim >= 0) {
        const int dim = best_dim;
        const float c0 = clo[dim], c1 = chi[dim];
        auto it = std::partition(idx.begin() + long(lo), idx.begin() + long(hi), [&](uint32_t i) {
            float c = centroid(bounds_[i])[dim];
            int b = std::max(std::min(int(kBuckets * ((c - c0) / (c1 - c0))), kBuckets - 1), 0);
            return b <= best_split;
        });
        mid = size_t(it - idx.begin());
    }
    if (mid == lo || mid == hi) {
        int dim = 0;
        Vec3 cext = chi - clo;
        if (cext.y > cext[dim]) dim = 1;
        if (cext.z > cext[dim]) dim = 2;
        mid = (lo + hi) / 2;
        std::nth_element(idx.begin() + long(lo), idx.begin() + long(mid), idx.begin() + long(hi),
                         [&](uint32_t a, uint32_t b) {
                             float ca = centroid(bounds_[a])[dim], cb = centroid(bounds_[b])[dim];
                             return ca < cb || (ca == cb && a < b);
                         });
    }
    build(idx, lo, mid, me, depth + 1);
    int right = build(idx, mid, hi, me, depth + 1);
    nodes_[me].child = uint32_t(right);
    nodes_[me].b = bounds_union(nodes_[me + 1].b, nodes_[right].b);
    return me;
}

float LightSampler::prob_infinite() const {
    if (infinite_.empty()) return 0.f;
    return float(infinite_.size()) / float(infinite_.size() + (nodes_.empty() ? 0 : 1));
}

int LightSampler::sample_tree(const Vec3& p, const Vec3& n, float u, float& pmf) const {
    pmf = 0.f;
    if (n_ == 0) return -1;
    const float p_inf = prob_infinite();
    if (u < p_inf) {
        size_t k = infinite_.size();
        size_t i = std::min(size_t(u / p_inf * float(k)), k - 1);
        pmf = p_inf / float(k);
        return int(infinite_[i]);
    }
    if (nodes_.empty()) return -1;
    double uu = std::min((double(u) - p_inf) / (1.0 - p_inf), 1.0 - 0x1p-53);
    double pm = 1.0 - p_inf;
    int node = 0;
    while (!nodes_[size_t(node)].leaf) {
        const Node& nd = nodes_[size_t(node)];
        double i0 = nodes_[size_t(node) + 1].b.importance(p, n), i1 = nodes_[nd.child].b.importance(p, n);
        sanitize(i0, i1);
        double tot = i0 + i1;
        if (!(tot > 0.0)) return -1;
        double q0 = i0 / tot;
        if (uu < q0) {
            uu = uu / q0;
            pm *= q0;
            node = node + 1;
        } else {
            uu = (uu - q0) / (1.0 - q0);
            pm *= i1 / tot;
            node = int(nd.child);
        }
        uu = std::min(std::max(uu, 0.0), 1.0 - 0x1p-53);
    }
    if (node == 0 && !(nodes_[0].b.importance(p, n) > 0.0)) return -1;
    pmf = float(pm);
    return int(nodes_[size_t(node)].child);
}

float LightSampler::pmf(const Vec3& p, const Vec3& n, int light) const {
    if (light < 0 || size_t(light) >= n_) return 0.f;
    if (kind_ != LightSamplerKind::Tree) return pmf_start(light);
    const float p_inf = prob_infinite();
    int node = leaf_of_[size_t(light)];
    if (node < 0) {
        bool inf = std::find(infinite_.begin(), infinite_.end(), uint32_t(light)) != infinite_.end();
        return inf ? p_inf / float(infinite_.size()) : 0.f;
    }
    if (node == 0) return nodes_[0].b.importance(p, n) > 0.0 ? 1.f - p_inf : 0.f;
    // The factors from the leaf up, multiplied from the root down as
    // sample() multiplies them, so both give the same float.
    double factor[256];
    int k = 0;
    while (node != 0) {
        int par = parent_[size_t(node)];
        double i0 = nodes_[size_t(par) + 1].b.importance(p, n),
               i1 = nodes_[nodes_[size_t(par)].child].b.importance(p, n);
        sanitize(i0, i1);
        double tot = i0 + i1;
        double self = node == par + 1 ? i0 : i1;
        if (!(tot > 0.0) || !(self > 0.0)) return 0.f;
        if (k == 256) return 0.f;  // deeper than the build makes
        factor[k++] = self / tot;
        node = par;
    }
    double pm = 1.0 - p_inf;
    while (k > 0) pm *= factor[--k];
    return float(pm);
}

int LightSampler::sample_start_weighted(float u, float& pmf) const {
    pmf = 0.f;
    if (n_ == 0) return -1;
    if (kind_ == LightSamplerKind::Uniform || cdf_.empty()) {
        pmf = 1.f / float(n_);
        return int(std::min(size_t(u * float(n_)), n_ - 1));
    }
    double target = double(u) * cdf_[n_];
    size_t i = size_t(std::upper_bound(cdf_.begin() + 1, cdf_.end(), target) - (cdf_.begin() + 1));
    i = std::min(i, n_ - 1);
    while (i > 0 && !(cdf_[i + 1] > cdf_[i])) --i;  // never a light of zero power
    pmf = float((cdf_[i + 1] - cdf_[i]) / cdf_[n_]);
    return int(i);
}

float LightSampler::pmf_start(int light) const {
    if (light < 0 || size_t(light) >= n_) return 0.f;
    if (kind_ == LightSamplerKind::Uniform || cdf_.empty()) return 1.f / float(n_);
    return float((cdf_[size_t(light) + 1] - cdf_[size_t(light)]) / cdf_[n_]);
}

size_t LightSampler::memory_bytes() const {
    return sizeof(*this) + nodes_.capacity() * sizeof(Node) + parent_.capacity() * sizeof(int32_t) +
           leaf_of_.capacity() * sizeof(int32_t) + infinite_.capacity() * sizeof(uint32_t) +
           cdf_.capacity() * sizeof(double) + bounds_.capacity() * sizeof(LightBounds);
}

}  // namespace rm
