// `pssmlt`: primary-sample-space Metropolis light transport (Kelemen,
// Szirmay-Kalos, Antal and Csonka 2002) over the unidirectional path tracer
// (`path`) or bidirectional path tracing (`bdpt`, parameter
// `bidirectional`, Mitsuba 0.6's name). The sampled point u of the unit
// hypercube (mlt_sampler.h) drives the whole sample: its first two
// coordinates pick a pixel of the film uniformly, the rest are what the
// inner estimator draws (its camera ray through that pixel, by filter
// importance sampling, and its paths). The sample's splats g(u) (one per
// effect class at the pixel, and for bdpt the light-tracing splats of t = 1
// anywhere on the film) have the scalar contribution f(u) = the sum of
// their luminances, and a pixel's value is I_j = E[g_j(u)] (u uniform) =
// b E_pi[g_j / f] with b = E[f] and pi = f / b (Veach 1997, sec. 11.3).
//
// Chains: `chains` independent Markov chains, each with a bootstrap of its
// own (bootstrap_samples / chains independent points u_i, b_c their mean
// f) and a start u_{i*} drawn from it with probability f_i / sum f (pbrt-v4
// MLTIntegrator's bootstrap; Veach 1997, sec. 11.3.3 for the start-up bias
// it removes). That start makes each chain's estimate b_c mean_k g(x_k) /
// f(x_k) exactly unbiased at any chain length: E[b_c h(x_0)] = E[(1/n) sum_i
// f_i h(u_i)] = b E_pi[h], and the chain's kernel keeps pi (detailed
// balance), so E[b_c h(x_k)] = b E_pi[h] for every k. Hence `bias` is
// declared unbiased (the matrix test holds it to that); what remains is the
// chains' correlation, which only the variance sees.
//
// Mutations: a large step (probability large_step_probability) or a small
// one (normals of deviation `sigma`, mlt_sampler.h), accepted with
// a = min(1, f(y) / f(x)) (Metropolis et al. 1953: both kernels are
// symmetric). Expected-value splatting (Veach 1997, sec. 11.5): every
// proposal adds (1 - a) g(x) / f(x) and a g(y) / f(y); the current state's
// weights are summed and splatted once, when it is left (or at the end of a
// work chunk), which changes nothing in the sums but their rounding.
//
// Budget: one sample per pixel is mutations_per_pixel x W x H mutations
// (the crop window's pixels), dealt to the chains in turn (mutation m to
// chain m mod chains), so the plan is fixed by the budget alone.
//
// Variance (res.variance): batch means over independent chains (Law and
// Kelton, "Simulation Modeling and Analysis", sec. 9.5): chain c belongs to
// batch c mod B (B = min(32, chains)), I_b the estimate of batch b's n_b
// mutations, I that of all N; var = sum_b n_b (I_b - I)^2 / ((B - 1) N),
// as the light driver's (light_render.cpp). The batches are independent
// (own bootstraps, own streams), so this sees the correlation along each
// chain and the bootstrap's noise in b_c, which a variance over one chain's
// samples would not. Neighbouring pixels are correlated too (a chain
// lingers): a block mean's variance is not the sum of its pixels'.
//
// Determinism: each chain draws on its own streams and its splats join the
// film in chain order, so the result is the seed's whatever the thread
// count.
//
// res.stats: "mlt_b" (mean of the chains' b_c) and "mlt_b_variance" (its
// variance, from all bootstrap samples), "mlt_acceptance" (overall),
// "mlt_acceptance_per_chain", "mlt_large_step_acceptance",
// "mlt_small_step_acceptance", "mlt_max_rejections_per_chain" (the longest
// run of consecutive rejections of each chain, the stuck-chain symptom;
// "mlt_longest_rejection_run" its maximum, "mlt_stuck_chains" the chains
// whose run exceeds `stuck_rejections`, a threshold that is only reported),
// "mlt_dead_chains" (chains whose bootstrap found no light: they add 0).
//
// `mmlt`: multiplexed MLT (Hachisuka, Kaplanyan and Dachsbacher 2014) with
// a normalisation per depth, as pbrt-v4's MLTIntegrator bootstraps per
// depth. Depth d = 1 (the emitters the camera sees, s + t = 2) is a
// separate estimator (Hachisuka 2014, sec. 4, allows it for direct light):
// one camera ray per pixel and sample per pixel through the path tracer
// with max_depth 1, filter importance sampled, its variance per pixel from
// its samples. Depths d = 2 .. max_depth each have chains of their own:
// after the pixel, one coordinate chooses a strategy (s, t), s + t = d + 1,
// uniformly; the sample is that strategy alone on subpaths of s and t
// vertices (bdpt_internal.h), its MIS-weighted contribution times d + 1, so
// f_d's expectation b_d is depth d's share of bdpt's image. A chain never
// leaves its depth (small steps may change the strategy).
//   Bootstrap: each point u_i of depth d is evaluated with every strategy
// of its depth (the strategy coordinate moved into each strategy's
// interval at the same relative place), F_i = (1 / (d + 1)) sum_s
// f_d(u_i^s) and b_d = (1 / n_d) sum_i F_i, without the variance of the
// strategy choice. An eighth of bootstrap_samples is a pilot, dealt evenly
// to the depths on streams of its own, that only sets the n_d: the rest go
// an eighth evenly, seven eighths in proportion to the pilot's sd(F_d)
// (Neyman allocation, which minimises sum_d var(F_d) / n_d, b's variance;
// Cochran, "Sampling Techniques", sec. 5.5). The pilot's points are not
// averaged, so given the pilot n_d is fixed and b_d unbiased.
//   Chains: every depth with b_d > 0 gets two chains, the rest of `chains`
// go in proportion to sqrt(b_d) (largest remainders; in proportion to b_d,
// the time Hachisuka 2014's one chain spends at depth d, is best for the
// image mean but left the pixels a dim deep depth lights most to a few
// chains: docs/mlt.md). Every chain of depth d starts at a (point,
// strategy) drawn from depth d's bootstrap with probability f_d(u_i^s) /
// ((d + 1) sum_i F_i), and splats g / f_d with weight b_d C / M_d (C
// chains, M_d at depth d; fewer chains than 2 (max_depth - 1) are raised to
// that, and reported). Unbiased at
// any length: given the bootstrap, E[b_d h(x_0)] = (1 / n_d) sum_i
// (1 / (d + 1)) sum_s f_d(u_i^s) h(u_i^s), whose expectation is
// E[f_d h] = b_d E_pi_d[h] (for u uniform the moved point is uniform given
// its strategy), and the kernel keeps pi_d, so E[b_d h(x_k)] = b_d
// E_pi_d[h] for every k. M_d depends on the bootstrap, but every chain runs
// the same number of mutations K (mmlt rounds a sample per pixel up to a
// multiple of `chains` mutations), so depth d's estimate b_d (1 / (M_d K))
// sum_{c, k} h(x_k^c) has the conditional mean b_d (1 / K) sum_k
// E[h(x_k) | bootstrap] whatever M_d: the allocation cannot bias it.
//   Variance: depth d's chains share b_d, so its batch means (over its own
// chains: min(M_d, 32) batches, the depth's chain j in batch j mod B_d)
// see the chains' correlation, not b_d's error; that is added per pixel as
// I_{d,p}^2 var(F) / (n_d b_d^2) (the delta method on b_d's relative
// error, var(F) the spread of the depth's n_d bootstrap points), and the
// camera pass's variance for d = 1. The depths are independent (own
// points, own chains, own streams), so the three parts sum. A depth's tail
// (the tiny lights of veach_mis seen directly: depth 1) thus reaches only
// its own share of the image and its own variance.
//   res.stats: "mlt_b_per_depth" (d = 1: the camera pass's luminance sum)
// with "mlt_b_per_depth_variance", "mlt_chains_per_depth",
// "mlt_acceptance_per_depth" (NaN for d = 1), "mlt_b_per_strategy" (each
// (d, s)'s share of b with its variance, NaN for d = 1: the check against
// bdpt's strategy images, docs/mlt.md).
//
// Limits: no participating media, no dipole (refused by name: caps); no
// per-strategy images; the path tracer's samples reach only their pixel
// (filter importance sampling, as the camera driver's).
#include <algorithm>
#include <cmath>
#include <limits>
#include <memory>
#include <numeric>
#include <stdexcept>
#include <string>

#include "estimators/bdpt_internal.h"
#include "estimators/mlt_sampler.h"
#include "render/memory.h"
#include "render/pass_loop.h"
#include "render/registry.h"
#include "transport/camera_sample.h"

