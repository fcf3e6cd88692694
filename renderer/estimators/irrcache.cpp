// `irrcache`: irradiance caching (Ward, Rubinstein and Clear 1988, "A Ray
// Tracing Solution for Diffuse Interreflection"): indirect diffuse
// irradiance is computed at sparse records by stratified final gathering
// and interpolated between them; everything else is path traced.
//
// What comes from where, at the first vertex x of a camera path when x is
// Lambertian (DESIGN section 3's classes, camera side):
//   emission, direct (L D E), caustic (L D S+ E... seen as L S+ D E) and
//   specular (anything seen through a delta vertex first): the `path`
//   estimator itself, run with the indirect class masked out (its
//   PathClass stops the path at the second smooth vertex), so these classes
//   stay exact (unbiased);
//   indirect (L ... D D E): f(x) E_c(x), E_c the irradiance at x carried by
//   light that scattered at a smooth vertex after x, interpolated from the
//   cache. At a first vertex that is not Lambertian (glossy, mixed lobes,
//   index-matched boundaries) the whole path is path traced.
// A record at x holds E_c by M x N stratified cosine-weighted gather rays
// (Ward and Heckbert 1992, sec. 2: M = gather_resolution polar strata,
// N = round(pi M) azimuthal ones). Each gather ray follows delta vertices
// to its first smooth vertex y and takes `path`'s estimate of the radiance
// y reflects towards x (emission at y and light reaching x through delta
// vertices only are excluded: they are direct and caustic light at x).
// Gradients (Ward and Heckbert 1992; the forms of Krivanek and Gautron
// 2009, "Practical Global Illumination with Irradiance Caching", ch. 5,
// derived there after Krivanek et al. 2005, "Radiance caching for
// efficient global illumination computation"):
//   rotational     grad_r E = pi / (M N) sum_k v_k sum_j tan(theta_j) L_jk,
//                  v_k = (-sin phi_k, cos phi_k, 0);
//   translational  per boundary between cells, the radiance difference
//                  times the rate at which the projected solid angle of the
//                  cell moves when x moves, the nearer of the two cells'
//                  hit distances setting that rate:
//                  polar walls  2 pi cos^2 theta_- sin theta_- / (N r) along u_k,
//                  azimuthal    cos theta_c (cos theta_- - cos theta_+) / (sin theta_c r) along v_k-.
// Weights (the record valid where w > 0, E(x) = sum w_i E_i(x) / sum w_i):
//   tabellion  Tabellion and Lamorlette 2004, "An Approximate Global
//              Illumination System for Computer Generated Films":
//              w = 1 - kappa max(2 |x - x_i| / R_i, sqrt(1 - n.n_i) / sqrt(1 - cos 10 deg)),
//              R_i the smallest hit distance of the gather rays at least
//              10 degrees above the tangent plane;
//   ward       Ward et al. 1988: w = 1 / (|x - x_i| / R_i + sqrt(1 - n.n_i)),
//              valid where w > 1 / ward_a, R_i the harmonic mean hit distance.
// Records "in front of" x (Ward et al. 1988: (x - x_i).(n + n_i)/2 < 0) are
// skipped. R_i is limited by E / |grad_t E| when gradients are on
// (Krivanek and Gautron 2009, ch. 5), by neighbour clamping (Krivanek et
// al. 2006, "Making radiance and irradiance caching practical: adaptive
// caching and neighbor clamping": R_i <= R_j + |x_i - x_j| both ways for
// overlapping records), and clamped to [min_spacing, max_spacing] times
// the radius of the scene's bounding sphere.
//
// Determinism: the cache is filled before the camera passes by an
// overture over a fixed set of record candidates (the first hit of one
// camera ray per pixel, in coarse-to-fine pixel grids, strides 16 .. 1),
// in batches of a fixed size: within a batch each candidate not covered by
// the cache so far computes its record on its own random stream (in
// parallel), then the batch's records are inserted in candidate order. The
// camera passes only read the cache (with the weights relaxed by
// quality_adjustment, as Mitsuba 0.6's irrcache relaxes kappa after its
// overture); a point no record covers gets a record of its own, computed
// from the camera sample's stream and not stored (res.stats counts them).
// So a seed fixes the bytes whatever the thread count. overture = false
// leaves the cache empty: every camera sample then gathers its own
// irradiance, an unbiased estimate (final gathering without caching).
//
// The record index: cache_common.h's loose octree (why our own: there).
//
// Bias: biased (interpolation error that more samples per pixel do not
// remove; it falls as the records get denser, kappa up). Measured in
// docs/irrcache.md and tests/test_irrcache.py. Records (position, normal,
// radius) come back in res.arrays["irrcache_records"].
#include <atomic>
#include <cmath>
#include <memory>
#include <stdexcept>

