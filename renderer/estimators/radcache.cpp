// `radcache`: radiance caching for glossy (and diffuse) surfaces (Krivanek,
// Gautron, Pattanaik and Bouatouch 2005, "Radiance caching for efficient
// global illumination computation"): a record stores the incident radiance
// at x as coefficients of hemispherical harmonics (Gautron, Krivanek,
// Pattanaik and Bouatouch 2004, "A novel hemispherical basis for accurate
// and efficient rendering") up to `order`, and a lookup evaluates the
// interpolated incident radiance against the BSDF of the lookup point.
//
// The split into effect classes, the gather rays' radiance, the overture
// and the record index are irrcache's (irrcache.cpp's first comment,
// cache_common.h): emission, direct, caustic and specular are `path`'s own;
// only the indirect class at the first vertex x comes from the cache, at
// every x whose BSDF is smooth and reflective only (diffuse, rough
// conductors; mixed delta-and-smooth and transmissive BSDFs are path
// traced), and whose lobe is broad enough for the harmonics: its density
// towards the mirror direction at most max_lobe_pdf (8 by default: a GGX
// conductor of alpha 0.2 seen at 50 degrees is about 3, alpha 1e-4 about
// 1e7; Krivanek et al. 2005 likewise leave highly glossy BRDFs to ray
// tracing).
//
// Record at x, in x's shading frame: M x N stratified directions uniform in
// solid angle (M = gather_resolution strata of cos theta, N = round(pi M) of
// phi), L_jk the gather radiance, and
//   lambda_lm = sum_jk L_jk H_lm(w_jk) 2 pi / (M N),
// H_lm(theta, phi) = sqrt(2) Y_lm(arccos(2 cos theta - 1), phi), Y_lm the
// real spherical harmonics (orthonormal on the hemisphere, Gautron et al.
// 2004). Lookup at x: the records that cover x by Tabellion and
// Lamorlette's weight (irrcache's, with kappa), their coefficients averaged
// with the weights and read in x's frame (no rotation: the weight keeps the
// records' normals within 10 degrees / kappa of x's, and what that costs is
// part of the measured bias),
//   L(w) = sum_lm lambda_lm H_lm(w in x's frame),
// integrated against x's BSDF by lookup_samples
// BSDF samples: L_o = 1/S sum_s f cos / pdf (w_s) L(w_s) (an unbiased
// estimate of the reconstruction's reflected radiance, clamped at 0 only
// as a whole; on a Lambertian x in closed form instead: f times the
// reconstruction's irradiance, from its l <= 1, m = 0 coefficients). No gradients
// (Krivanek et al. 2005 and Jarosz et al. 2008 derive radiance-cache
// gradients; not implemented) and no neighbour clamping: the bias is the
// interpolation's and the truncation at `order` (measured against the
// order in docs/irrcache.md).
// Bias: biased. Records in res.arrays["radcache_records"].
#include <cmath>
#include <stdexcept>

#include "estimators/cache_common.h"
#include "transport/common.h"