namespace rm {

namespace {

constexpr int kMaxBatches = 32;
constexpr uint32_t kStrategyDim = 2;  // mmlt's coordinates: pixel (0, 1), strategy (2)
// mmlt's depth-1 sums per pixel: [effect][rgb], then the sample total's squares (rgb, luminance).
constexpr size_t kDirectSlots = size_t(kNumEffects) * 3 + 4;
constexpr uint64_t kChunkMutations = uint64_t(1) << 19;  // mutations of all chains between commits (bounds memory)

// The chains' parameters, shared by pssmlt and mmlt (`bootstrap`: the default sample count).
std::vector<ParamSpec> chain_params(int64_t bootstrap) {
    return {
        ParamSpec::integer("chains", 256, "independent Markov chains (the variance's batches: min(32, chains))")
            .at_least(2)
            .at_most(1 << 20),
        ParamSpec::integer("bootstrap_samples", bootstrap,
                           "independent samples estimating b, shared out among the chains (each gets at least one)")
            .at_least(1)
            .at_most(int64_t(1) << 30),
        ParamSpec::integer("mutations_per_pixel", 1, "mutations per pixel in one sample per pixel of the budget")
            .at_least(1)
            .at_most(1 << 16),
        ParamSpec::real("large_step_probability", 0.3, "probability of a large step (a fresh independent sample)")
            .greater_than(0)
            .at_most(1),
        ParamSpec::real("sigma", 0.01, "standard deviation of a small step in primary sample space")
            .greater_than(0)
            .at_most(1),
        ParamSpec::integer("stuck_rejections", 256,
                           "a chain whose longest run of consecutive rejections exceeds this is counted as stuck "
                           "(res.stats mlt_stuck_chains); only reported, nothing is changed")
            .at_least(1)
            .at_most(int64_t(1) << 30),
    };
}

std::unique_ptr<Integrator> make_pssmlt(ParamReader& p);

[[maybe_unused]] const bool kRegistered = register_estimator([] {
    EstimatorInfo e;
    e.name = "pssmlt";
    e.doc =
        "primary-sample-space Metropolis light transport over path or bdpt (Kelemen et al. 2002), independent "
        "chains with their own bootstrap";
    e.params = {
        max_depth_param(),
        rr_depth_param(),
        hide_emitters_param(),
        ParamSpec::boolean("bidirectional", true, "mutate bdpt's samples (false: the unidirectional path tracer's)"),
    };
    for (ParamSpec& q : chain_params(16384)) e.params.push_back(q);
    e.caps.driver = Driver::OwnPasses;
    e.caps.bias = Bias::Unbiased;
    e.caps.correlated_pixels = true;
    e.factory = make_pssmlt;
    return e;
}());

std::unique_ptr<Integrator> make_mmlt(ParamReader& p);

// mmlt: the chains of pssmlt over one bdpt strategy per sample.
[[maybe_unused]] const bool kRegisteredMmlt = register_estimator([] {
    EstimatorInfo e;
    e.name = "mmlt";
    e.doc =
        "multiplexed Metropolis light transport: one bdpt strategy per sample, chosen by a mutated coordinate "
        "(Hachisuka et al. 2014)";
    e.params = {
        ParamSpec::integer("max_depth", 5, "longest path in segments (the depths a sample chooses among)")
            .at_least(1)
            .at_most(1024),
        rr_depth_param(),
        hide_emitters_param(),
    };
    for (ParamSpec& q : chain_params(65536)) e.params.push_back(q);
    e.caps.driver = Driver::OwnPasses;
    e.caps.bias = Bias::Unbiased;
    e.caps.correlated_pixels = true;
    e.factory = make_mmlt;
    return e;
}());

// Mutation index m goes to chain m mod C: chain c's share of the first n.
inline uint64_t chain_share(uint64_t n, uint64_t chains, uint64_t c) { return n / chains + (c < n % chains ? 1 : 0); }

}  // namespace

class PssmltIntegrator final : public Integrator {
public:
    PssmltIntegrator(ParamReader& p, bool multiplexed)
        : max_depth_(p.get_int("max_depth")),
          rr_depth_(p.get_int("rr_depth")),
          hide_(p.get_bool("hide_emitters")),
          bidir_(multiplexed || p.get_bool("bidirectional")),
          multiplexed_(multiplexed),
          chains_(p.get_int("chains")),
          bootstrap_(p.get_int("bootstrap_samples")),
          mpp_(p.get_int("mutations_per_pixel")),
          large_p_(p.get_float("large_step_probability")),
          sigma_(p.get_float("sigma")),
          stuck_(p.get_int("stuck_rejections")),
          chains_requested_(chains_) {
        // mmlt gives every depth 2 .. max_depth with light two chains at least
        // (the head): fewer are raised to that, which res.stats reports
        // ("mlt_chains", "mlt_chains_requested") and the Python side warns of.
        if (multiplexed) chains_ = std::max(chains_, 2 * (max_depth_ - 1));
    }

    void sample(const Scene&, Sampler&, const Ray&, EffectRadiance&, ThreadStats&) const override {
        throw std::logic_error("integrator '" + type + "' renders through its own driver");
    }
    RenderOutput drive(const Scene& scene, const RenderOptions& opts, const PollFn& poll) const override;

    class Passes;

private:
    int max_depth_, rr_depth_;
    bool hide_, bidir_, multiplexed_;
    int chains_, bootstrap_, mpp_;
    float large_p_, sigma_;
    int64_t stuck_;
    int chains_requested_;
};

class PssmltIntegrator::Passes final : public PassStep {
public:
    // `direct`: mmlt's estimator of depth 1 (the path tracer, max_depth 1); null for pssmlt.
    Passes(const PssmltIntegrator& m, const Scene& scene, const Integrator& inner, const Integrator* direct)
        : m_(m),
          scene_(scene),
          inner_(inner),
          direct_(direct),
          filter_(scene.sensor_desc.rfilter, scene.sensor_desc.filter_radius, scene.sensor_desc.filter_stddev),
          W_(scene.sensor->width),
          H_(scene.sensor->height),
          C_(uint64_t(m.chains_)),
          B_(int(std::min<uint64_t>(kMaxBatches, C_))),
          per_spp_(mutations_per_spp(m, *scene.sensor)),
          n_boot_(std::max<uint64_t>(1, (uint64_t(m.bootstrap_) + C_ - 1) / C_)) {
        const Sensor& sn = *scene.sensor;
        cx0_ = sn.crop_x, cx1_ = sn.crop_x + sn.crop_w, cy0_ = sn.crop_y, cy1_ = sn.crop_y + sn.crop_h;
        norm_x_ = splat_norms(filter_, W_, cx0_, cx1_);
        norm_y_ = splat_norms(filter_, H_, cy0_, cy1_);
        const size_t px = size_t(W_) * size_t(H_);
        sums_.assign(px * kNumEffects * 3, 0.0);
        chains_.reserve(size_t(C_));
        for (uint64_t c = 0; c < C_; ++c) chains_.emplace_back(m.sigma_, m.large_p_);
        stripes_ = std::max(1, std::min(H_, 64));
        if (!m.multiplexed_) {
            batches_.assign(px * size_t(B_) * 3, 0.0);
            for (uint64_t c = 0; c < C_; ++c) chains_[size_t(c)].batch = size_t(c % uint64_t(B_));
            return;
        }
        depths_.resize(size_t(m.max_depth_) + 1);
        const uint64_t nd = uint64_t(std::max(m.max_depth_ - 1, 1));
        for (int d = 2; d <= m.max_depth_; ++d)
            depths_[size_t(d)].n = std::max<uint64_t>(1, chain_share(uint64_t(m.bootstrap_), nd, uint64_t(d - 2)));
        direct_sums_.assign(px * kDirectSlots, 0.0);
        direct_chunk_.assign(px * kDirectSlots, 0.0);
    }

    // Mutations in one sample per pixel: mutations_per_pixel x the crop
    // window's pixels; mmlt rounds it up to a multiple of `chains`, so that
    // all chains run equally long (the head's unbiasedness argument).
    static uint64_t mutations_per_spp(const PssmltIntegrator& m, const Sensor& sn) {
        const uint64_t n = uint64_t(m.mpp_) * uint64_t(sn.crop_w) * uint64_t(sn.crop_h);
        if (!m.multiplexed_) return n;
        const uint64_t c = uint64_t(m.chains_);
        return (n + c - 1) / c * c;
    }

