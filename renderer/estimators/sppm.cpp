// `sppm`: stochastic progressive photon mapping (Hachisuka & Jensen 2009,
// "Stochastic Progressive Photon Mapping"; the radius reduction of Hachisuka,
// Ogaki & Jensen 2008, "Progressive Photon Mapping"). Each pass (one sample
// per pixel):
//   1. a camera ray per pixel (filter importance sampled: camera_sample.h)
//      follows specular vertices to its first non-specular vertex x, the
//      pass's visible point; emission on the way and direct light at x
//      (one light sample, next event estimation) are added as in `path`;
//   2. photon_count light paths leave photons at their non-specular vertices
//      after the first (direct light came from step 1) -- photon_trace.h;
//   3. each pixel gathers the M photons within its radius r of x, Phi =
//      beta sum f_r Phi_p, and updates its statistics (H&J 2009, eqs. 6-8;
//      HOJ 2008, eqs. 6, 7 and 11):
//        N' = N + alpha M,   r'^2 = r^2 (N + alpha M) / (N + M),
//        tau' = (tau + Phi) (N + alpha M) / (N + M);
//   the pixel's photon-mapped radiance after i passes of n photon paths is
//   tau / (pi r^2 i n) (H&J 2009, eq. 10): consistent, bias and variance both
//   vanish as the passes grow, for 0 < alpha < 1.
// Determinism: pixel p's camera sample of pass s draws on Sampler(seed, p, s)
// and photon path g of pass s on its own stream (photon_trace.h); each
// pixel's gather sums in the photon map's fixed order.
// Variance (res.variance): the sample variance over passes of each pass's
// own estimate (direct part + Phi / (pi r_i^2 n)) divided by the pass
// count, i.e. the passes treated as independent estimates as Knaus & Zwicker
// 2011 ("Progressive Photon Mapping: A Probabilistic Approach") do; it does
// not see the bias.
// Radius bias (res.error_budget's discretisation term): each pass also
// counts the photons within r / sqrt(2) of x; with Phi_h their sum, the
// pass's estimate at the half-area disc is Phi_h / (pi r^2 / 2). A disc
// average of a radiance smooth at x is biased by c r^2 + O(r^4) (the
// Laplacian term of the disc mean's Taylor series), so the difference
// Phi / (pi r^2) - Phi_h / (pi r^2 / 2) has expectation c r^2 / 2 and twice
// it estimates the pass's bias at r (Richardson extrapolation in r^2). The
// progressive estimate is close to the mean of the passes' own estimates
// (Knaus & Zwicker 2011), so the mean over passes of these estimates is its
// bias estimate, per pixel (res.arrays["radius_bias"]) and for the image
// mean with its standard error over the passes (independent: each has its
// own camera samples and photons): estimator stats radius_bias_sum /
// radius_bias_sq_sum (per channel, sums over passes of the pass's image
// mean) and radius_bias_passes. It is wrong where the radiance is not
// smooth within r (an edge: bias of order r, not r^2).
// Effect classes: emission and direct as in `path`; photons whose light path
// was specular-only before x are `caustic`, the others `indirect`; all of x's
// light is `specular` when the camera reached x through a specular vertex.
// Limits: the visible point is the first non-specular vertex, so the
// specular lobe of a mixed BSDF (plastic's coat) there is not followed
// (pbrt-v3's SPPM shares this); glossy visible points gather photons like
// diffuse ones (their sharp highlights converge slowly).
//
// Parameters: the registration below (Mitsuba 0.6's sppm names in snake_case,
// its camelCase ones as aliases). The pass count is the spp.
#include <chrono>
#include <limits>
#include <stdexcept>
#include <thread>

#include "render/memory.h"
#include "render/pass_loop.h"
#include "render/registry.h"
#include "transport/camera_sample.h"
#include "transport/common.h"
#include "transport/photon_trace.h"