namespace rm {

namespace {

std::unique_ptr<Integrator> make_radcache(ParamReader& p);

constexpr int kMaxOrder = 12;

[[maybe_unused]] const bool kRegistered = register_estimator([] {
    EstimatorInfo e;
    e.name = "radcache";
    e.doc =
        "radiance caching (Krivanek et al. 2005): incident radiance in hemispherical harmonics, evaluated "
        "against the BSDF at lookup; indirect light only, the rest path traced";
    e.params = {
        max_depth_param(),
        rr_depth_param(),
        hide_emitters_param(),
        ParamSpec::integer("order", 4, "highest hemispherical-harmonics band l ((order + 1)^2 coefficients)")
            .at_least(0)
            .at_most(kMaxOrder),
        ParamSpec::integer("gather_resolution", 10, "cos-theta strata M of a record's gather (M x round(pi M) rays)")
            .at_least(1)
            .at_most(256),
        ParamSpec::real("kappa", 1.0, "Tabellion's kappa: larger means denser records")
            .greater_than(0)
            .alias("quality"),
        ParamSpec::real("quality_adjustment", 0.5, "kappa of the camera passes' lookups relative to the overture's")
            .greater_than(0)
            .at_most(1),
        ParamSpec::integer("lookup_samples", 4, "BSDF samples per lookup").at_least(1).at_most(1024),
        ParamSpec::real("max_lobe_pdf", 8.0,
                        "BSDFs whose density towards the mirror direction exceeds this (sharper lobes than the "
                        "harmonics resolve) are path traced; 0: no limit")
            .at_least(0),
        ParamSpec::real("min_spacing", 0.005, "smallest record radius, relative to the scene's bounding sphere")
            .at_least(0),
        ParamSpec::real("max_spacing", 0.25, "largest record radius, relative to the scene's bounding sphere")
            .greater_than(0),
        ParamSpec::boolean("overture", true,
                           "fill the cache before the camera passes (false: no cache, every sample gathers)"),
    };
    e.caps.driver = Driver::OwnPasses;
    e.caps.bias = Bias::Biased;
    e.factory = make_radcache;
    return e;
}());

const float kSqrtOneMinusCos10 = std::sqrt(1.f - std::cos(10.f * kPi / 180.f));

// Hemispherical harmonics H_lm (file's first comment) of a local direction
// (z >= 0) for l <= order, index l (l + 1) + m. The associated Legendre
// functions by the standard recurrences in m and l; K_lm the normalisation.
class Hsh {
public:
    explicit Hsh(int order) : order_(order) {
        for (int l = 0; l <= order; ++l)
            for (int m = 0; m <= l; ++m) {
                double f = 1.0;  // (l - m)! / (l + m)!
                for (int k = l - m + 1; k <= l + m; ++k) f /= double(k);
                k_[l][m] = float(std::sqrt((2.0 * l + 1.0) / (4.0 * kPi) * f));
            }
    }
    int count() const { return (order_ + 1) * (order_ + 1); }
    void eval(const Vec3& w, float* out) const {
        float x = std::min(1.f, std::max(-1.f, 2.f * w.z - 1.f));
        float sx = std::sqrt(std::max(0.f, 1.f - x * x));
        float phi = std::atan2(w.y, w.x);
        float p[kMaxOrder + 1][kMaxOrder + 1];
        float pmm = 1.f;
        for (int m = 0; m <= order_; ++m) {
            if (m > 0) pmm *= -float(2 * m - 1) * sx;
            p[m][m] = pmm;
            if (m < order_) p[m + 1][m] = x * float(2 * m + 1) * pmm;
            for (int l = m + 2; l <= order_; ++l)
                p[l][m] = (float(2 * l - 1) * x * p[l - 1][m] - float(l + m - 1) * p[l - 2][m]) / float(l - m);
        }
        const float s2 = std::sqrt(2.f);
        for (int l = 0; l <= order_; ++l) {
            out[l * (l + 1)] = s2 * k_[l][0] * p[l][0];
            for (int m = 1; m <= l; ++m) {
                float base = s2 * s2 * k_[l][m] * p[l][m];
                out[l * (l + 1) + m] = base * std::cos(float(m) * phi);
                out[l * (l + 1) - m] = base * std::sin(float(m) * phi);
            }
        }
    }

private:
    int order_;
    float k_[kMaxOrder + 1][kMaxOrder + 1] = {};
};

struct RadRecord {
    Vec3 p;
    Frame f;
    float r = 0.f;
    std::vector<Color> c;  // (order + 1)^2 coefficients
};

}  // namespace

class RadCache final : public Integrator {
public:
    explicit RadCache(ParamReader& p)
        : max_depth_(p.get_int("max_depth")),
          hsh_(p.get_int("order")),
          res_(p.get_int("gather_resolution")),
          kappa_(p.get_float("kappa")),
          adjust_(p.get_float("quality_adjustment")),
          lookup_samples_(p.get_int("lookup_samples")),
          max_lobe_pdf_(p.get_float("max_lobe_pdf")),
          min_spacing_(p.get_float("min_spacing")),
          max_spacing_(p.get_float("max_spacing")),
          overture_(p.get_bool("overture")),
          paths_(max_depth_, p.get_int("rr_depth"), p.get_bool("hide_emitters")) {
        CachePaths::check_spacing(p, min_spacing_, max_spacing_);
        n_phi_ = std::max(1, int(std::lround(kPi * float(res_))));
    }