#include "estimators/cache_common.h"
#include "render/pass_loop.h"
#include "render/registry.h"
#include "transport/camera_sample.h"
#include "transport/common.h"

namespace rm {

namespace {

std::unique_ptr<Integrator> make_irrcache(ParamReader& p);

[[maybe_unused]] const bool kRegistered = register_estimator([] {
    EstimatorInfo e;
    e.name = "irrcache";
    e.doc =
        "irradiance caching (Ward et al. 1988) with gradients (Ward and Heckbert 1992) and neighbour clamping "
        "(Krivanek et al. 2006): indirect diffuse light interpolated, the rest path traced";
    e.params = {
        max_depth_param(),
        rr_depth_param(),
        hide_emitters_param(),
        ParamSpec::integer("gather_resolution", 8,
                           "polar strata M of a record's final gather (M x round(pi M) rays; Mitsuba's resolution)")
            .at_least(1)
            .at_most(256)
            .alias("resolution"),
        ParamSpec::string("weight", "tabellion", "interpolation weight: Tabellion and Lamorlette 2004, or Ward 1988")
            .one_of({"tabellion", "ward"}),
        ParamSpec::real("kappa", 1.0, "Tabellion's kappa: larger means denser records (Mitsuba's quality)")
            .greater_than(0)
            .alias("quality"),
        ParamSpec::real("ward_a", 0.2, "Ward's error bound a (weight 'ward'): smaller means denser records")
            .greater_than(0),
        ParamSpec::real("quality_adjustment", 0.5,
                        "kappa (or 1 / a) of the camera passes' lookups relative to the overture's")
            .greater_than(0)
            .at_most(1),
        ParamSpec::boolean("gradients", true, "translational and rotational irradiance gradients"),
        ParamSpec::boolean("neighbour_clamping", true, "neighbour clamping of record radii (Krivanek et al. 2006)")
            .alias("clamp_neighbor")
            .alias("clampNeighbor"),
        ParamSpec::real("min_spacing", 0.005, "smallest record radius, relative to the scene's bounding sphere")
            .at_least(0),
        ParamSpec::real("max_spacing", 0.25, "largest record radius, relative to the scene's bounding sphere")
            .greater_than(0),
        ParamSpec::boolean("overture", true,
                           "fill the cache before the camera passes (false: no cache, every sample gathers)"),
    };
    e.caps.driver = Driver::OwnPasses;
    e.caps.bias = Bias::Biased;
    e.factory = make_irrcache;
    return e;
}());

const float kSqrtOneMinusCos10 = std::sqrt(1.f - std::cos(10.f * kPi / 180.f));

struct Record {
    Vec3 p, n;
    Color e;
    float r = 0.f;      // validity radius (clamped)
    float r_raw = 0.f;  // before the min/max clamp (what neighbour clamping compares)
    Color tgrad[3];     // d E / d x_a, a = world axis
    Color rgrad[3];     // rotational gradient, per world axis
};

}  // namespace

class IrrCache final : public Integrator {
public:
    explicit IrrCache(ParamReader& p)
        : max_depth_(p.get_int("max_depth")),
          res_(p.get_int("gather_resolution")),
          ward_(p.get_string("weight") == "ward"),
          kappa_(p.get_float("kappa")),
          ward_a_(p.get_float("ward_a")),
          adjust_(p.get_float("quality_adjustment")),
          gradients_(p.get_bool("gradients")),
          clamp_(p.get_bool("neighbour_clamping")),
          min_spacing_(p.get_float("min_spacing")),
          max_spacing_(p.get_float("max_spacing")),
          overture_(p.get_bool("overture")),
          paths_(max_depth_, p.get_int("rr_depth"), p.get_bool("hide_emitters")) {
        CachePaths::check_spacing(p, min_spacing_, max_spacing_);
        n_phi_ = std::max(1, int(std::lround(kPi * float(res_))));
    }