namespace rm {

namespace {

std::unique_ptr<Integrator> make_sppm(ParamReader& p);

[[maybe_unused]] const bool kRegistered = register_estimator([] {
    EstimatorInfo e;
    e.name = "sppm";
    e.doc =
        "stochastic progressive photon mapping: one camera pass and one photon pass per spp, shrinking "
        "radii (Hachisuka & Jensen 2009)";
    e.params = {
        max_depth_param().alias("maxDepth"),
        rr_depth_param().alias("rrDepth"),
        hide_emitters_param().alias("hideEmitters"),
        ParamSpec::integer("photon_count", 250000, "light paths traced per pass").at_least(1).alias("photonCount"),
        ParamSpec::real("initial_radius", 0.0,
                        "initial gather radius in world units (automatic: 1/100 of the scene's bounding-sphere "
                        "radius)")
            .at_least(0)
            .with_special(0.0, "automatic")
            .alias("initialRadius"),
        ParamSpec::real("alpha", 0.7, "radius reduction (Hachisuka, Ogaki & Jensen 2008, eq. 7)")
            .greater_than(0)
            .less_than(1),
        ParamSpec::mitsuba_ignored("granularity", "Mitsuba's work-unit size: changes nothing here"),
    };
    e.caps.driver = Driver::OwnPasses;
    e.caps.bias = Bias::Consistent;
    e.factory = make_sppm;
    return e;
}());

using Clock = std::chrono::steady_clock;
double since(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }

// The photon-mapped classes a pixel's tau is split into.
constexpr int kTauClasses[3] = {kCaustic, kIndirect, kSpecular};

struct VisiblePoint {
    Interaction it;
    const Bsdf* bsdf = nullptr;  // null: no visible point this pass
    Vec3 wi;                     // local
    Color beta{0.f};
    EffectRadiance er;  // the pass's ray-traced part (emission, direct)
    bool via_specular = false;
    int c = 0;  // camera segments to x
};

struct PixelStats {
    double r2 = 0, n = 0;
    double tau[3][3] = {};               // [class][channel]
    double ray[kNumEffects][3] = {};     // sums of the ray-traced parts over passes
    double sum[3] = {}, sum_sq[3] = {};  // per-pass total estimates
    // The radius-bias estimate (top of file): per pass, twice the photon-
    // mapped estimate at r minus the one at r / sqrt(2), summed over passes.
    double bias[3] = {};
};

}  // namespace

class Sppm final : public Integrator {
public:
    explicit Sppm(ParamReader& p)
        : max_depth_(p.get_int("max_depth")),
          rr_depth_(p.get_int("rr_depth")),
          hide_(p.get_bool("hide_emitters")),
          photon_count_(p.get_int("photon_count")),
          initial_radius_(p.get_float("initial_radius")),
          alpha_(p.get_float("alpha")) {}
    void sample(const Scene&, Sampler&, const Ray&, EffectRadiance&, ThreadStats&) const override {
        throw std::logic_error("integrator 'sppm' renders through its own driver");
    }
    RenderOutput drive(const Scene& scene, const RenderOptions& opts, const PollFn& poll) const override;

private:
    class Passes;

    // Step 1: the camera path to its visible point; emission and direct light
    // along the way go to `out`.
    void camera_path(const Scene& scene, Sampler& sampler, Ray ray, EffectRadiance& out, VisiblePoint& vp,
                     ThreadStats& stats) const {
        walk_specular_chain(scene, sampler, ray, SpecularChain{max_depth_, rr_depth_, hide_}, mask, out, stats,
                            [&](const Interaction& it, const Bsdf& bsdf, const Vec3& wi, const Color& beta,
                                const PathClass& pc, int depth) {
                                if (!bsdf.has_smooth()) return true;
                                bool via_specular = pc.scatter_vertices > 0;
                                // Direct light by one light sample (no MIS partner: bsdf_frac 0).
                                int cls_d = via_specular ? kSpecular : kDirect;
                                if (mask[cls_d] && !scene.emitters.empty())
                                    out.add(cls_d,
                                            beta * estimate_direct(scene, it, bsdf, wi, sampler, stats, 1.f, 0.f));
                                vp.it = it;
                                vp.bsdf = &bsdf;
                                vp.wi = wi;
                                vp.beta = beta;
                                vp.via_specular = via_specular;
                                vp.c = depth + 1;
                                return false;
                            });
    }