    int pass(PassLoop& loop, int s0, int s1) override {
        if (!started_) {
            if (m_.multiplexed_) {
                if (!bootstrap_depths(loop)) return s0;
            } else {
                auto boot = [&](size_t c, int th) { bootstrap(loop, c, loop.stats(th)); };
                if (!loop.parallel_for(size_t(C_), boot)) return s0;
            }
            started_ = true;
        }
        const int step = int(std::max<uint64_t>(1, kChunkMutations / std::max<uint64_t>(per_spp_, 1)));
        for (int a = s0; a < s1;) {
            const int b = std::min(s1, a + step);
            auto run = [&](size_t c, int th) {
                Chain& ch = chains_[c];
                ch.out.clear();
                const uint64_t n0 = chain_share(uint64_t(a) * per_spp_, C_, c);
                const uint64_t n1 = chain_share(uint64_t(b) * per_spp_, C_, c);
                for (uint64_t k = n0; k < n1; ++k) {
                    if (loop.cancelled()) return;
                    mutate(ch, loop.stats(th));
                }
                flush(ch);
            };
            if (!loop.parallel_for(size_t(C_), run)) return a;
            if (direct_) {
                std::fill(direct_chunk_.begin(), direct_chunk_.end(), 0.0);
                auto row = [&](size_t y, int th) { direct_row(loop, int(y), a, b, loop.stats(th)); };
                if (!loop.parallel_for(size_t(H_), row)) return a;
            }
            auto merge = [&](size_t i, int) {
                int y0 = int(int64_t(H_) * int64_t(i) / stripes_), y1 = int(int64_t(H_) * int64_t(i + 1) / stripes_);
                merge_rows(y0, y1);
            };
            loop.parallel_commit(size_t(stripes_), merge);
            loop.add_done(uint64_t(b - a) * uint64_t(scene_.sensor->crop_w) * uint64_t(scene_.sensor->crop_h));
            committed_ = b;
            a = b;
        }
        return s1;
    }

    void develop(int spp, std::vector<float>& image, std::vector<float>& variance,
                 std::vector<std::vector<float>>* effects) const override {
        if (m_.multiplexed_) return develop_mmlt(spp, image, variance, effects);
        const size_t px = size_t(W_) * size_t(H_);
        image.assign(3 * px, 0.f);
        variance.assign(3 * px, std::numeric_limits<float>::quiet_NaN());
        if (effects) effects->assign(kNumEffects, std::vector<float>(3 * px, 0.f));
        const uint64_t n = uint64_t(std::max(spp, 0)) * per_spp_;
        if (n == 0) return;
        std::vector<double> n_b(size_t(B_), 0.0);
        for (uint64_t c = 0; c < C_; ++c) n_b[c % uint64_t(B_)] += double(chain_share(n, C_, c));
        int b_eff = 0;
        for (double v : n_b) b_eff += v > 0 ? 1 : 0;
        const double inv_n = 1.0 / double(n);
        for (size_t p = 0; p < px; ++p)
            for (int c = 0; c < 3; ++c) {
                double total = 0;
                for (int k = 0; k < kNumEffects; ++k) {
                    double e = sums_[(p * kNumEffects + k) * 3 + c] * inv_n;
                    total += e;
                    if (effects) (*effects)[k][3 * p + c] = float(e);
                }
                image[3 * p + c] = float(total);
                if (b_eff < 2) continue;  // too few batches: NaN, never a fake 0
                double ss = 0;
                for (int b = 0; b < B_; ++b)
                    if (n_b[size_t(b)] > 0) {
                        double d = batches_[(p * size_t(B_) + size_t(b)) * 3 + c] / n_b[size_t(b)] - total;
                        ss += n_b[size_t(b)] * d * d;
                    }
                variance[3 * p + c] = float(ss / (double(b_eff - 1) * double(n)));
            }
    }

    void finish(RenderOutput& out) const override {
        double b_sum = 0, f_sum = 0, f_sq = 0, n_f = 0, dead = 0, stuck = 0, longest = 0;
        uint64_t acc = 0, prop = 0, lacc = 0, lprop = 0;
        std::vector<double> per_chain, max_rej;
        for (const Chain& ch : chains_) {
            b_sum += ch.b;
            f_sum += ch.f_sum;
            f_sq += ch.f_sq;
            n_f += double(ch.n_f);
            dead += ch.b > 0 ? 0 : 1;
            acc += ch.accepted;
            prop += ch.proposed;
            lacc += ch.large_accepted;
            lprop += ch.large_proposed;
            per_chain.push_back(ch.proposed ? double(ch.accepted) / double(ch.proposed)
                                            : std::numeric_limits<double>::quiet_NaN());
            max_rej.push_back(double(ch.max_run));
            stuck += ch.max_run > uint64_t(m_.stuck_) ? 1 : 0;
            longest = std::max(longest, double(ch.max_run));
        }
        auto ratio = [](uint64_t a, uint64_t b) {
            return b ? double(a) / double(b) : std::numeric_limits<double>::quiet_NaN();
        };
        // b: the mean of the chains' b_c (each the mean of an equal share of
        // the bootstrap), its variance from the bootstrap samples' spread.
        // mmlt: the sum of the depths' b_d (d = 1: the camera pass's), the
        // sum of their variances (independent depths).
        double b = started_ ? b_sum / double(C_) : 0.0;
        const double mean_f = n_f > 0 ? f_sum / n_f : 0.0;
        const double var_f = n_f > 1 ? std::max(0.0, (f_sq - n_f * mean_f * mean_f) / (n_f - 1.0)) : 0.0;
        double b_var = n_f > 0 ? var_f / n_f : std::numeric_limits<double>::quiet_NaN();
        std::vector<double> b_depth, b_depth_var;
        if (m_.multiplexed_) {
            depth_b(b_depth, b_depth_var);
            b = 0, b_var = 0, n_f = 0;
            for (size_t k = 0; k < b_depth.size(); ++k) b += b_depth[k], b_var += b_depth_var[k];
            n_f = double(pilot_);
            for (const Depth& dp : depths_) n_f += double(dp.n);
        }
        auto& st = out.estimator_stats;
        st.push_back({"mlt_b", {b}});
        st.push_back({"mlt_b_variance", {b_var}});
        st.push_back({"mlt_bootstrap_samples", {n_f}});
        st.push_back({"mlt_chains", {double(C_)}});
        st.push_back({"mlt_chains_requested", {double(m_.chains_requested_)}});
        st.push_back({"mlt_dead_chains", {dead}});
        st.push_back({"mlt_mutations", {double(prop)}});
        st.push_back({"mlt_acceptance", {ratio(acc, prop)}});
        st.push_back({"mlt_large_step_acceptance", {ratio(lacc, lprop)}});
        st.push_back({"mlt_small_step_acceptance", {ratio(acc - lacc, prop - lprop)}});
        st.push_back({"mlt_acceptance_per_chain", per_chain});
        st.push_back({"mlt_max_rejections_per_chain", max_rej});
        st.push_back({"mlt_longest_rejection_run", {longest}});
        st.push_back({"mlt_stuck_rejections", {double(m_.stuck_)}});
        st.push_back({"mlt_stuck_chains", {stuck}});
        if (!m_.multiplexed_) {
            image_mean_variance(st);
            return;
        }
        std::vector<double> mean_dof;
        st.push_back({"mlt_image_mean_variance", mmlt_image_mean_variance(mean_dof)});
        st.push_back({"mlt_image_mean_dof", mean_dof});
        out.arrays.push_back(variance_dof_array());
        st.push_back({"mlt_b_per_depth", b_depth});
        st.push_back({"mlt_b_per_depth_variance", b_depth_var});
        // Chains and acceptance by depth 1 .. max_depth (depth 1: no chains, NaN).
        std::vector<double> per_depth, chains_d;
        for (int d = 1; d <= m_.max_depth_; ++d) {
            uint64_t a = 0, p = 0;
            for (const Chain& ch : chains_)
                if (ch.depth == d) a += ch.accepted, p += ch.proposed;
            per_depth.push_back(ratio(a, p));
            chains_d.push_back(double(depths_[size_t(d)].chains));
        }
        st.push_back({"mlt_acceptance_per_depth", per_depth});
        st.push_back({"mlt_chains_per_depth", chains_d});
        // b by strategy: each (d, s)'s share of b_d and the variance of that
        // share's mean, from the depth's bootstrap points. A strategy's
        // share is the expectation of its MIS-weighted contribution, the
        // luminance sum of bdpt's strategy image (s, d + 1 - s): the check
        // that each strategy is unbiased, which b alone cannot localise.
        // Depth 1 is the camera pass's, not by strategy: NaN.
        const double nan = std::numeric_limits<double>::quiet_NaN();
        std::vector<double> share(strategy_slots(), nan), share_var(strategy_slots(), nan);
        for (int d = 2; d <= m_.max_depth_; ++d) {
            const Depth& dp = depths_[size_t(d)];
            const double n = double(dp.n);
            for (int s = 0; s <= d && s < int(dp.fs_sum.size()); ++s) {
                const double m = dp.fs_sum[size_t(s)] / n;
                share[strategy_slot(d, s)] = m;
                share_var[strategy_slot(d, s)] =
                    n > 1 ? std::max(0.0, (dp.fs_sq[size_t(s)] - n * m * m) / (n - 1.0)) / n : nan;
            }
        }
        st.push_back({"mlt_b_per_strategy", share});
        st.push_back({"mlt_b_per_strategy_variance", share_var});
    }

private:
    // "mlt_image_mean_variance" (R, G, B): the variance of the image mean by
    // the batch means res.variance uses per pixel. A chain's normalisation
    // b_c scales every pixel it visits, so the pixels' errors share one
    // component across the image, which no sum of their variances gives;
    // the batches are independent (own chains, own bootstraps), so their
    // image means carry it. NaN with fewer than 2 batches.
    void image_mean_variance(std::vector<std::pair<std::string, std::vector<double>>>& st) const {
        std::vector<double> n_b(size_t(B_), 0.0);
        for (uint64_t c = 0; c < C_; ++c) n_b[c % uint64_t(B_)] += double(chains_[c].proposed);
        double n = 0;
        int b_eff = 0;
        for (double v : n_b) {
            n += v;
            b_eff += v > 0 ? 1 : 0;
        }
        const size_t px = size_t(W_) * size_t(H_);
        std::vector<double> out(3, std::numeric_limits<double>::quiet_NaN());
        if (b_eff >= 2 && px > 0) {
            for (int c = 0; c < 3; ++c) {
                std::vector<double> m(size_t(B_), 0.0);
                double total = 0;
                for (size_t p = 0; p < px; ++p)
                    for (int b = 0; b < B_; ++b) m[size_t(b)] += batches_[(p * size_t(B_) + size_t(b)) * 3 + c];
                for (double v : m) total += v;
                total /= n * double(px);
                double ss = 0;
                for (int b = 0; b < B_; ++b)
                    if (n_b[size_t(b)] > 0) {
                        const double d = m[size_t(b)] / (n_b[size_t(b)] * double(px)) - total;
                        ss += n_b[size_t(b)] * d * d;
                    }
                out[size_t(c)] = ss / (double(b_eff - 1) * n);
            }
        }
        st.push_back({"mlt_image_mean_variance", out});
    }