    void sample(const Scene&, Sampler&, const Ray&, EffectRadiance&, ThreadStats&) const override {
        throw std::logic_error("integrator 'irrcache' renders through its own driver");
    }
    RenderOutput drive(const Scene& scene, const RenderOptions& opts, const PollFn& poll) const override;

    // The camera passes' radiance along one camera ray (the file's first comment).
    void radiance(const Scene& scene, Sampler& sampler, const Ray& ray, EffectRadiance& out, ThreadStats& stats) const {
        Interaction it;
        auto can = [&](const Interaction& x) { return cacheable(scene, x); };
        if (!paths_.camera(scene, sampler, ray, mask, can, it, out, stats)) return;
        Color e;
        cstats_.lookups.fetch_add(1, std::memory_order_relaxed);
        if (!interpolate(it, adjust_, e)) {
            cstats_.misses.fetch_add(1, std::memory_order_relaxed);
            Record rec;
            gather(scene, sampler, it, stats, rec);
            e = rec.e;
        }
        out.add(kIndirect, albedo_over_pi(scene, it) * e);
    }

private:
    // x takes its indirect light from the cache: a Lambertian surface seen
    // from its front, and paths of 3 segments allowed.
    bool cacheable(const Scene& scene, const Interaction& it) const {
        if (!paths_.indirect_possible()) return false;
        const Bsdf& b = *scene.bsdfs[scene.shapes[it.shape]->bsdf];
        return b.flags() == kDiffuseReflection && it.to_local(it.wi).z > 0.f && scene.shapes[it.shape]->dipole < 0;
    }
    static Color albedo_over_pi(const Scene& scene, const Interaction& it) {
        const Bsdf& b = *scene.bsdfs[scene.shapes[it.shape]->bsdf];
        BsdfContext ctx;
        ctx.set(it);
        return b.eval(ctx, it.to_local(it.wi), Vec3(0.f, 0.f, 1.f));  // f |cos| at the normal: rho / pi
    }

    // A record at x: M x N stratified cosine-weighted gather rays, the
    // irradiance, its gradients and radius (the file's first comment).
    void gather(const Scene& scene, Sampler& sampler, const Interaction& x, ThreadStats& stats, Record& rec) const {
        const int M = res_, N = n_phi_;
        thread_local std::vector<Color> L;
        thread_local std::vector<float> r;
        L.assign(size_t(M) * size_t(N), Color(0.f));
        r.assign(size_t(M) * size_t(N), kInf);
        for (int j = 0; j < M; ++j)
            for (int k = 0; k < N; ++k) {
                Vec2 u = sampler.next_2d();
                float s2 = (float(j) + u.x) / float(M);
                float ct = std::sqrt(std::max(0.f, 1.f - s2)), st = std::sqrt(s2);
                float phi = 2.f * kPi * (float(k) + u.y) / float(N);
                Vec3 d = x.to_world(Vec3(st * std::cos(phi), st * std::sin(phi), ct));
                size_t i = size_t(j) * size_t(N) + size_t(k);
                L[i] = paths_.gather_radiance(scene, sampler, x, d, r[i], stats);
                if (!is_finite(L[i])) L[i] = Color(0.f);
            }
        Color e(0.f);
        Vec3 gt_local[3], gr_local[3];  // per channel, local frame
        float inv_sum = 0.f, rmin = kInf;
        for (int j = 0; j < M; ++j) {
            float ctm = std::sqrt(1.f - float(j) / float(M)), stm = std::sqrt(float(j) / float(M));
            float ctc = std::sqrt(1.f - (float(j) + 0.5f) / float(M)), stc = std::sqrt((float(j) + 0.5f) / float(M));
            float ctp = std::sqrt(std::max(0.f, 1.f - float(j + 1) / float(M)));
            float tanc = stc / ctc;
            for (int k = 0; k < N; ++k) {
                size_t i = size_t(j) * size_t(N) + size_t(k);
                float phic = 2.f * kPi * (float(k) + 0.5f) / float(N), phim = 2.f * kPi * float(k) / float(N);
                Vec3 uk(std::cos(phic), std::sin(phic), 0.f), vk(-std::sin(phic), std::cos(phic), 0.f);
                Vec3 vkm(-std::sin(phim), std::cos(phim), 0.f);
                e += L[i];
                for (int ch = 0; ch < 3; ++ch) gr_local[ch] += vk * (tanc * L[i][ch]);
                if (j >= 1) {  // the wall between rings j - 1 and j
                    size_t o = size_t(j - 1) * size_t(N) + size_t(k);
                    float rm = std::min(r[i], r[o]);
                    if (rm < kInf && rm > 0.f) {
                        float f = 2.f * kPi * ctm * ctm * stm / (float(N) * rm);
                        for (int ch = 0; ch < 3; ++ch) gt_local[ch] += uk * (f * (L[i][ch] - L[o][ch]));
                    }
                }
                if (N > 1) {  // the wall between sectors k - 1 and k
                    size_t o = size_t(j) * size_t(N) + size_t((k + N - 1) % N);
                    float rm = std::min(r[i], r[o]);
                    if (rm < kInf && rm > 0.f) {
                        float f = ctc * (ctm - ctp) / (stc * rm);
                        for (int ch = 0; ch < 3; ++ch) gt_local[ch] += vkm * (f * (L[i][ch] - L[o][ch]));
                    }
                }
                if (r[i] < kInf && r[i] > 0.f) {
                    inv_sum += 1.f / r[i];
                    if (ctc > 0.173f) rmin = std::min(rmin, r[i]);  // at least 10 degrees above the tangent plane
                }
            }
        }
        const float norm = kPi / float(M * N);
        rec.p = x.p;
        rec.n = x.sh.n;
        rec.e = e * norm;
        for (int a = 0; a < 3; ++a) {
            rec.tgrad[a] = Color(0.f);
            rec.rgrad[a] = Color(0.f);
        }
        for (int ch = 0; ch < 3; ++ch) {
            Vec3 gt = x.to_world(gt_local[ch]), gr = x.to_world(gr_local[ch] * norm);
            for (int a = 0; a < 3; ++a) {
                rec.tgrad[a][ch] = gt[a];
                rec.rgrad[a][ch] = gr[a];
            }
        }
        float radius = ward_ ? (inv_sum > 0.f ? float(M * N) / inv_sum : kInf) : rmin;
        if (gradients_)
            for (int ch = 0; ch < 3; ++ch) {
                float g = length(Vec3(rec.tgrad[0][ch], rec.tgrad[1][ch], rec.tgrad[2][ch]));
                if (g > 0.f) radius = std::min(radius, rec.e[ch] / g);
            }
        rec.r_raw = radius;
        rec.r = clamp_radius(radius);
    }