    int max_depth_, rr_depth_;
    bool hide_;
    int photon_count_;
    float initial_radius_, alpha_;
};

// The passes of sppm on the pass loop: one pass of the loop's plan is
// steps 1-3 of the top of the file, once per sample index.
class Sppm::Passes final : public PassStep {
public:
    Passes(const Sppm& sppm, const Scene& scene) : sppm_(sppm), scene_(scene), filter_(make_filter(scene)) {
        const size_t pixels = size_t(scene.sensor->width) * size_t(scene.sensor->height);
        Vec3 center;
        float radius;
        scene.bounding_sphere(center, radius);
        const double r0 = sppm.initial_radius_ > 0.f ? sppm.initial_radius_ : 0.01 * radius;
        px_.resize(pixels);
        for (auto& p : px_) p.r2 = r0 * r0;
        vps_.resize(pixels);
        // Photons are needed when a photon-mapped class can appear at all.
        const SceneFeatures& f = scene.features;
        const EffectMask& mask = sppm.mask;
        const bool long_paths = sppm.max_depth_ < 0 || sppm.max_depth_ >= 3;
        photons_needed_ = !scene.emitters.empty() && f.has_smooth_bsdf && long_paths &&
                          (mask[kIndirect] || (f.has_delta_bsdf && (mask[kCaustic] || mask[kSpecular])));
        spec_.max_depth = sppm.max_depth_ < 0 ? -1 : sppm.max_depth_ - 1;
        spec_.rr_depth = sppm.rr_depth_;
        spec_.store_direct = false;
        spec_.stream = 3;
        pms_.name = "sppm";
        pms_.bytes_per_photon = double(PhotonMap::bytes_per_photon());
        // What the memory left beside the per-pixel buffers holds (memory.h).
        const double left = memory_limit_bytes() - double(pixels) * (sizeof(PixelStats) + sizeof(VisiblePoint));
        if (memory_limit_bytes() > 0) max_photons_ = left > 0 ? uint64_t(left / photon_map_build_bytes(1.0)) : 0;
    }

    int pass(PassLoop& loop, int s0, int s1) override {
        // Polled between sppm passes too: each of its parallel steps may
        // finish before run_parallel's first poll (parallel.h).
        PollGate gate(loop.poll_once());
        for (int s = s0; s < s1; ++s) {
            if (!gate()) return s;
            // 1. Camera pass: visible points, emission and direct light (kept
            //    in the visible points until step 3, so a cancel leaves the
            //    finished passes untouched).
            auto t0 = Clock::now();
            if (!loop.parallel_for(size_t(scene_.sensor->height),
                                   [&](size_t y, int t) { camera_row(loop, s, int(y), loop.stats(t)); }))
                return s;
            camera_seconds_ += since(t0);
            // 2. Photon pass: photon_count light paths into this pass's map
            //    (map_, whose arrays the previous pass's map leaves behind).
            if (photons_needed_ && !photon_pass(loop, s)) return s;
            // 3. Gather and update every pixel's statistics (never cancelled:
            //    a pass is either wholly in the estimate or not at all).
            auto tg = Clock::now();
            row_bias_.assign(3 * size_t(scene_.sensor->height), 0.0);
            loop.parallel_commit(size_t(scene_.sensor->height), [&](size_t y, int) { gather_row(map_, int(y)); });
            gather_seconds_ += since(tg);
            // The pass's radius-bias estimate of the image mean (rows summed
            // in order: the same whatever the thread count).
            for (int ch = 0; ch < 3; ++ch) {
                double t = 0;
                for (size_t y = 0; y < size_t(scene_.sensor->height); ++y) t += row_bias_[3 * y + ch];
                t /= double(px_.size());
                bias_sum_[ch] += t;
                bias_sq_[ch] += t * t;
            }
            ++bias_passes_;
        }
        return s1;
    }