    void sample(const Scene&, Sampler&, const Ray&, EffectRadiance&, ThreadStats&) const override {
        throw std::logic_error("integrator 'radcache' renders through its own driver");
    }
    RenderOutput drive(const Scene& scene, const RenderOptions& opts, const PollFn& poll) const override;

    void radiance(const Scene& scene, Sampler& sampler, const Ray& ray, EffectRadiance& out, ThreadStats& stats) const {
        Interaction it;
        auto can = [&](const Interaction& x) { return cacheable(scene, x); };
        if (!paths_.camera(scene, sampler, ray, mask, can, it, out, stats)) return;
        cstats_.lookups.fetch_add(1, std::memory_order_relaxed);
        thread_local std::vector<std::pair<int, float>> found;
        covering(it, adjust_, found);
        // The records' coefficients averaged with their weights (read in x's
        // frame: no rotation; the weight keeps their normals within 10
        // degrees / kappa of x's), or x's own record on a miss.
        thread_local RadRecord own;
        if (found.empty()) {
            cstats_.misses.fetch_add(1, std::memory_order_relaxed);
            gather(scene, sampler, it, stats, own);
        } else {
            // A Lambertian x reads only the l <= 1, m = 0 coefficients (below).
            const bool diffuse = scene.bsdfs[scene.shapes[it.shape]->bsdf]->flags() == kDiffuseReflection;
            const size_t used = diffuse ? std::min<size_t>(3, size_t(hsh_.count())) : size_t(hsh_.count());
            own.c.assign(size_t(hsh_.count()), Color(0.f));
            float wsum = 0.f;
            for (const auto& fw : found) {
                const std::vector<Color>& c = records_[size_t(fw.first)].c;
                for (size_t i = 0; i < used; ++i) own.c[i] += c[i] * fw.second;
                wsum += fw.second;
            }
            for (size_t i = 0; i < used; ++i) own.c[i] /= wsum;
        }
        own.f = it.sh;
        const Bsdf& bsdf = *scene.bsdfs[scene.shapes[it.shape]->bsdf];
        BsdfContext ctx;
        ctx.set(it);
        Vec3 wi = it.to_local(it.wi);
        if (bsdf.flags() == kDiffuseReflection) {
            // Lambertian: f times the irradiance of the reconstruction, in
            // closed form (int cos H_lm dw vanishes but for l <= 1, m = 0).
            Color e = own.c[0] * cos_h00_;
            if (hsh_.count() > 1) e += own.c[2] * cos_h10_;
            e = Color(std::max(e.x, 0.f), std::max(e.y, 0.f), std::max(e.z, 0.f));
            out.add(kIndirect, bsdf.eval(ctx, wi, Vec3(0.f, 0.f, 1.f)) * e);
            return;
        }
        // The reconstruction integrated against x's BSDF by BSDF sampling.
        thread_local std::vector<float> basis;
        basis.resize(size_t(hsh_.count()));
        Color lo(0.f);
        for (int s = 0; s < lookup_samples_; ++s) {
            BsdfSample bs = bsdf.sample(ctx, wi, sampler.next_1d(), sampler.next_2d());
            if (!(bs.pdf_w > 0.f) || is_black(bs.weight) || bs.is_delta) continue;
            lo += bs.weight * reconstruct(own, it.to_world(bs.wo), basis);
        }
        // Clamped only here (a clamp per direction would turn the
        // reconstruction's noise into a positive bias: +5 % at order 1, 6 x
        // 19 gather rays, measured on the Cornell box).
        lo /= float(lookup_samples_);
        out.add(kIndirect, Color(std::max(lo.x, 0.f), std::max(lo.y, 0.f), std::max(lo.z, 0.f)));
    }

private:
    bool cacheable(const Scene& scene, const Interaction& it) const {
        if (!paths_.indirect_possible()) return false;
        const Bsdf& b = *scene.bsdfs[scene.shapes[it.shape]->bsdf];
        Vec3 wi = it.to_local(it.wi);
        if (!b.has_smooth() || (b.flags() & (kDelta | kTransmission)) || !(wi.z > 0.f) ||
            scene.shapes[it.shape]->dipole >= 0)
            return false;
        if (max_lobe_pdf_ <= 0.f) return true;
        BsdfContext ctx;
        ctx.set(it);
        return b.pdf_w(ctx, wi, Vec3(-wi.x, -wi.y, wi.z)) <= max_lobe_pdf_;
    }