    struct Chain {
        Chain(float sigma, float large_p) : pss(sigma, large_p) {}
        PssSampler pss;
        double b = 0;                         // the chain's bootstrap estimate of b
        double f_sum = 0, f_sq = 0;           // its bootstrap samples' f: sum, sum of squares
        uint64_t n_f = 0;                     // and their count
        int depth = 0;                        // mmlt: the chain's depth (0: none, a dead chain)
        size_t batch = 0;                     // the variance's batch it belongs to
        std::vector<Splat> cur, prop;         // the current state's splats, the proposal's
        float f_cur = 0;                      // f of the current state
        double pending = 0;                   // expected-value weight the current state has gathered
        std::vector<Splat> out;               // this chunk's splats, values weighted
        uint64_t accepted = 0, proposed = 0;  // acceptance counts
        uint64_t large_accepted = 0, large_proposed = 0;
        uint64_t run = 0, max_run = 0;  // consecutive rejections: now, longest
    };

    // mmlt: one depth's bootstrap and chains.
    struct Depth {
        uint64_t n = 0;                     // bootstrap points
        std::vector<double> cdf;            // prefix sums of the points' F_i (n + 1 entries)
        double f_sum = 0, f_sq = 0;         // sum of F_i, of F_i^2
        double f_c4 = 0;                    // sum of (F_i - b_d)^4
        std::vector<double> fs_sum, fs_sq;  // per strategy s: sum of f_d(u_i^s) / (d + 1), of its square
        double b = 0;                       // b_d = f_sum / n
        int first_chain = 0, chains = 0;
        size_t first_batch = 0, batches = 0;
    };
    // The sums of a block of bootstrap points.
    struct BootBlock {
        int d = 0;
        uint64_t i0 = 0, i1 = 0;
        bool pilot = false;
        double f_sum = 0, f_sq = 0;
        std::vector<double> fs_sum, fs_sq;
    };

    // The sample of the point `pss` holds: its splats inside the crop
    // window (finite ones; the others are counted) and f, their luminance.
    // mmlt: at depth `depth` (2 .. max_depth).
    float evaluate(PssSampler& pss, std::vector<Splat>& out, ThreadStats& stats, int depth = 0) const {
        out.clear();
        Sampler sampler(&pss);
        const Vec2 u = sampler.next_2d();
        const int x = std::min(int(u.x * float(W_)), W_ - 1), y = std::min(int(u.y * float(H_)), H_ - 1);
        const int pixel = y * W_ + x;
        const float film_scale = float(W_) * float(H_);
        if (m_.multiplexed_) {
            // mmlt (Hachisuka et al. 2014, sec. 4) at the chain's depth d: a
            // strategy (s, t), s + t = d + 1, chosen uniformly by a
            // coordinate of its own; the contribution times d + 1.
            const int d = depth;
            const int s = std::min(int(sampler.next_1d() * float(d + 1)), d);
            bdpt_trace_strategy(inner_, scene_, sampler, pixel, s, d + 1 - s, float(d + 1), out, stats);
        } else if (m_.bidir_) {
            // bdpt's camera splats (pixel >= 0) are already scaled by W H:
            // its samples pick their pixel uniformly, as here.
            inner_.trace_light_path(scene_, sampler, pixel, out, stats);
        } else {
            SensorRay sr = sample_camera_ray(*scene_.sensor, filter_, pixel, sampler);
            EffectRadiance er;
            ++stats.paths;
            inner_.sample(scene_, sampler, sr.ray, er, stats);
            for (int k = 0; k < kNumEffects; ++k) {
                Color v = er.by_effect[k] * sr.weight * film_scale;
                if (is_black(v)) continue;
                Splat sp;
                sp.pixel = pixel;
                sp.effect = k;
                sp.value = v;
                out.push_back(sp);
            }
        }
        double f = 0;
        size_t kept = 0;
        for (const Splat& sp : out) {
            if (!keep_finite(stats, sp.value)) continue;
            if (sp.pixel >= 0) {
                if (!scene_.sensor->in_crop(sp.pixel % W_, sp.pixel / W_)) continue;
            } else if (sp.film.x < float(cx0_) || sp.film.x > float(cx1_) || sp.film.y < float(cy0_) ||
                       sp.film.y > float(cy1_)) {
                continue;
            }
            const float l = luminance(sp.value);
            if (!(l > 0.f)) continue;
            f += double(l);
            out[kept++] = sp;
        }
        out.resize(kept);
        return std::isfinite(f) ? float(f) : 0.f;
    }

    // pssmlt: chain c's bootstrap: its share of independent points, b_c,
    // and its start drawn from them in proportion to f (replayed from its
    // stream).
    void bootstrap(PassLoop& loop, size_t c, ThreadStats& stats) {
        Chain& ch = chains_[c];
        const uint64_t stream = mix64(loop.seed() ^ mix64(uint64_t(c) + 0x6d6c74626f6f7473ULL));
        std::vector<double> cdf(1, 0.0);
        cdf.reserve(size_t(n_boot_) + 1);
        std::vector<Splat> tmp;
        for (uint64_t i = 0; i < n_boot_; ++i) {
            if (loop.cancelled()) return;
            ch.pss.restart(stream, i);
            const double f = evaluate(ch.pss, tmp, stats);
            cdf.push_back(cdf.back() + f);
            ch.f_sum += f;
            ch.f_sq += f * f;
        }
        ch.n_f = n_boot_;
        ch.b = ch.f_sum / double(n_boot_);
        // The chain's own stream: the start's choice, then every mutation.
        const uint64_t own = mix64(loop.seed() ^ mix64(uint64_t(c) + 0x6d6c74636861696eULL));
        if (!(ch.f_sum > 0)) {
            ch.pss.reseed(own, uint64_t(c));
            return;  // no light found: the chain adds 0 (its mutations still count)
        }
        Pcg32 pick(own, uint64_t(c) ^ 0x5bd1e995ULL);
        const size_t j = pick_index(cdf, double(pick.next_float()) * cdf.back());
        ch.pss.restart(stream, uint64_t(j));
        ch.f_cur = evaluate(ch.pss, ch.cur, stats);
        ch.pss.reseed(own, uint64_t(c));
    }