    // The estimate after `n` passes (H&J 2009, eq. 10 plus the ray-traced part).
    void develop(int n, std::vector<float>& image, std::vector<float>& variance,
                 std::vector<std::vector<float>>* effects) const override {
        const size_t pixels = px_.size();
        image.assign(3 * pixels, 0.f);
        variance.assign(3 * pixels, std::numeric_limits<float>::quiet_NaN());
        if (effects) effects->assign(kNumEffects, std::vector<float>(3 * pixels, 0.f));
        if (n <= 0) return;
        for (size_t p = 0; p < pixels; ++p) {
            const PixelStats& s = px_[p];
            double e[kNumEffects][3];
            for (int k = 0; k < kNumEffects; ++k)
                for (int ch = 0; ch < 3; ++ch) e[k][ch] = s.ray[k][ch] / n;
            double norm = 1.0 / (kPi * s.r2 * double(n));
            for (int j = 0; j < 3; ++j)
                for (int ch = 0; ch < 3; ++ch) e[kTauClasses[j]][ch] += s.tau[j][ch] * norm;
            for (int ch = 0; ch < 3; ++ch) {
                double t = 0;
                for (int k = 0; k < kNumEffects; ++k) {
                    t += e[k][ch];
                    if (effects) (*effects)[k][3 * p + ch] = float(e[k][ch]);
                }
                image[3 * p + ch] = float(t);
                if (n > 1) {
                    double mean = s.sum[ch] / n;
                    double var = std::max(0.0, (s.sum_sq[ch] - n * mean * mean) / (n - 1.0));
                    variance[3 * p + ch] = float(var / n);
                }
            }
        }
    }

    void finish(RenderOutput& out) const override {
        out.stats.merge(pstats_);
        if (photons_needed_ && bias_passes_ > 0) {
            OutputArray a;
            a.name = "radius_bias";
            a.shape = {scene_.sensor->height, scene_.sensor->width, 3};
            a.data.resize(3 * px_.size());
            for (size_t p = 0; p < px_.size(); ++p)
                for (int ch = 0; ch < 3; ++ch) a.data[3 * p + ch] = float(px_[p].bias[ch] / double(bias_passes_));
            out.arrays.push_back(std::move(a));
            out.estimator_stats.push_back({"radius_bias_sum", {bias_sum_[0], bias_sum_[1], bias_sum_[2]}});
            out.estimator_stats.push_back({"radius_bias_sq_sum", {bias_sq_[0], bias_sq_[1], bias_sq_[2]}});
            out.estimator_stats.push_back({"radius_bias_passes", {double(bias_passes_)}});
        }
        if (photons_needed_) out.photon_maps.push_back(pms_);
        // Where the passes' time went (benchmarks/studies/photon_passes.py).
        out.estimator_stats.push_back({"phase_seconds_camera", {camera_seconds_}});
        out.estimator_stats.push_back({"phase_seconds_photon_trace", {pms_.trace_seconds}});
        out.estimator_stats.push_back({"phase_seconds_photon_build", {pms_.build_seconds}});
        out.estimator_stats.push_back({"phase_seconds_gather", {gather_seconds_}});
    }

private:
    static FilterSampler make_filter(const Scene& scene) {
        const SensorDesc& sd = scene.sensor_desc;
        return FilterSampler(sd.rfilter, sd.filter_radius, sd.filter_stddev);
    }