    Color reconstruct(const RadRecord& rec, const Vec3& d, std::vector<float>& basis) const {
        Vec3 w = rec.f.to_local(d);
        if (!(w.z > 0.f)) return Color(0.f);
        hsh_.eval(w, basis.data());
        Color v(0.f);
        for (int i = 0; i < hsh_.count(); ++i) v += rec.c[size_t(i)] * basis[size_t(i)];
        return v;
    }

    // The stratified gather and its projection (file's first comment).
    void gather(const Scene& scene, Sampler& sampler, const Interaction& x, ThreadStats& stats, RadRecord& rec) const {
        const int M = res_, N = n_phi_, K = hsh_.count();
        thread_local std::vector<float> basis;
        basis.resize(size_t(K));
        rec.c.assign(size_t(K), Color(0.f));
        float rmin = kInf;
        const float dw = 2.f * kPi / float(M * N);
        for (int j = 0; j < M; ++j)
            for (int k = 0; k < N; ++k) {
                Vec2 u = sampler.next_2d();
                float ct = 1.f - (float(j) + u.x) / float(M), st = std::sqrt(std::max(0.f, 1.f - ct * ct));
                float phi = 2.f * kPi * (float(k) + u.y) / float(N);
                Vec3 wl(st * std::cos(phi), st * std::sin(phi), ct);
                float dist;
                Color L = paths_.gather_radiance(scene, sampler, x, x.to_world(wl), dist, stats);
                if (!is_finite(L)) L = Color(0.f);
                if (dist < kInf && ct > 0.173f) rmin = std::min(rmin, dist);  // 10 degrees above the tangent plane
                if (is_black(L)) continue;
                hsh_.eval(wl, basis.data());
                for (int i = 0; i < K; ++i) rec.c[size_t(i)] += L * (basis[size_t(i)] * dw);
            }
        rec.p = x.p;
        rec.f = x.sh;
        rec.r = std::min(std::max(rmin, r_min_), r_max_);
    }

    float weight(const RadRecord& rec, const Vec3& p, const Vec3& n, float adjust) const {
        Vec3 dp = p - rec.p;
        if (dot(dp, n + rec.f.n) * 0.5f < -1e-3f * rec.r) return 0.f;  // in front of x
        float nd = std::sqrt(std::max(0.f, 1.f - dot(n, rec.f.n)));
        return 1.f - kappa_ * adjust * std::max(2.f * length(dp) / rec.r, nd / kSqrtOneMinusCos10);
    }
    void covering(const Interaction& it, float adjust, std::vector<std::pair<int, float>>& found) const {
        found.clear();
        octree_.lookup(it.p, [&](int i) {
            float w = weight(records_[size_t(i)], it.p, it.sh.n, adjust);
            if (w > 0.f) found.push_back({i, w});
        });
    }
    float reach(float r) const { return r / (2.f * kappa_ * adjust_); }