    // The entry j of prefix sums `cdf` (cdf[0] = 0) whose interval
    // [cdf[j], cdf[j + 1]) holds `target`, never one of weight 0.
    static size_t pick_index(const std::vector<double>& cdf, double target) {
        size_t j = size_t(std::upper_bound(cdf.begin() + 1, cdf.end(), target) - cdf.begin()) - 1;
        while (j + 1 < cdf.size() && !(cdf[j + 1] > cdf[j])) ++j;
        return std::min(j, cdf.size() - 2);
    }

    // mmlt's bootstrap stream of depth d.
    uint64_t depth_stream(const PassLoop& loop, int d) const {
        return mix64(loop.seed() ^ mix64(uint64_t(d) + 0x6d6d6c7464657074ULL));
    }

    // mmlt: bootstrap point i of depth d evaluated with each of its d + 1
    // strategies: f[s] = f_d(u_i^s), v[s] the strategy coordinate of u_i^s
    // (the point's own for its own strategy, the others moved into their
    // intervals at the same relative place, strategy_coordinate).
    void point_strategies(PssSampler& pss, uint64_t stream, uint64_t i, int d, std::vector<Splat>& tmp,
                          ThreadStats& stats, std::vector<double>& f, std::vector<float>& v) const {
        const int n = d + 1;
        f.assign(size_t(n), 0.0);
        v.assign(size_t(n), 0.f);
        pss.restart(stream, i);
        const double f0 = evaluate(pss, tmp, stats, d);
        const float v0 = pss.value(kStrategyDim);
        const int s0 = std::min(int(v0 * float(n)), d);
        const float xi = std::min(std::max(v0 * float(n) - float(s0), 0.f), 1.f);
        for (int s = 0; s < n; ++s) {
            if (s == s0) {
                f[size_t(s)] = f0, v[size_t(s)] = v0;
                continue;
            }
            v[size_t(s)] = strategy_coordinate(s, n, xi);
            pss.restart(stream, i, int(kStrategyDim), v[size_t(s)]);
            f[size_t(s)] = evaluate(pss, tmp, stats, d);
        }
    }

    // mmlt's bootstrap (the head): a pilot that deals the points to the
    // depths, then every depth's points; each in blocks on the threads,
    // summed in block order; b_d; the chains dealt to the depths; each
    // chain's start. False when cancelled.
    bool bootstrap_depths(PassLoop& loop) {
        const int D = m_.max_depth_;
        if (D < 2) return true;  // depth 1 alone: the camera pass, every chain dead
        const uint64_t nd = uint64_t(D - 1), total = uint64_t(m_.bootstrap_);
        pilot_ = std::min(total, std::max(nd, total / 8));
        std::vector<BootBlock> pilot;
        for (int d = 2; d <= D; ++d) add_blocks(pilot, d, chain_share(pilot_, nd, uint64_t(d - 2)), true);
        if (!run_blocks(loop, pilot)) return false;
        std::vector<double> sd(size_t(D) + 1, 0.0), n_p(size_t(D) + 1, 0.0), s1(size_t(D) + 1, 0.0),
            s2(size_t(D) + 1, 0.0);
        for (const BootBlock& bb : pilot) {
            n_p[size_t(bb.d)] += double(bb.i1 - bb.i0);
            s1[size_t(bb.d)] += bb.f_sum;
            s2[size_t(bb.d)] += bb.f_sq;
        }
        double sd_sum = 0;
        for (int d = 2; d <= D; ++d) {
            const double n = n_p[size_t(d)];
            sd[size_t(d)] =
                n > 1 ? std::sqrt(std::max(0.0, (s2[size_t(d)] - s1[size_t(d)] * s1[size_t(d)] / n) / (n - 1.0))) : 0.0;
            sd_sum += sd[size_t(d)];
        }
        // Neyman allocation (Cochran, "Sampling Techniques", sec. 5.5): b's
        // variance sum_d var(F_d) / n_d is least with n_d in proportion to
        // sd(F_d); an eighth of the points is spread evenly, as the pilot's
        // sd is itself an estimate. The pilot's points are not reused, so
        // n_d is independent of the points b_d averages (b_d stays unbiased).
        const uint64_t rest = total - pilot_, even = rest / (8 * nd);
        std::vector<double> weight(size_t(D) + 1, 0.0);
        for (int d = 2; d <= D; ++d) weight[size_t(d)] = sd_sum > 0 ? sd[size_t(d)] : 1.0;
        std::vector<uint64_t> share = largest_remainders(rest - even * nd, weight);
        std::vector<BootBlock> blocks;
        for (int d = 2; d <= D; ++d) {
            Depth& dp = depths_[size_t(d)];
            dp.n = std::max<uint64_t>(1, even + share[size_t(d)]);
            dp.cdf.assign(size_t(dp.n) + 1, 0.0);
            add_blocks(blocks, d, dp.n, false);
        }
        if (!run_blocks(loop, blocks)) return false;
        std::vector<double> root_b(size_t(D) + 1, 0.0);
        int live = 0;
        for (int d = 2; d <= D; ++d) {
            Depth& dp = depths_[size_t(d)];
            dp.fs_sum.assign(size_t(d) + 1, 0.0);
            dp.fs_sq.assign(size_t(d) + 1, 0.0);
        }
        for (const BootBlock& bb : blocks) {
            Depth& dp = depths_[size_t(bb.d)];
            dp.f_sum += bb.f_sum;
            dp.f_sq += bb.f_sq;
            for (size_t s = 0; s < bb.fs_sum.size(); ++s) dp.fs_sum[s] += bb.fs_sum[s], dp.fs_sq[s] += bb.fs_sq[s];
        }
        for (int d = 2; d <= D; ++d) {
            Depth& dp = depths_[size_t(d)];
            dp.b = dp.f_sum / double(dp.n);
            if (dp.b > 0) ++live, root_b[size_t(d)] = std::sqrt(dp.b);
            // The points' central fourth moment (b_d's degrees of freedom,
            // depth_variance), from each F_i before the prefix sums.
            for (size_t i = 1; i < dp.cdf.size(); ++i) {
                const double e2 = (dp.cdf[i] - dp.b) * (dp.cdf[i] - dp.b);
                dp.f_c4 += e2 * e2;
            }
            for (size_t i = 1; i < dp.cdf.size(); ++i) dp.cdf[i] += dp.cdf[i - 1];
        }
        allocate_chains(root_b, live);
        auto start = [&](size_t c, int th) { start_chain(loop, c, loop.stats(th)); };
        return loop.parallel_for(size_t(C_), start);
    }

    // `n` split in proportion to `weight` (largest remainders, ties to the
    // lower index).
    static std::vector<uint64_t> largest_remainders(uint64_t n, const std::vector<double>& weight) {
        std::vector<uint64_t> out(weight.size(), 0);
        double sum = 0;
        for (double w : weight) sum += w;
        if (!(sum > 0)) return out;
        std::vector<std::pair<double, size_t>> frac;
        uint64_t given = 0;
        for (size_t k = 0; k < weight.size(); ++k) {
            if (!(weight[k] > 0)) continue;
            const double q = double(n) * weight[k] / sum;
            out[k] = std::min<uint64_t>(n - given, uint64_t(std::floor(q)));
            given += out[k];
            frac.push_back({q - double(out[k]), k});
        }
        std::stable_sort(frac.begin(), frac.end(), [](const auto& a, const auto& b) { return a.first > b.first; });
        for (size_t k = 0; given < n && k < frac.size(); ++k, ++given) ++out[frac[k].second];
        return out;
    }

    // Depth d's points [0, n) in blocks (`pilot`: the pilot's stream).
    static void add_blocks(std::vector<BootBlock>& blocks, int d, uint64_t n, bool pilot) {
        constexpr uint64_t kBlock = 1024;
        for (uint64_t i0 = 0; i0 < n; i0 += kBlock) {
            BootBlock bb;
            bb.d = d, bb.i0 = i0, bb.i1 = std::min(n, i0 + kBlock), bb.pilot = pilot;
            blocks.push_back(bb);
        }
    }