    // Step 1 for the pixels of row y: pixel p's camera sample of pass s on
    // Sampler(seed, p, s), to its visible point.
    void camera_row(PassLoop& loop, int s, int y, ThreadStats& stats) {
        const int W = scene_.sensor->width;
        for (int x = 0; x < W; ++x) {
            size_t p = size_t(y) * size_t(W) + size_t(x);
            Sampler sampler(loop.seed(), p, uint64_t(s));
            SensorRay sr = sample_camera_ray(*scene_.sensor, filter_, int(p), sampler);
            VisiblePoint& vp = vps_[p];
            vp.bsdf = nullptr;
            vp.er = EffectRadiance();
            ++stats.paths;
            sppm_.camera_path(scene_, sampler, sr.ray, vp.er, vp, stats);
            vp.beta *= sr.weight;
            Color tot(0.f);
            for (int k = 0; k < kNumEffects; ++k) {
                vp.er.by_effect[k] *= sr.weight;
                tot += vp.er.by_effect[k];
            }
            // A NaN or Inf sample is counted and dropped, never written.
            if (!keep_finite(stats, tot, vp.bsdf ? vp.beta : Color(0.f))) {
                vp.er = EffectRadiance();
                vp.bsdf = nullptr;
            }
        }
        loop.add_done(uint64_t(W));
    }

    // Step 2: pass s's photon paths into map_, traced into the photon
    // array of the previous pass's map; false when cancelled.
    bool photon_pass(PassLoop& loop, int s) {
        PhotonPass pp = trace_photon_paths(scene_, spec_, loop.seed(), uint64_t(s), uint64_t(sppm_.photon_count_),
                                           loop.threads(), loop.poll_once(), pstats_, max_photons_, map_.release());
        if (pp.over_memory)
            throw std::invalid_argument("render: integrator 'sppm': a pass's " + std::to_string(sppm_.photon_count_) +
                                        " photon paths stored more than " + std::to_string(max_photons_) +
                                        " photons (" + format_bytes(photon_map_build_bytes(double(pp.photons.size()))) +
                                        " with their tree), more than " + "this machine's " +
                                        format_bytes(memory_limit_bytes()) +
                                        " of memory holds beside the film; lower " + "photon_count");
        if (pp.cancelled) return false;
        pms_.photons += pp.photons.size();
        pms_.paths += pp.paths;
        pms_.trace_seconds += pp.seconds;
        auto tb = Clock::now();
        if (!map_.build(std::move(pp.photons), loop.threads(), false, loop.poll_once())) return false;
        pms_.build_seconds += since(tb);
        return true;
    }

