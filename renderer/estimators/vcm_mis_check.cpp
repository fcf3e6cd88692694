// vcm's test hook (integrator.h's vcm_mis_check; bindings:
// _core.vcm_mis_check): for the full paths of n random sample pairs (every
// connection (s, t) the pair makes, every length), every technique that
// can make the path -- the connections s' = 0 .. k and the merges at its
// non-delta surface vertices x_1 .. x_{k-1} -- weighted twice:
//   brute: from each technique's full-path density computed from scratch,
//          a product over all vertices with the technique's sample count
//          (light tracing n_L, a merge pi r^2 n_L: its acceptance
//          probability pi r^2 p(x_i) over the light path's density times
//          n_L light paths; tech. rep. sec. 4, eq. (20)), h(p_T) / sum h(p);
//   fast:  the renderer's recursive weights (vcm.cpp), the path split into
//          the technique's light and camera prefixes, each vertex carrying
//          the densities its walk would store and the quantities the
//          renderer's updates give it.
// and per path the sum of the fast weights over all its techniques (a
// partition of unity sums to 1), and the renderer's weight of the pair's
// own technique on its walked subpaths beside the brute one. Visibility is
// ignored: weights do not depend on it. `mutation` breaks one quantity (1:
// the camera vertex's d^VCM without the light-path count; 2: light
// d^VM 50 % off from y_2 on), for the test's power check.
#include <algorithm>
#include <cmath>
#include <stdexcept>

#include "estimators/vcm_internal.h"