    // The blocks' points on the threads: their sums, and each point's F_i
    // into its depth's cdf (not the pilot's). False when cancelled.
    bool run_blocks(PassLoop& loop, std::vector<BootBlock>& blocks) {
        auto run = [&](size_t k, int th) {
            BootBlock& bb = blocks[k];
            Depth& dp = depths_[size_t(bb.d)];
            const uint64_t stream =
                bb.pilot ? mix64(depth_stream(loop, bb.d) ^ 0x70696c6f74ULL) : depth_stream(loop, bb.d);
            PssSampler pss(m_.sigma_, m_.large_p_);
            std::vector<Splat> tmp;
            std::vector<double> f;
            std::vector<float> v;
            bb.fs_sum.assign(size_t(bb.d) + 1, 0.0);
            bb.fs_sq.assign(size_t(bb.d) + 1, 0.0);
            for (uint64_t i = bb.i0; i < bb.i1; ++i) {
                if (loop.cancelled()) return;
                point_strategies(pss, stream, i, bb.d, tmp, loop.stats(th), f, v);
                double F = 0;
                for (size_t s = 0; s < f.size(); ++s) {
                    const double share = f[s] / double(f.size());
                    F += share;
                    bb.fs_sum[s] += share;
                    bb.fs_sq[s] += share * share;
                }
                if (!bb.pilot) dp.cdf[size_t(i) + 1] = F;  // the point's F_i; prefix sums after
                bb.f_sum += F;
                bb.f_sq += F * F;
            }
        };
        return loop.parallel_for(blocks.size(), run);
    }

    // mmlt: the chains dealt to the depths with b_d > 0: two each, the rest
    // in proportion to sqrt(b_d) (largest_remainders), in depth order, each
    // depth's batches next to each other. In proportion to b_d (the time
    // Hachisuka 2014's one chain spends at each depth) would be best for the
    // image mean, but starves the pixels a deep, dim depth lights most
    // (docs/mlt.md); sqrt(b_d) lies between that and an even split.
    void allocate_chains(const std::vector<double>& root_b, int live) {
        if (live == 0) return;  // no light at any depth: every chain dead
        // chains >= 2 (max_depth - 1): checked by the factory
        const std::vector<uint64_t> extra = largest_remainders(C_ - 2 * uint64_t(live), root_b);
        int next_chain = 0;
        size_t next_batch = 0;
        for (int d = 2; d <= m_.max_depth_; ++d) {
            Depth& dp = depths_[size_t(d)];
            if (!(dp.b > 0)) continue;
            dp.chains = int(2 + extra[size_t(d)]);
            dp.first_chain = next_chain;
            dp.first_batch = next_batch;
            dp.batches = size_t(std::min(dp.chains, kMaxBatches));
            for (int j = 0; j < dp.chains; ++j) {
                Chain& ch = chains_[size_t(next_chain + j)];
                ch.depth = d;
                ch.batch = dp.first_batch + size_t(j) % dp.batches;
                ch.b = dp.b * double(C_) / double(dp.chains);  // the splats' weight: b_d C / M_d
            }
            next_chain += dp.chains;
            next_batch += dp.batches;
        }
        nb_ = next_batch;
        batches_.assign(size_t(W_) * size_t(H_) * nb_ * 3, 0.0);
    }

    // mmlt: chain c's start, a (point, strategy) of its depth's bootstrap
    // drawn with probability f_d(u_i^s) / ((d + 1) sum_i F_i): the point by
    // F_i, then its strategy by f_d(u_i^s), each by a number of the chain's
    // own stream.
    void start_chain(PassLoop& loop, size_t c, ThreadStats& stats) {
        Chain& ch = chains_[c];
        const uint64_t own = mix64(loop.seed() ^ mix64(uint64_t(c) + 0x6d6c74636861696eULL));
        if (ch.depth == 0) {
            ch.pss.reseed(own, uint64_t(c));
            return;
        }
        const Depth& dp = depths_[size_t(ch.depth)];
        const uint64_t stream = depth_stream(loop, ch.depth);
        Pcg32 pick(own, uint64_t(c) ^ 0x5bd1e995ULL);
        const size_t i = pick_index(dp.cdf, double(pick.next_float()) * dp.cdf.back());
        std::vector<Splat> tmp;
        std::vector<double> f;
        std::vector<float> v;
        point_strategies(ch.pss, stream, uint64_t(i), ch.depth, tmp, stats, f, v);
        std::vector<double> cdf(1, 0.0);
        for (double x : f) cdf.push_back(cdf.back() + x);
        const size_t s = pick_index(cdf, double(pick.next_float()) * cdf.back());
        ch.pss.restart(stream, uint64_t(i), int(kStrategyDim), v[s]);
        ch.f_cur = evaluate(ch.pss, ch.cur, stats, ch.depth);
        ch.pss.reseed(own, uint64_t(c));
    }

    // mmlt's depth 1: row y's camera samples [a, b) into this chunk's sums
    // (the emitters seen directly, the path tracer with max_depth 1).
    void direct_row(PassLoop& loop, int y, int a, int b, ThreadStats& stats) {
        if (y < cy0_ || y >= cy1_) return;
        const uint64_t seed = mix64(loop.seed() ^ 0x6d6d6c7464697231ULL);
        for (int x = cx0_; x < cx1_; ++x) {
            const int pixel = y * W_ + x;
            double* acc = &direct_chunk_[size_t(pixel) * kDirectSlots];
            for (int k = a; k < b; ++k) {
                if (loop.cancelled()) return;
                Sampler sampler(seed, uint64_t(pixel), uint64_t(k));
                SensorRay sr = sample_camera_ray(*scene_.sensor, filter_, pixel, sampler);
                EffectRadiance er;
                ++stats.paths;
                direct_->sample(scene_, sampler, sr.ray, er, stats);
                Color total(0.f);
                for (int e = 0; e < kNumEffects; ++e) {
                    const Color v = er.by_effect[e] * sr.weight;
                    if (!keep_finite(stats, v)) continue;
                    total += v;
                    for (int ch = 0; ch < 3; ++ch) acc[size_t(e) * 3 + size_t(ch)] += double(v[ch]);
                }
                const double l = double(luminance(total));
                for (int ch = 0; ch < 3; ++ch) acc[kNumEffects * 3 + size_t(ch)] += double(total[ch]) * total[ch];
                acc[kNumEffects * 3 + 3] += l * l;
            }
        }
    }

    // mmlt's strategies (d, s), d = 1 .. max_depth, s = 0 .. d, in that
    // order: slot d (d + 1) / 2 - 1 + s.
    size_t strategy_slots() const { return size_t(m_.max_depth_) * size_t(m_.max_depth_ + 3) / 2; }
    static size_t strategy_slot(int d, int s) { return size_t(d) * size_t(d + 1) / 2 - 1 + size_t(s); }

    // mmlt's strategy coordinate: s of n strategies at relative place xi
    // in [0, 1) of its interval, kept inside it against rounding.
    static float strategy_coordinate(int s, int n, float xi) {
        float v = (float(s) + xi) / float(n);
        for (int k = 0; k < 8; ++k) {
            const int got = std::min(int(v * float(n)), n - 1);
            if (got == s) break;
            v = std::nextafter(v, got > s ? 0.f : 1.f);
        }
        return v;
    }

    void mutate(Chain& ch, ThreadStats& stats) {
        if (!(ch.b > 0) || !(ch.f_cur > 0.f)) return;  // a chain without light
        PssSampler& pss = ch.pss;
        pss.start_iteration();
        const bool large = pss.large_step();
        const float fy = evaluate(pss, ch.prop, stats, ch.depth);
        const double a = std::min(1.0, double(fy) / double(ch.f_cur));
        ++ch.proposed;
        if (large) ++ch.large_proposed;
        ch.pending += 1.0 - a;
        if (a > 0) emit(ch, ch.prop, a * ch.b / double(fy));
        if (double(pss.uniform()) < a) {
            flush(ch);
            std::swap(ch.cur, ch.prop);
            ch.f_cur = fy;
            pss.accept();
            ++ch.accepted;
            if (large) ++ch.large_accepted;
            ch.run = 0;
        } else {
            pss.reject();
            ch.max_run = std::max(ch.max_run, ++ch.run);
        }
    }

    // The current state's gathered weight, splatted.
    void flush(Chain& ch) {
        if (ch.pending > 0 && ch.f_cur > 0.f) emit(ch, ch.cur, ch.pending * ch.b / double(ch.f_cur));
        ch.pending = 0;
    }

    static void emit(Chain& ch, const std::vector<Splat>& splats, double w) {
        for (Splat sp : splats) {
            sp.value = sp.value * float(w);
            ch.out.push_back(sp);
        }
    }