    // Step 3 for the pixels of row y: the photons within each pixel's
    // radius of its visible point, and its statistics' update.
    void gather_row(const PhotonMap& map, int y) {
        const int W = scene_.sensor->width;
        const EffectMask& mask = sppm_.mask;
        const float alpha = sppm_.alpha_;
        thread_local std::vector<Neighbour> nb;
        BsdfContext ctx;
        for (int x = 0; x < W; ++x) {
            size_t p = size_t(y) * size_t(W) + size_t(x);
            const VisiblePoint& vp = vps_[p];
            PixelStats& ps = px_[p];
            Color phi[3] = {Color(0.f), Color(0.f), Color(0.f)};
            Color phi_half(0.f);  // photons within r / sqrt(2), every class
            double m = 0;
            if (vp.bsdf && !map.empty()) {
                ctx.set(vp.it);
                int budget = sppm_.max_depth_ < 0 ? 255 : sppm_.max_depth_ - vp.c;
                map.range(vp.it.p, float(ps.r2), nb);
                for (const Neighbour& n : nb) {
                    const Photon& ph = map.photons()[n.idx];
                    if (photon_depth(ph) > budget) continue;
                    Vec3 wp = vp.it.to_local(ph.wi);
                    float c = std::fabs(wp.z);
                    if (!(c > 1e-7f)) continue;
                    Color fr = vp.bsdf->eval(ctx, vp.wi, wp) * (1.f / c);
                    if (is_black(fr)) continue;  // photons x cannot reflect (back side) do not count
                    int j = vp.via_specular ? 2 : ((ph.flags & kPhotonIndirect) ? 1 : 0);
                    m += 1;
                    if (mask[kTauClasses[j]]) {
                        Color v = vp.beta * fr * ph.power;
                        phi[j] += v;
                        if (2.f * n.d2 <= float(ps.r2)) phi_half += v;
                    }
                }
            }
            {
                const Color all = phi[0] + phi[1] + phi[2];
                const double inv = 1.0 / (kPi * ps.r2);
                for (int ch = 0; ch < 3; ++ch) {
                    double b = 2.0 * (double(all[ch]) * inv - 2.0 * double(phi_half[ch]) * inv);
                    ps.bias[ch] += b;
                    row_bias_[3 * size_t(y) + ch] += b;
                }
            }
            Color value = vp.er.total() + (phi[0] + phi[1] + phi[2]) * float(1.0 / (kPi * ps.r2));
            for (int k = 0; k < kNumEffects; ++k)
                for (int ch = 0; ch < 3; ++ch) ps.ray[k][ch] += vp.er.by_effect[k][ch];
            // H&J 2009, eqs. 6-8 (radius and flux reduction).
            double ratio = m > 0 ? (ps.n + alpha * m) / (ps.n + m) : 1.0;
            for (int j = 0; j < 3; ++j)
                for (int ch = 0; ch < 3; ++ch) ps.tau[j][ch] = (ps.tau[j][ch] + phi[j][ch]) * ratio;
            ps.r2 *= ratio;
            ps.n += alpha * m;
            for (int ch = 0; ch < 3; ++ch) {
                ps.sum[ch] += value[ch];
                ps.sum_sq[ch] += double(value[ch]) * double(value[ch]);
            }
        }
    }

    const Sppm& sppm_;
    const Scene& scene_;
    FilterSampler filter_;
    std::vector<PixelStats> px_;
    std::vector<VisiblePoint> vps_;
    PhotonMap map_;  // the current pass's photons; its arrays serve the next pass again
    double camera_seconds_ = 0, gather_seconds_ = 0;
    bool photons_needed_ = false;
    PhotonTraceSpec spec_;
    PhotonMapStats pms_;
    ThreadStats pstats_;                 // photon tracing's counters
    uint64_t max_photons_ = UINT64_MAX;  // a pass's photons beyond this do not fit in memory
    std::vector<double> row_bias_;       // a pass's radius-bias estimates summed per row
    double bias_sum_[3] = {0, 0, 0}, bias_sq_[3] = {0, 0, 0};
    int bias_passes_ = 0;
};

RenderOutput Sppm::drive(const Scene& scene, const RenderOptions& opts, const PollFn& poll) const {
    // Said up front (memory.h): the per-pixel visible points and statistics,
    // the output, and a pass's photon map (the photons a path stores are
    // known only once traced; counted here as one per path, and
    // trace_photon_paths refuses a pass whose photons outgrow the memory).
    const int W = scene.sensor->width, H = scene.sensor->height;
    const double pixels = double(W) * double(H);
    check_memory(type, W, H,
                 {{"visible points", pixels * sizeof(VisiblePoint), "the resolution (film width, height)"},
                  {"pixel statistics", pixels * sizeof(PixelStats), "the resolution (film width, height)"},
                  output_memory(opts, W, H),
                  {"a pass's photon map (" + std::to_string(photon_count_) + " paths, one photon each)",
                   photon_map_build_bytes(double(photon_count_)), "photon_count"}});
    PassLoop loop(scene, opts, poll);
    Passes passes(*this, scene);
    return loop.run(passes);
}

namespace {

std::unique_ptr<Integrator> make_sppm(ParamReader& p) { return std::make_unique<Sppm>(p); }

}  // namespace

}  // namespace rm