namespace rm {

namespace {

struct Full {
    std::vector<PathVertex> x;   // x_0 (light) .. x_k (camera)
    std::vector<double> pl, pc;  // densities from the light side, from the camera side
    double p_le = 1, p_nee = 1;
    int k = 0;
};

Full full_path(const Scene& scene, const VcmWeights& w, const std::vector<PathVertex>& cam,
               const std::vector<PathVertex>& light, int s, int t) {
    Full f;
    std::vector<PathVertex>& x = f.x;
    for (int i = 0; i < s; ++i) x.push_back(light[i]);
    for (int j = t - 1; j >= 0; --j) x.push_back(cam[j]);
    const int k = f.k = int(x.size()) - 1;
    if (s > 0 && s < k + 1) {
        x[s - 1].delta = false;
        x[s].delta = false;
    }
    x[0].delta = false;
    x[0].type = VType::Light;
    const Emitter* em = x[0].emitter;
    f.pl.assign(k + 1, 1.0);
    f.pc.assign(k + 1, 1.0);
    for (int i = 1; i < k; ++i) {
        if (x[i - 1].delta) continue;
        double p = i == 1 ? emitter_pdf_to(scene, x[0], x[1]) : pdf_to(scene, x[i - 1], &x[i - 2], x[i]);
        f.pl[i] = p != 0.0 ? p : 1.0;
    }
    for (int i = 0; i < k; ++i) {
        if (x[i + 1].delta) continue;
        double p =
            i == k - 1 ? w.film_pixels * camera_pdf_a(scene, x[k], x[k - 1]) : pdf_to(scene, x[i + 1], &x[i + 2], x[i]);
        f.pc[i] = p != 0.0 ? p : 1.0;
    }
    if (em->is_delta()) {
        f.p_le = start_pick_prob(scene, *em);
        f.p_nee = x[0].infinite ? f.p_le : emitter_pick_prob(scene, vertex_light_context(x[1]), *em);
        if (!(f.p_le > 0.0) || !(f.p_nee > 0.0)) f.p_nee = f.p_le;  // as nee_over_emission's ratio of 1
    } else {
        f.p_nee = light_origin_pdf(scene, x[0], x[1]);
        f.p_le = x[0].infinite ? f.p_nee : double(emission_origin_pdf(scene, *em, x[0].it.p));
        if (!(f.p_le > 0.0)) f.p_le = f.p_nee;
        if (!(f.p_nee > 0.0)) f.p_nee = f.p_le;  // as nee_over_emission's ratio of 1
    }
    return f;
}

enum Kind { kVC, kVM };
struct Tech {
    Kind kind;
    int a;  // VC: s' light vertices; VM: the merge vertex i
};

bool merge_vertex(const PathVertex& v) { return vcm_mergeable(v); }

// Whether technique `tc` can make the path, and its log density. A delta
// lobe at a vertex leaves its neighbours' densities from that side at 1
// (the delta is common to every technique), and so does a density of 0
// (a path no technique's walk could make, whose weights matter to nothing),
// as the renderer's remap0 (bdpt's convention).
bool tech_density(const Scene& scene, const VcmWeights& w, const Full& f, const Tech& tc, bool has_importance,
                  double& logp) {
    const int k = f.k;
    const std::vector<PathVertex>& x = f.x;
    logp = 0.0;
    auto cam_from = [&](int lo) {  // camera side samples x_lo .. x_{k-1}
        for (int j = lo; j < k; ++j) logp += std::log(f.pc[j]);
    };
    auto light_to = [&](int hi, double p0) {  // light side samples x_0 .. x_hi
        logp += std::log(p0);
        for (int j = 1; j <= hi; ++j) logp += std::log(f.pl[j]);
    };
    if (tc.kind == kVM) {
        const int i = tc.a;
        if (!w.vm || i < 1 || i > k - 1 || !merge_vertex(x[i])) return false;
        light_to(i, f.p_le);
        cam_from(i);
        logp += std::log(w.eta);
        return true;
    }
    const int sp = tc.a;
    if (sp == 0) {
        if (x[0].emitter->is_delta()) return false;
        if (!w.vc) {  // bpm: the camera's emission hits count on purely specular paths only
            for (int j = 1; j < k; ++j)
                if (!x[j].delta) return false;
        }
        cam_from(0);
        return true;
    }
    if (!w.vc) return false;
    if (sp == k) {  // light tracing
        if (k < 2 || !has_importance || x[k - 1].delta || !vcm_mergeable_end(x[k - 1])) return false;
        light_to(k - 1, f.p_le);
        logp += std::log(w.n_light);
        return true;
    }
    if (x[sp - 1].delta || x[sp].delta) return false;
    if (!vcm_mergeable_end(x[sp]) || (sp >= 2 && !vcm_mergeable_end(x[sp - 1]))) return false;
    light_to(sp - 1, sp == 1 ? f.p_nee : f.p_le);
    cam_from(sp);
    return true;
}

// The renderer's weight of technique tc on the path split for it.
double fast_weight(const Scene& scene, const VcmWeights& w, const Full& f, const Tech& tc, int mutation) {
    const int k = f.k;
    const int s_light = tc.kind == kVM ? tc.a + 1 : tc.a;  // light vertices x_0 .. x_{s_light - 1}
    const int c_first = tc.a;                              // camera vertices x_k .. x_{c_first}
    std::vector<PathVertex> L(f.x.begin(), f.x.begin() + s_light), C;
    for (int i = k; i >= c_first; --i) C.push_back(f.x[i]);
    for (int j = 0; j < s_light; ++j) {
        L[j].pdf_fwd = float(j == 0 ? (s_light == 1 && tc.kind == kVC ? f.p_nee : f.p_le) : f.pl[j]);
        L[j].pdf_rev = float(f.pc[j]);
    }
    for (int m = 1; m < int(C.size()); ++m) {
        int i = k - m;
        C[m].pdf_fwd = float(m == 1 ? f.pc[k - 1] / w.film_pixels : f.pc[i]);
        C[m].pdf_rev = float(i >= 1 ? f.pl[i] : f.p_le);
    }
    std::vector<VcmMis> lr(L.size()), cr(C.size());
    for (int n = 0; n < int(L.size()); ++n) {
        w.light_update(scene, L.data(), n, lr.data());
        if (mutation == 2 && n >= 2) lr[n].dvm *= 1.5;
    }
    for (int j = 1; j < int(C.size()); ++j) {
        w.camera_update(C.data(), j, cr.data());
        if (mutation == 1 && j == 1) cr[1].dvcm /= w.h(w.n_light);
    }
    const int t = int(C.size());
    if (tc.kind == kVM) return w.merge(scene, C.data(), cr.data(), t, L.data(), lr.data(), tc.a);
    const int sp = tc.a;
    if (sp == 0) return w.vc ? w.emission(scene, C.data(), cr.data(), t) : 1.0;
    if (sp == 1) return w.nee(scene, C.data(), cr.data(), t, L[0]);
    if (sp == k) return w.light_trace(scene, f.x[k], L.data(), lr.data(), sp);
    return w.connect(scene, C.data(), cr.data(), t, L.data(), lr.data(), sp);
}

}  // namespace

void vcm_mis_check(const Scene& scene, const Integrator& vcm, uint64_t seed, int n, int iteration, int mutation,
                   std::vector<float>& fast, std::vector<float>& brute, std::vector<int>& technique,
                   std::vector<float>& sums, std::vector<float>& own_fast, std::vector<float>& own_brute) {
    const std::unique_ptr<VcmMisProbe> probe = make_vcm_mis_probe(scene, vcm);
    if (probe->ppm()) throw std::invalid_argument("vcm_mis_check: ppm weighs nothing (its merges have weight 1)");
    const VcmWeights w = probe->weights(scene, iteration);
    const int max_depth = probe->max_depth();
    const int P = scene.sensor->width * scene.sensor->height;
    const bool importance = scene.sensor->has_importance();
    std::vector<PathVertex> cam, light;
    std::vector<VcmMis> crec, lrec;
    for (int g = 0; g < n; ++g) {
        Sampler cs(seed, uint64_t(g % P), uint64_t(g / P));
        Sampler ls(seed + 1, uint64_t(g), 0);
        probe->generate(scene, w, cs, ls, g % P, cam, crec, light, lrec);
        if (mutation == 1 && cam.size() > 1) {  // redo the camera quantities with the broken start
            for (int j = 1; j < int(cam.size()); ++j) {
                w.camera_update(cam.data(), j, crec.data());
                if (j == 1) crec[1].dvcm /= w.h(w.n_light);
            }
        }
        if (mutation == 2)
            for (int i = 2; i < int(light.size()); ++i) lrec[i].dvm *= 1.5;  // (downstream quantities unchanged)
        for (int t = 2; t <= int(cam.size()); ++t)
            for (int s = 0; s <= int(light.size()); ++s) {
                if (max_depth >= 0 && s + t - 1 > max_depth) continue;
                const PathVertex& z = cam[t - 1];
                if (s == 0 && !(z.infinite || (z.type == VType::Surface && z.emitter))) continue;
                if (s > 0 && (z.type != VType::Surface || !vcm_mergeable_end(z))) continue;
                if (s > 1 && (light[s - 1].type != VType::Surface || !vcm_mergeable_end(light[s - 1]))) continue;
                if (s == 1 && !light[0].emitter->is_delta() && !light[0].infinite &&
                    !(dot(light[0].it.n, z.it.p - light[0].it.p) > 0.f))
                    continue;
                if (s == 0 && t == 2) continue;  // the emitter seen directly: one technique
                const Full f = full_path(scene, w, cam, light, s, t);
                const int k = f.k;
                std::vector<Tech> techs;
                for (int sp = 0; sp <= k; ++sp) techs.push_back({kVC, sp});
                for (int i = 1; i < k; ++i) techs.push_back({kVM, i});
                std::vector<double> lp(techs.size());
                std::vector<bool> ok(techs.size());
                double top = -INFINITY;
                const double b = w.balance ? 1.0 : double(w.beta);
                for (size_t q = 0; q < techs.size(); ++q) {
                    double l = 0;
                    ok[q] = tech_density(scene, w, f, techs[q], importance, l);
                    lp[q] = b * l;
                    if (ok[q]) top = std::max(top, lp[q]);
                }
                if (!std::isfinite(top)) continue;
                double den = 0;
                for (size_t q = 0; q < techs.size(); ++q)
                    if (ok[q]) den += std::exp(lp[q] - top);
                double sum = 0;
                int own = -1;
                for (size_t q = 0; q < techs.size(); ++q) {
                    if (!ok[q]) continue;
                    double fw = fast_weight(scene, w, f, techs[q], mutation);
                    double bw = std::exp(lp[q] - top) / den;
                    fast.push_back(float(fw));
                    brute.push_back(float(bw));
                    technique.push_back(techs[q].kind == kVM ? 500000 + techs[q].a * 1000 + (k + 1 - techs[q].a)
                                                             : techs[q].a * 1000 + (k + 1 - techs[q].a));
                    sum += fw;
                    if (techs[q].kind == kVC && techs[q].a == s) own = int(q);
                }
                sums.push_back(float(sum));
                if (own < 0) continue;
                // The renderer's weight of (s, t) on the walked subpaths.
                double wf;
                float saved = light.empty() ? 0.f : light[0].pdf_fwd;
                if (s == 0) {
                    wf = w.vc ? w.emission(scene, cam.data(), crec.data(), t) : 1.0;
                } else if (s == 1) {
                    PathVertex y0 = light[0];
                    y0.pdf_fwd = float(f.p_nee);
                    wf = w.nee(scene, cam.data(), crec.data(), t, y0);
                } else {
                    wf = w.connect(scene, cam.data(), crec.data(), t, light.data(), lrec.data(), s);
                }
                if (!light.empty()) light[0].pdf_fwd = saved;
                own_fast.push_back(float(wf));
                own_brute.push_back(float(std::exp(lp[own] - top) / den));
            }
    }
}

}  // namespace rm