    // The chunk's splats, in chain order, into rows [y0, y1).
    void merge_rows(int y0, int y1) {
        for (uint64_t c = 0; c < C_; ++c) {
            const size_t b = chains_[size_t(c)].batch;
            for (const Splat& sp : chains_[size_t(c)].out) {
                if (sp.pixel >= 0) {
                    const int py = sp.pixel / W_;
                    if (py < y0 || py >= y1) continue;
                    add(size_t(sp.pixel), b, sp.effect, sp.value, 1.0);
                    continue;
                }
                for_each_splat_pixel(filter_, norm_x_, norm_y_, W_, y0, y1, sp.film.x, sp.film.y,
                                     [&](size_t p, double wgt) { add(p, b, sp.effect, sp.value, wgt); });
            }
        }
        if (!direct_) return;
        // mmlt: the chunk's camera samples of depth 1.
        const size_t p0 = size_t(y0) * size_t(W_) * kDirectSlots, p1 = size_t(y1) * size_t(W_) * kDirectSlots;
        for (size_t k = p0; k < p1; ++k) direct_sums_[k] += direct_chunk_[k];
    }

    void add(size_t p, size_t batch, int effect, const Color& v, double wgt) {
        double* e = &sums_[(p * kNumEffects + size_t(effect)) * 3];
        double* bb = &batches_[(p * (m_.multiplexed_ ? nb_ : size_t(B_)) + batch) * 3];
        for (int c = 0; c < 3; ++c) {
            e[c] += wgt * double(v[c]);
            bb[c] += wgt * double(v[c]);
        }
    }

    // mmlt's estimate: the depths' chains (sums_ / n) and depth 1's camera
    // samples (their mean); the variance per pixel: each depth's batch
    // means and b_d's share (depth_variance), and the camera samples' own
    // (pixel_variance, which also gives its degrees of freedom).
    void develop_mmlt(int spp, std::vector<float>& image, std::vector<float>& variance,
                      std::vector<std::vector<float>>* effects) const {
        const size_t px = size_t(W_) * size_t(H_);
        image.assign(3 * px, 0.f);
        variance.assign(3 * px, std::numeric_limits<float>::quiet_NaN());
        if (effects) effects->assign(kNumEffects, std::vector<float>(3 * px, 0.f));
        if (spp <= 0) return;
        const double n = double(uint64_t(spp) * per_spp_), k = double(spp);
        for (size_t p = 0; p < px; ++p) {
            const double* dir = &direct_sums_[p * kDirectSlots];
            for (int c = 0; c < 3; ++c) {
                double total = 0;
                for (int e = 0; e < kNumEffects; ++e) {
                    const double v =
                        sums_[(p * kNumEffects + size_t(e)) * 3 + size_t(c)] / n + dir[size_t(e) * 3 + size_t(c)] / k;
                    total += v;
                    if (effects) (*effects)[size_t(e)][3 * p + size_t(c)] = float(v);
                }
                image[3 * p + size_t(c)] = float(total);
                if (spp < 2) continue;  // depth 1's variance needs two samples: NaN, never a fake 0
                variance[3 * p + size_t(c)] = float(pixel_variance(p, c, spp).var);
            }
        }
    }

    // A variance made of independent parts, each estimated with its own
    // degrees of freedom, and the degrees of freedom of the sum by
    // Welch-Satterthwaite (Satterthwaite 1946): nu = (sum v_i)^2 /
    // sum (v_i^2 / nu_i). Parts of variance 0 carry no weight; a sum of 0
    // has nu = inf (nothing varied: the z-tests take a zero variance as
    // exact).
    struct VarianceDof {
        double var = 0, weight = 0;  // sum v_i, sum v_i^2 / nu_i
        void add(double v, double nu) { add(v, nu, 0.0, 1.0); }
        // Two parts at once, summed first (as res.variance always summed them).
        void add(double v1, double nu1, double v2, double nu2) {
            var += std::max(v1, 0.0) + std::max(v2, 0.0);
            if (v1 > 0) weight += v1 * v1 / nu1;
            if (v2 > 0) weight += v2 * v2 / nu2;
        }
        double dof() const { return weight > 0 ? var * var / weight : std::numeric_limits<double>::infinity(); }
    };

    // Pixel p's channel c after `spp` samples per pixel: its variance (what
    // res.variance reports) and that estimate's degrees of freedom
    // ("mlt_variance_dof"). The camera pass's sample variance has spp - 1;
    // each depth's batch means and b_d's share theirs (depth_variance).
    VarianceDof pixel_variance(size_t p, int c, int spp) const {
        const double n = double(uint64_t(spp) * per_spp_), k = double(spp);
        const double* dir = &direct_sums_[p * kDirectSlots];
        double dir_sum = 0;
        for (int e = 0; e < kNumEffects; ++e) dir_sum += dir[size_t(e) * 3 + size_t(c)];
        VarianceDof v;
        v.add(sample_mean_variance(dir_sum, dir[kNumEffects * 3 + size_t(c)], k), k - 1.0);
        for (const Depth& dp : depths_)
            if (dp.chains > 0)
                depth_variance(dp, n, [&](size_t b) { return batches_[(p * nb_ + b) * 3 + size_t(c)]; }, v);
        return v;
    }

    // The variance of the mean of k samples with sum `sum` and sum of squares `sq`.
    static double sample_mean_variance(double sum, double sq, double k) {
        return k > 1 ? std::max(0.0, sq - sum * sum / k) / (k * (k - 1.0)) : std::numeric_limits<double>::quiet_NaN();
    }

    // b_d's relative variance: var(F) / (n_d b_d^2), from its bootstrap points.
    static double b_relative_variance(const Depth& dp) {
        const double n = double(dp.n);
        if (!(dp.b > 0) || n < 2) return 0.0;
        return std::max(0.0, (dp.f_sq - n * dp.b * dp.b) / (n - 1.0)) / n / (dp.b * dp.b);
    }

    // The variance of depth dp's estimate I_d = sum_b S(b) / n (S(b): batch
    // b's sum, of a pixel or of the image mean; n the mutations of all
    // chains, each chain n / C), added to `out` in two parts:
    // - batch means over the depth's B_d batches of m_b chains each (Law and
    //   Kelton, sec. 9.5), batch b's estimate I_b = S(b) M_d / (m_b n),
    //   var = sum_b w_b (I_b - I_d)^2 / (B_d - 1) with w_b = m_b / M_d. Its
    //   degrees of freedom are B_d - 1 only for normal batch means; a pixel
    //   that few chains visit has batch means that are mostly 0 and a few
    //   clumps, and then the estimate of the variance is itself uncertain.
    //   Satterthwaite's nu = 2 var^2 / Var(var estimate) with the variance
    //   of a sample variance, Var(s^2) = sigma^4 (2 / (B - 1) + (kappa - 3)
    //   / B) (kappa the batch means' kurtosis; Cramer 1946, sec. 27.4),
    //   kappa estimated by sum_b w_b e_b^4 / (sum_b w_b e_b^2)^2: normal
    //   batch means give B_d - 1, one visited batch of 32 about 2, k visited
    //   batches about 2 k (a Poisson count's own variance estimate), kept
    //   within [1, B_d - 1] (variance_dof);
    // - I_d^2 times b_d's relative variance (the head), from the depth's
    //   n_d bootstrap points, with their kurtosis likewise (a heavy tail of
    //   F gives far fewer than n_d - 1).
    template <class Sum>
    static void depth_variance(const Depth& dp, double n, Sum S, VarianceDof& out) {
        const size_t B = dp.batches, M = size_t(dp.chains);
        double I = 0;
        for (size_t b = 0; b < B; ++b) I += S(dp.first_batch + b);
        I /= n;
        double m2 = 0, m4 = 0;
        for (size_t b = 0; b < B; ++b) {
            const double m_b = double(M / B + (b < M % B ? 1 : 0));
            const double I_b = S(dp.first_batch + b) * double(M) / (m_b * n);
            const double e2 = (I_b - I) * (I_b - I);
            m2 += m_b / double(M) * (I_b - I) * (I_b - I);
            m4 += m_b / double(M) * e2 * e2;
        }
        const double n_d = double(dp.n), m2_b = n_d > 1 ? (dp.f_sq - n_d * dp.b * dp.b) / n_d : 0.0;
        out.add(m2 / (double(B) - 1.0), variance_dof(double(B), m2, m4), I * I * b_relative_variance(dp),
                variance_dof(n_d, m2_b, dp.f_c4 / n_d));
    }

    // The degrees of freedom of a sample variance of `n` values with second
    // and fourth central moments m2, m4 (weighted means over the values):
    // Satterthwaite's nu = 2 sigma^4 / Var(s^2), Var(s^2) = sigma^4 (2 / (n
    // - 1) + (kappa - 3) / n), kappa = m4 / m2^2 (Cramer 1946, sec. 27.4),
    // within [1, n - 1] (n - 1 for normal values).
    static double variance_dof(double n, double m2, double m4) {
        const double top = n - 1.0;
        if (!(m2 > 0) || !(top > 0)) return std::max(top, 1.0);
        const double rel = 2.0 / top + (m4 / (m2 * m2) - 3.0) / n;  // Var(s^2) / sigma^4
        return rel > 0 ? std::min(top, std::max(1.0, 2.0 / rel)) : top;
    }