    bool overture(PassLoop& loop) const {
        std::vector<RadRecord> batch(kOvertureBatch);
        thread_local std::vector<std::pair<int, float>> found;
        return run_overture(
            loop, cstats_,
            [&](const Interaction& it) {
                if (!cacheable(loop.scene(), it)) return false;
                covering(it, 1.f, found);
                return found.empty();
            },
            [&](size_t i, const Interaction& it, Sampler& rs, ThreadStats& stats) {
                gather(loop.scene(), rs, it, stats, batch[i]);
            },
            [&](size_t i) {
                records_.push_back(std::move(batch[i]));
                octree_.insert(int(records_.size()) - 1, records_.back().p, reach(records_.back().r));
            });
    }

    int max_depth_;
    Hsh hsh_;
    int res_, n_phi_ = 1;
    float kappa_, adjust_;
    int lookup_samples_;
    float max_lobe_pdf_;
    // int cos(theta) H_l0 dw over the hemisphere for l = 0, 1: with
    // x = 2 cos(theta) - 1, pi / sqrt(2) K_l0 int_{-1}^{1} (x + 1) P_l(x) dx,
    // K_00 = 1 / sqrt(4 pi), K_10 = sqrt(3 / (4 pi)).
    const float cos_h00_ = float(std::sqrt(2.0) * kPi / std::sqrt(4.0 * kPi));
    const float cos_h10_ = float(kPi / std::sqrt(2.0) * std::sqrt(3.0 / (4.0 * kPi)) * (2.0 / 3.0));
    float min_spacing_, max_spacing_;
    bool overture_;
    CachePaths paths_;
    // The cache of one render (drive() fills it; the camera passes only read it).
    mutable std::vector<RadRecord> records_;
    mutable RecordOctree octree_;
    mutable float r_min_ = 0.f, r_max_ = kInf;
    mutable CacheStats cstats_;
};

RenderOutput RadCache::drive(const Scene& scene, const RenderOptions& opts, const PollFn& poll) const {
    paths_.set_masks(mask);
    auto reset = [&](const Vec3& center, float radius) {
        records_.clear();
        octree_.reset(center, radius * 1.01f + 1e-4f);
        r_min_ = min_spacing_ * radius;
        r_max_ = max_spacing_ * radius;
    };
    RenderOutput out = drive_cache(*this, scene, opts, poll, cstats_, overture_ && mask[kIndirect], reset,
                                   [&](PassLoop& loop) { return overture(loop); });
    OutputArray rec;
    rec.name = "radcache_records";
    rec.columns = {"x", "y", "z", "nx", "ny", "nz", "radius"};
    for (const RadRecord& r : records_)
        for (float v : {r.p.x, r.p.y, r.p.z, r.f.n.x, r.f.n.y, r.f.n.z, r.r}) rec.data.push_back(v);
    rec.shape = {int(rec.data.size() / rec.columns.size()), int(rec.columns.size())};
    out.arrays.push_back(std::move(rec));
    out.estimator_stats.push_back({"radcache_candidates", {double(cstats_.candidates)}});
    out.estimator_stats.push_back({"radcache_computed", {double(cstats_.computed)}});
    out.estimator_stats.push_back({"radcache_lookups", {double(cstats_.lookups.load())}});
    out.estimator_stats.push_back({"radcache_misses", {double(cstats_.misses.load())}});
    out.estimator_stats.push_back({"radcache_overture_seconds", {cstats_.overture_seconds}});
    out.estimator_stats.push_back({"radcache_coefficients", {double(hsh_.count())}});
    return out;
}

namespace {

std::unique_ptr<Integrator> make_radcache(ParamReader& p) { return std::make_unique<RadCache>(p); }

}  // namespace

}  // namespace rm