    float clamp_radius(float r) const { return std::min(std::max(r, r_min_), r_max_); }
    // The farthest a record of radius r can be used (lookups relaxed by
    // quality_adjustment).
    float reach(float r) const { return ward_ ? r * ward_a_ / adjust_ : r / (2.f * kappa_ * adjust_); }

    // The weight of record `rec` at (p, n); <= 0: not used. `adjust`:
    // 1 in the overture, quality_adjustment in the camera passes.
    float weight(const Record& rec, const Vec3& p, const Vec3& n, float adjust) const {
        Vec3 dp = p - rec.p;
        float dist = length(dp);
        if (dot(dp, n + rec.n) * 0.5f < -1e-3f * rec.r) return 0.f;  // in front of x
        float nd = std::sqrt(std::max(0.f, 1.f - dot(n, rec.n)));
        if (ward_) {
            float a = ward_a_ / adjust;
            float den = dist / rec.r + nd;
            if (!(den < a)) return 0.f;
            return 1.f / std::max(den, 1e-6f);
        }
        return 1.f - kappa_ * adjust * std::max(2.f * dist / rec.r, nd / kSqrtOneMinusCos10);
    }

    // The cache's irradiance at `it`, false when no record covers it.
    bool interpolate(const Interaction& it, float adjust, Color& e) const {
        float wsum = 0.f;
        Color sum(0.f);
        const Vec3 n = it.sh.n;
        octree_.lookup(it.p, [&](int i) {
            const Record& rec = records_[size_t(i)];
            float w = weight(rec, it.p, n, adjust);
            if (!(w > 0.f)) return;
            Color v = rec.e;
            if (gradients_) {
                Vec3 dp = it.p - rec.p, cn = cross(rec.n, n);
                for (int a = 0; a < 3; ++a) v += rec.tgrad[a] * dp[a] + rec.rgrad[a] * cn[a];
                v = Color(std::max(v.x, 0.f), std::max(v.y, 0.f), std::max(v.z, 0.f));
            }
            sum += v * w;
            wsum += w;
        });
        if (!(wsum > 0.f)) return false;
        e = sum / wsum;
        return true;
    }