    // mmlt's "mlt_image_mean_variance" (R, G, B): per depth the batch means
    // of the image sums and b_d's share, plus the camera samples' variance
    // of depth 1 (independent pixels: the sum of theirs over px^2, with the
    // camera pass's spp - 1 degrees of freedom); `dof` gets each channel's
    // degrees of freedom ("mlt_image_mean_dof").
    std::vector<double> mmlt_image_mean_variance(std::vector<double>& dof) const {
        const size_t px = size_t(W_) * size_t(H_);
        std::vector<double> out(3, std::numeric_limits<double>::quiet_NaN());
        dof = out;
        if (committed_ < 2 || px == 0) return out;
        const double n = double(uint64_t(committed_) * per_spp_), k = double(committed_);
        for (int c = 0; c < 3; ++c) {
            std::vector<double> img(nb_, 0.0);
            double dir_var = 0;
            for (size_t p = 0; p < px; ++p) {
                for (size_t b = 0; b < nb_; ++b) img[b] += batches_[(p * nb_ + b) * 3 + size_t(c)];
                const double* dir = &direct_sums_[p * kDirectSlots];
                double sum = 0;
                for (int e = 0; e < kNumEffects; ++e) sum += dir[size_t(e) * 3 + size_t(c)];
                dir_var += sample_mean_variance(sum, dir[kNumEffects * 3 + size_t(c)], k);
            }
            VarianceDof v;
            v.add(dir_var / (double(px) * double(px)), k - 1.0);
            for (const Depth& dp : depths_)
                if (dp.chains > 0) depth_variance(dp, n, [&](size_t b) { return img[b] / double(px); }, v);
            out[size_t(c)] = v.var;
            dof[size_t(c)] = v.dof();
        }
        return out;
    }

    // "mlt_variance_dof": res.variance's degrees of freedom per pixel and
    // channel (pixel_variance), the crop window's (H, W, 3) as res.variance;
    // NaN where the variance is (fewer than 2 samples per pixel).
    OutputArray variance_dof_array() const {
        OutputArray a;
        a.name = "mlt_variance_dof";
        const int w = cx1_ - cx0_, h = cy1_ - cy0_;
        a.shape = {h, w, 3};
        a.data.assign(size_t(w) * size_t(h) * 3, std::numeric_limits<float>::quiet_NaN());
        if (committed_ < 2) return a;
        for (int y = cy0_; y < cy1_; ++y)
            for (int x = cx0_; x < cx1_; ++x)
                for (int c = 0; c < 3; ++c)
                    a.data[(size_t(y - cy0_) * size_t(w) + size_t(x - cx0_)) * 3 + size_t(c)] =
                        float(pixel_variance(size_t(y) * size_t(W_) + size_t(x), c, committed_).dof());
        return a;
    }

    // mmlt's b per depth 1 .. max_depth and the variance of each: depth 1
    // the luminance sum of the camera samples' image, the others b_d.
    void depth_b(std::vector<double>& b, std::vector<double>& var) const {
        b.assign(size_t(m_.max_depth_), 0.0);
        var.assign(size_t(m_.max_depth_), 0.0);
        const double k = double(committed_);
        if (committed_ > 0) {
            for (size_t p = 0; p < size_t(W_) * size_t(H_); ++p) {
                const double* dir = &direct_sums_[p * kDirectSlots];
                Color sum(0.f);
                for (int e = 0; e < kNumEffects; ++e)
                    for (int c = 0; c < 3; ++c) sum[c] += float(dir[size_t(e) * 3 + size_t(c)]);
                const double l = double(luminance(sum));
                b[0] += l / k;
                var[0] += sample_mean_variance(l, dir[kNumEffects * 3 + 3], k);
            }
        } else {
            var[0] = std::numeric_limits<double>::quiet_NaN();
        }
        for (int d = 2; d <= m_.max_depth_; ++d) {
            const Depth& dp = depths_[size_t(d)];
            b[size_t(d - 1)] = dp.b;
            var[size_t(d - 1)] = dp.b * dp.b * b_relative_variance(dp);
        }
    }

    const PssmltIntegrator& m_;
    const Scene& scene_;
    const Integrator& inner_;
    const Integrator* direct_;  // mmlt's depth 1 (null for pssmlt)
    FilterSampler filter_;
    const int W_, H_;
    const uint64_t C_;
    const int B_;
    const uint64_t per_spp_;  // mutations per sample per pixel of the budget
    const uint64_t n_boot_;   // bootstrap samples per chain
    int cx0_ = 0, cx1_ = 0, cy0_ = 0, cy1_ = 0;
    std::vector<double> norm_x_, norm_y_;
    std::vector<double> sums_, batches_;  // [pixel][effect][rgb], [pixel][batch][rgb]
    std::vector<Chain> chains_;
    // mmlt: depths 0 .. max_depth (2 .. max_depth used), the batches of all
    // depths, depth 1's sums per pixel (committed, this chunk's):
    // [pixel][kDirectSlots].
    std::vector<Depth> depths_;
    size_t nb_ = 0;
    uint64_t pilot_ = 0;  // the pilot's bootstrap points
    std::vector<double> direct_sums_, direct_chunk_;
    int committed_ = 0;  // samples per pixel in the sums
    int stripes_ = 1;
    bool started_ = false;
};

RenderOutput PssmltIntegrator::drive(const Scene& scene, const RenderOptions& opts, const PollFn& poll) const {
    const int W = scene.sensor->width, H = scene.sensor->height;
    const double px = double(W) * double(H);
    if (multiplexed_)  // batches: min(32, M_d) per depth; depth 1's sums twice; the bootstrap's F_i
        check_memory(type, W, H,
                     {{"per-pixel sums",
                       px * 8.0 *
                           (3.0 * (kNumEffects + std::min(chains_, kMaxBatches * std::max(max_depth_ - 1, 1))) +
                            2.0 * kDirectSlots),
                       "the resolution (film width, height)"},
                      {"chains", double(chains_) * 512.0, "chains"},
                      {"bootstrap", double(bootstrap_) * 8.0, "bootstrap_samples"},
                      output_memory(opts, W, H)});
    else
        check_memory(type, W, H,
                     {{"per-pixel sums", px * 8.0 * 3.0 * (kNumEffects + std::min(kMaxBatches, chains_)),
                       "the resolution (film width, height)"},
                      {"chains", double(chains_) * 512.0, "chains"},
                      output_memory(opts, W, H)});
    IntegratorDesc d;
    d.type = bidir_ ? "bdpt" : "path";
    d.params.set("max_depth", int64_t(max_depth_));
    d.params.set("rr_depth", int64_t(rr_depth_));
    d.params.set("hide_emitters", hide_);
    // No truncation probe inside the chains: its tally counts camera samples
    // of its own, and its draws would only lengthen the primary sample vector.
    if (!bidir_) d.params.set("truncation_probe", 0.0);
    std::unique_ptr<Integrator> made = make_integrator(d, mask);
    const Integrator& inner = made->for_scene(scene);
    inner.check_scene(scene);
    // mmlt's depth 1: the path tracer with max_depth 1, the emitters the
    // camera sees (the head).
    std::unique_ptr<Integrator> made_direct;
    const Integrator* direct = nullptr;
    if (multiplexed_) {
        IntegratorDesc d1;
        d1.type = "path";
        d1.params.set("max_depth", int64_t(1));
        d1.params.set("rr_depth", int64_t(rr_depth_));
        d1.params.set("hide_emitters", hide_);
        d1.params.set("truncation_probe", 0.0);
        made_direct = make_integrator(d1, mask);
        direct = &made_direct->for_scene(scene);
        direct->check_scene(scene);
    }
    PassLoop loop(scene, opts, poll);
    loop.set_pixels(uint64_t(scene.sensor->crop_w) * uint64_t(scene.sensor->crop_h));
    Passes passes(*this, scene, inner, direct);
    return loop.run(passes);
}

namespace {

std::unique_ptr<Integrator> make_pssmlt(ParamReader& p) { return std::make_unique<PssmltIntegrator>(p, false); }
std::unique_ptr<Integrator> make_mmlt(ParamReader& p) { return std::make_unique<PssmltIntegrator>(p, true); }

}  // namespace

}  // namespace rm
