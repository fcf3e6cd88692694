// bdpt's test hook (integrator.h's bdpt_mis_check; bindings:
// _core.bdpt_mis_check): for the strategies of n random sample pairs, the
// weight bdpt computes (its linear-time ratios, bdpt.cpp's mis_weight), the
// weight from every strategy's full path density computed from scratch, a
// product over all vertices (Veach 1997, eqs. 10.5-10.6 and 9.13), and
// (split_sum) the sum of bdpt's weights over every strategy of the same full
// path. The subpaths and weights are bdpt's own (bdpt_internal.h); only the
// brute force is this file's. Visibility is ignored: weights do not depend
// on it. Medium vertices take part like any connectible vertex (their
// densities: bdpt.cpp's head comment).
#include <algorithm>
#include <cmath>

#include "estimators/bdpt_internal.h"

namespace rm {

namespace {

// The full path x_0 (camera) .. x_k (light) of strategy (s, t), each
// vertex's density in the camera direction (pc) and in the light
// direction (pl), computed from scratch; a delta vertex contributes 1 to
// the vertex after it (the delta functions are common to all strategies
// that can make the path).
struct FullPath {
    std::vector<PathVertex> x;
    std::vector<double> pc, pl;
    double p_le = 1.0;  // the light subpath's own density of x_k (pl[k] is next event estimation's)
    int k = 0;
    // whether strategy tt (tt camera vertices) can make the path
    bool valid(int tt) const {
        if (tt == k + 1) return !x[k].emitter->is_delta();  // s = 0: the camera path hits the emitter
        return !x[tt - 1].delta && !x[tt].delta;
    }
};

FullPath full_path(const BdptMisProbe& bd, const Scene& scene, int s, int t) {
    std::vector<PathVertex>& cam = bd.cam();
    std::vector<PathVertex>& light = bd.light();
    FullPath fp;
    std::vector<PathVertex>& x = fp.x;
    for (int i = 0; i < t; ++i) x.push_back(cam[i]);
    for (int i = s - 1; i >= 0; --i) x.push_back(light[i]);
    const int k = fp.k = int(x.size()) - 1;
    if (s > 0) {
        x[t - 1].delta = false;
        x[t].delta = false;
    }
    x[k].delta = false;
    if (s == 0) {  // the emitter the camera path ended on acts as the light vertex
        x[k].type = VType::Light;
    }
    const Emitter* em = x[k].emitter;
    std::vector<double>&pc = fp.pc, &pl = fp.pl;
    pc.assign(k + 1, 1.0);
    pl.assign(k + 1, 1.0);
    for (int i = 1; i <= k; ++i) {
        if (x[i - 1].delta) continue;
        double p = i == 1 ? camera_pdf_a(scene, x[0], x[1]) : pdf_to(scene, x[i - 1], &x[i - 2], x[i]);
        pc[i] = p != 0.0 ? p : 1.0;
    }
    double p_nee = 0.0;  // next event estimation's density of x_k, before the remap
    for (int i = k; i >= 1; --i) {
        double p;
        if (i == k) {  // next event estimation's density (strategy s' = 1); p_le below for s' >= 2
            p = p_nee = em->is_delta() ? emitter_pick_prob(scene, vertex_light_context(x[k - 1]), *em)
                                       : light_origin_pdf(scene, x[k], x[k - 1]);
        } else {
            if (x[i + 1].delta) continue;
            p = i == k - 1 ? emitter_pdf_to(scene, x[k], x[i]) : pdf_to(scene, x[i + 1], &x[i + 2], x[i]);
        }
        pl[i] = p != 0.0 ? p : 1.0;
    }
    // The light subpath's own density of x_k (sample_emission by area),
    // for strategies with s' >= 2 light vertices.
    // (Where next event estimation cannot reach x_k, both keep the
    // remapped density, as nee_over_emission's ratio of 1 does: a spot's
    // back, which its light-tree selection gives probability 0.)
    fp.p_le = pl[k];
    if (em->is_delta() && !x[k].infinite && p_nee > 0.0) {
        double a = double(start_pick_prob(scene, *em));
        if (a > 0.0) fp.p_le = a;
    }
    if (!em->is_delta() && !x[k].infinite && light_origin_pdf(scene, x[k], x[k - 1]) > 0.f) {
        double a = double(emission_origin_pdf(scene, *em, x[k].it.p));
        if (a > 0.0) fp.p_le = a;
    }
    return fp;
}

// Strategy (s, t)'s weight from every strategy's full path density, a
// product of per-vertex densities.
float brute_weight(const BdptMisProbe& bd, const Scene& scene, int s, int t) {
    const FullPath fp = full_path(bd, scene, s, t);
    const int k = fp.k;
    // Strategy with tt camera vertices x_0 .. x_{tt-1} and the rest from
    // the light: the log of its density (a product of up to hundreds of
    // vertex densities in media overflows a double, raised to beta).
    auto log_density = [&](int tt) {
        double p = 0.0;
        for (int i = 1; i < tt; ++i) p += std::log(fp.pc[i]);
        for (int i = tt; i <= k; ++i) p += std::log((i == k && tt < k) ? fp.p_le : fp.pl[i]);
        return p;
    };
    // w = h_t / sum h, h = p^beta, as exp(log h - max log h).
    const double b = bd.heuristic_exponent();
    std::vector<double> lh(k + 2, -INFINITY);
    double top = -INFINITY;
    for (int tt = 1; tt <= k + 1; ++tt)
        if (fp.valid(tt)) top = std::max(top, lh[tt] = b * log_density(tt));
    if (!std::isfinite(top) || !fp.valid(t)) return 0.f;
    double sum = 0.0;
    for (int tt = 1; tt <= k + 1; ++tt)
        if (fp.valid(tt)) sum += std::exp(lh[tt] - top);
    return float(std::exp(lh[t] - top) / sum);
}

// The sum of mis_weight (the renderer's linear-time weights) over every
// strategy that can make strategy (s, t)'s full path: the path split
// into tt camera and k + 1 - tt light vertices, each subpath's vertices
// carrying the densities their walks would store (pdf_fwd along the
// subpath, pdf_rev against it, from full_path). A partition of unity
// sums to 1 (Veach 1997, eq. 9.13's weights of one sample over all
// techniques).
float split_sum(const BdptMisProbe& bd, const Scene& scene, int s, int t) {
    const FullPath fp = full_path(bd, scene, s, t);
    const int k = fp.k;
    std::vector<PathVertex>& cam = bd.cam();
    std::vector<PathVertex>& light = bd.light();
    std::vector<PathVertex> cam_saved = cam, light_saved = light;
    double sum = 0.0;
    for (int tt = 1; tt <= k + 1; ++tt) {
        if (!fp.valid(tt)) continue;
        const int ss = k + 1 - tt;
        if (ss + tt - 1 < 1 || (ss == 1 && tt == 1)) continue;  // (1, 1) is left to (0, 2)
        cam.assign(fp.x.begin(), fp.x.begin() + tt);
        light.clear();
        for (int i = k; i >= tt; --i) light.push_back(fp.x[i]);
        for (int i = 1; i < tt; ++i) {
            cam[i].pdf_fwd = float(fp.pc[i]);
            cam[i].pdf_rev = float(fp.pl[i]);
        }
        for (int j = 0; j < ss; ++j) {
            int i = k - j;
            light[j].pdf_fwd = float(j == 0 ? (ss == 1 ? fp.pl[k] : fp.p_le) : fp.pl[i]);
            light[j].pdf_rev = float(fp.pc[i]);
        }
        if (tt == 1) {  // light tracing: the camera vertex as connect() places it
            cam[0].pdf_fwd = 1.f;
        }
        sum += bd.mis_weight(scene, ss, tt);
    }
    cam = std::move(cam_saved);
    light = std::move(light_saved);
    return float(sum);
}

}  // namespace

void bdpt_mis_check(const Scene& scene, const Integrator& bdpt, uint64_t seed, int n, std::vector<float>& fast,
                    std::vector<float>& brute, std::vector<float>& sums, std::vector<int>& strategy) {
    const std::unique_ptr<BdptMisProbe> probe = make_bdpt_mis_probe(scene, bdpt);
    const BdptMisProbe& bd = *probe;
    const int max_depth = bd.max_depth();
    const int P = scene.sensor->width * scene.sensor->height;
    for (int g = 0; g < n; ++g) {
        Sampler sampler(seed, uint64_t(g % P), uint64_t(g / P));
        bd.generate_subpaths(scene, sampler, g % P);
        std::vector<PathVertex>& cam = bd.cam();
        std::vector<PathVertex>& light = bd.light();
        for (int t = 2; t <= int(cam.size()); ++t)
            for (int s = 0; s <= int(light.size()); ++s) {
                // s = 1 uses the light subpath's y0 here (the renderer draws a
                // fresh one, whose densities come from the same functions).
                if (s + t - 1 < 2) continue;
                if (max_depth >= 0 && s + t - 1 > max_depth) continue;
                if (s == 0 && !(cam[t - 1].emitter && (cam[t - 1].type == VType::Surface || cam[t - 1].infinite)))
                    continue;
                // connection ends: surface or medium vertices (not an escaped camera path)
                if (s > 0 && cam[t - 1].type != VType::Surface && cam[t - 1].type != VType::Medium) continue;
                if (s > 1 && light[s - 1].type != VType::Surface && light[s - 1].type != VType::Medium) continue;
                if (s > 0 && (!cam[t - 1].connectible() || !light[s - 1].connectible())) continue;
                // s = 1 behind a one-sided area light carries nothing (and has no light-sampling density)
                if (s == 1 && !light[0].emitter->is_delta() && !light[0].infinite &&
                    !(dot(light[0].it.n, cam[t - 1].it.p - light[0].it.p) > 0.f))
                    continue;
                // s = 1: y0 as next event estimation would have sampled it (its density, as the renderer's)
                float saved_fwd = light.empty() ? 0.f : light[0].pdf_fwd;
                if (s == 1 && !light[0].infinite && !light[0].emitter->is_delta())
                    light[0].pdf_fwd = light_origin_pdf(scene, light[0], cam[t - 1]);
                fast.push_back(bd.mis_weight(scene, s, t));
                brute.push_back(brute_weight(bd, scene, s, t));
                sums.push_back(split_sum(bd, scene, s, t));
                if (!light.empty()) light[0].pdf_fwd = saved_fwd;
                // + 1000000 when the strategy's path has a medium vertex (the tests
                // check that media scenes exercise them)
                bool medium = false;
                for (int i = 1; i < t; ++i) medium = medium || cam[i].type == VType::Medium;
                for (int i = 1; i < s; ++i) medium = medium || light[i].type == VType::Medium;
                strategy.push_back(s * 1000 + t + (medium ? 1000000 : 0));
            }
    }
}

}  // namespace rm