    // Adds a record in the overture's order, with neighbour clamping.
    void insert(Record rec) const {
        const int idx = int(records_.size());
        if (clamp_) {
            // R_i <= R_j + |x_i - x_j| over the records that reach x_i, then
            // the same bound on the records within x_i's reach.
            octree_.lookup(rec.p, [&](int j) {
                const Record& o = records_[size_t(j)];
                float d = length(rec.p - o.p);
                if (d < reach(o.r)) rec.r_raw = std::min(rec.r_raw, o.r_raw + d);
            });
            rec.r = clamp_radius(rec.r_raw);
            float rr = reach(rec.r);
            octree_.query_sphere(rec.p, rr, [&](int j) {
                Record& o = records_[size_t(j)];
                float d = length(rec.p - o.p);
                if (d < rr && o.r_raw > rec.r_raw + d) {
                    o.r_raw = rec.r_raw + d;
                    o.r = clamp_radius(o.r_raw);
                }
            });
        }
        records_.push_back(rec);
        octree_.insert(idx, rec.p, reach(rec.r));
    }

    bool overture(PassLoop& loop) const;
    void finish_stats(RenderOutput& out) const;

    int max_depth_, res_, n_phi_ = 1;
    bool ward_;
    float kappa_, ward_a_, adjust_;
    bool gradients_, clamp_;
    float min_spacing_, max_spacing_;
    bool overture_;
    CachePaths paths_;
    // The cache of one render (drive() fills it before the camera passes,
    // which only read it; one render at a time per integrator object).
    mutable std::vector<Record> records_;
    mutable RecordOctree octree_;
    mutable float r_min_ = 0.f, r_max_ = kInf;
    mutable CacheStats cstats_;
};

bool IrrCache::overture(PassLoop& loop) const {
    std::vector<Record> batch(kOvertureBatch);
    return run_overture(
        loop, cstats_,
        [&](const Interaction& it) {
            Color e;
            return cacheable(loop.scene(), it) && !interpolate(it, 1.f, e);
        },
        [&](size_t i, const Interaction& it, Sampler& rs, ThreadStats& stats) {
            gather(loop.scene(), rs, it, stats, batch[i]);
        },
        [&](size_t i) { insert(batch[i]); });
}

void IrrCache::finish_stats(RenderOutput& out) const {
    const size_t n = records_.size();
    OutputArray rec;
    rec.name = "irrcache_records";
    rec.columns = {"x", "y", "z", "nx", "ny", "nz", "radius", "E_r", "E_g", "E_b"};
    rec.data.reserve(n * rec.columns.size());
    for (const Record& r : records_)
        for (float v : {r.p.x, r.p.y, r.p.z, r.n.x, r.n.y, r.n.z, r.r, r.e.x, r.e.y, r.e.z}) rec.data.push_back(v);
    rec.shape = {int(rec.data.size() / rec.columns.size()), int(rec.columns.size())};
    out.arrays.push_back(std::move(rec));
    out.estimator_stats.push_back({"irrcache_candidates", {double(cstats_.candidates)}});
    out.estimator_stats.push_back({"irrcache_computed", {double(cstats_.computed)}});
    out.estimator_stats.push_back({"irrcache_lookups", {double(cstats_.lookups.load())}});
    out.estimator_stats.push_back({"irrcache_misses", {double(cstats_.misses.load())}});
    out.estimator_stats.push_back({"irrcache_overture_seconds", {cstats_.overture_seconds}});
    out.estimator_stats.push_back({"irrcache_gather_rays", {double(res_ * n_phi_)}});
}

RenderOutput IrrCache::drive(const Scene& scene, const RenderOptions& opts, const PollFn& poll) const {
    paths_.set_masks(mask);
    auto reset = [&](const Vec3& center, float radius) {
        records_.clear();
        octree_.reset(center, radius * 1.01f + 1e-4f);
        r_min_ = min_spacing_ * radius;
        r_max_ = max_spacing_ * radius;
    };
    RenderOutput out = drive_cache(*this, scene, opts, poll, cstats_, overture_ && mask[kIndirect], reset,
                                   [&](PassLoop& loop) { return overture(loop); });
    finish_stats(out);
    return out;
}

namespace {

std::unique_ptr<Integrator> make_irrcache(ParamReader& p) { return std::make_unique<IrrCache>(p); }

}  // namespace

}  // namespace rm
