// `vcm`, `bpm`, `ppm`: vertex connection and merging (Georgiev, Krivanek,
// Davidovic and Slusallek 2012, "Light Transport Simulation with Vertex
// Connection and Merging", and the tech. report "Implementing Vertex
// Connection and Merging" whose equation numbers the MIS lines cite),
// bidirectional photon mapping (Vorba 2011; merging at every camera vertex,
// MIS over the merge vertex) and progressive photon mapping (Hachisuka,
// Ogaki and Jensen 2008: merging at the first non-specular camera vertex,
// in the probabilistic form of Knaus and Zwicker 2011, a global radius per
// iteration instead of per-pixel statistics), one engine with SmallVCM's
// structure (src/vertexcm.hxx: kVcm, kBpm, kPpm).
//
// One iteration (one spp of the pass loop):
//   1. light_paths light subpaths on subpath.cpp's light walk; a visitor
//      gives each vertex its recursive MIS quantities (vcm_internal.h) as it
//      is made, and each vertex is stored once (the whole PathVertex, its
//      quantities beside it) for both connection and merging; vcm's light
//      tracing (t = 1) splats the non-delta vertices onto the film.
//   2. the non-delta surface vertices y_i, i >= 1, go into a range search
//      structure (range_search: a hash grid of cell size 2r, SmallVCM's
//      hashgrid.hxx layout, or photon_map.h's kd-tree);
//   3. each pixel's camera subpath (random_walk, as bdpt's); at each vertex
//      z_{t-1}: emission (s = 0), next event estimation (s = 1), connections
//      to the vertices of light path p mod light_paths (s >= 2), and merges
//      with the light vertices within r (vcm, bpm; ppm at its first
//      non-delta vertex only, weight 1).
// Radius: r_i = r_1 i^((alpha - 1) / 2) for iteration i = 1, 2, .. (the
// schedule of Georgiev et al. 2012, as SmallVCM's RunIteration computes it:
// radius / (iteration + 1)^(0.5 (1 - alpha))); Knaus and Zwicker 2011
// derive the same decay from r_{i+1}^2 / r_i^2 = (i + alpha) / (i + 1),
// whose product behaves as i^(alpha - 1); r_1 = radius times the scene's
// bounding-sphere radius. With alpha in (0, 1) the variance and the bias
// of the merges vanish together. The image is the mean of the iterations'
// estimates.
//
// The camera vertex: SmallVCM initialises the camera subpath's d^VCM to
// n_L / p_cam (the light-path count over the camera's per-pixel density),
// so that light tracing (n_L samples per camera path) and the camera's
// own technique compare at the right counts; the brute-force check of
// vcm_mis_check.cpp (tests/test_vcm.py) holds our weights to that and
// rejects the variant without n_L.
//
// Variance (res.variance): the sample variance over iterations of each
// iteration's estimate divided by their count (as sppm.cpp); with merging
// the iterations are independent but not identically distributed, and the
// estimate does not see the bias.
//
// Limits: no participating media (no volume merging); the MIS densities
// are the walk's (no Russian roulette in them, as bdpt); ppm's visible
// point is the first vertex with a smooth lobe, whose specular lobe (a
// plastic's coat) is not followed (sppm.cpp shares this).
#include <algorithm>
#include <chrono>
#include <climits>
#include <cmath>
#include <limits>
#include <stdexcept>

#include "estimators/vcm_internal.h"
#include "photon/photon_map.h"
#include "render/memory.h"
#include "render/pass_loop.h"
#include "render/registry.h"
#include "transport/camera_sample.h"

namespace rm {

// ---- the weights (vcm_internal.h) ----------------------------------------
//
// Notation: light vertices y_i with p->_i their density from the light side
// (pdf_fwd) and p<-_i from the camera side; camera vertices z_j with q<-_j
// (pdf_fwd, per pixel for z_1) and q->_j from the light side. A weight is
// 1 / (1 + w_light + w_camera) (tech. rep. eq. (37)), h the heuristic.

void VcmWeights::light_update(const Scene& scene, const PathVertex* path, int n, VcmMis* rec) const {
    const PathVertex& y = path[n];
    VcmMis& r = rec[n];
    if (n == 0) {
        // y_0 (tech. rep. eqs. (31)-(33); delta lights, which the camera
        // cannot hit, eqs. (48)-(50)): d^VCM = 1 / p->_0 when the camera can
        // hit the emitter (s = 0), no technique before it.
        r.dvcm = (vc && !y.emitter->is_delta()) ? 1.0 / h(remap0(y.pdf_fwd)) : 0.0;
        r.dvc = r.dvm = 0.0;
        return;
    }
    const PathVertex& prev = path[n - 1];
    const double pf = h(remap0(y.pdf_fwd));
    // The technique that connects y_{n-2} y_{n-1} (its d^VCM) needs y_{n-1}
    // non-delta; merging at y_{n-1} too. After a delta lobe at y_{n-1} only
    // the d^VC, d^VM chains carry on (eqs. (53)-(55)): its two densities
    // from y_{n-1} (pdf_fwd of y_n, pdf_rev of y_{n-2}) are the delta's,
    // stored as 0 by the walk and counted 1 (remap0, as bdpt).
    const double vcm_prev = prev.delta ? 0.0 : rec[n - 1].dvcm;
    const double rev = n >= 2 ? h(remap0(path[n - 2].pdf_rev)) : 0.0;
    const bool merge_prev = vm && n >= 2 && vcm_mergeable(prev);
    // d^VCM_n (eq. (34)): the connection y_{n-1} -> camera sampling y_n;
    // for n = 1 that is next event estimation, whose density of y_0 is
    // p_NEE, not the light walk's p_LE (SmallVCM: directPdfA /
    // emissionPdfW at the emitter).
    double first = n == 1 ? h(double(nee_over_emission(scene, path[0], y))) : 1.0;
    r.dvcm = (vc && !prev.delta) ? first / pf : 0.0;
    // d^VC_n (eq. (35)) and d^VM_n = d^VC_n / h(eta) (eq. (36)).
    r.dvc = (vcm_prev + rev * rec[n - 1].dvc + (merge_prev ? h(eta) : 0.0)) / pf;
    r.dvm = (vcm_prev / h(eta) + rev * rec[n - 1].dvm + (merge_prev ? 1.0 : 0.0)) / pf;
}

void VcmWeights::camera_update(const PathVertex* cam, int j, VcmMis* rec) const {
    const PathVertex& z = cam[j];
    VcmMis& r = rec[j];
    const double pf = h(remap0(z.pdf_fwd) * (j == 1 ? film_pixels : 1.0));
    if (j == 1) {
        // The camera vertex (eqs. (31)-(33), SmallVCM's GenerateCameraSample):
        // d^VCM = n_L / q<-_1, light tracing's count over the camera's
        // per-pixel density; no technique samples more from the camera.
        r.dvcm = (vc && !cam[0].delta) ? h(n_light) / pf : 0.0;
        r.dvc = r.dvm = 0.0;
        return;
    }
    const PathVertex& prev = cam[j - 1];
    const double vcm_prev = prev.delta ? 0.0 : rec[j - 1].dvcm;
    const double rev = j >= 3 ? h(remap0(cam[j - 2].pdf_rev)) : 0.0;
    const bool merge_prev = vm && vcm_mergeable(prev);
    r.dvcm = (vc && !prev.delta) ? 1.0 / pf : 0.0;                                       // eq. (34)
    r.dvc = (vcm_prev + rev * rec[j - 1].dvc + (merge_prev ? h(eta) : 0.0)) / pf;        // eq. (35)
    r.dvm = (vcm_prev / h(eta) + rev * rec[j - 1].dvm + (merge_prev ? 1.0 : 0.0)) / pf;  // eq. (36)
}

double VcmWeights::emission(const Scene& scene, const PathVertex* cam, const VcmMis* crec, int t) const {
    if (t == 2) return 1.0;  // the emitter seen directly: no other technique (SmallVCM)
    const PathVertex& z = cam[t - 1];
    const PathVertex& zm = cam[t - 2];
    PathVertex e = z;
    e.type = VType::Light;
    // p_NEE and p_LE of the emitter vertex; where one is 0, the other
    // (as nee_over_emission's ratio of 1).
    double p_nee = light_origin_pdf(scene, e, zm);
    double p_le = p_nee;
    if (!e.infinite) {
        double a = double(emission_origin_pdf(scene, *e.emitter, e.it.p));
        if (a > 0.0) p_le = a;
    }
    if (!(p_nee > 0.0)) p_nee = p_le;
    const double qm = h(remap0(emitter_pdf_to(scene, e, zm)));
    // Partial camera weight (eq. (43)); the light side has none (eq. (42)).
    const double wc = h(p_nee) * crec[t - 1].dvcm + h(p_le) * qm * crec[t - 1].dvc;
    return 1.0 / (1.0 + wc);
}

double VcmWeights::nee(const Scene& scene, const PathVertex* cam, const VcmMis* crec, int t,
                       const PathVertex& y0) const {
    const PathVertex& z = cam[t - 1];
    const PathVertex& zm = cam[t - 2];
    const double p_nee = y0.pdf_fwd;
    // eq. (44): the camera subpath hitting the emitter instead.
    double wl = 0.0;
    if (!y0.emitter->is_delta() && p_nee > 0.0) wl = h(remap0(pdf_to(scene, z, &zm, y0)) / p_nee);
    // eq. (45): the techniques with more light vertices, whose y_0 has the
    // light walk's density p_LE (1 / m each).
    const double m = h(double(nee_over_emission(scene, y0, z)));
    const double qf = remap0(emitter_pdf_to(scene, y0, z));
    double inner = crec[t - 1].dvcm;
    if (t >= 3) inner += h(remap0(pdf_to(scene, z, &y0, zm))) * crec[t - 1].dvc;
    double wc = h(qf) * inner + (vm && vcm_mergeable_end(z) ? h(eta * qf) : 0.0);
    wc /= m;
    return 1.0 / (1.0 + wl + wc);
}

double VcmWeights::connect(const Scene& scene, const PathVertex* cam, const VcmMis* crec, int t,
                           const PathVertex* light, const VcmMis* lrec, int s) const {
    const PathVertex& y = light[s - 1];
    const PathVertex& ym = light[s - 2];
    const PathVertex& z = cam[t - 1];
    const PathVertex& zm = cam[t - 2];
    const double pr1 = remap0(pdf_to(scene, z, &zm, y));  // p<-_{s-1}
    const double pr2 = remap0(pdf_to(scene, y, &z, ym));  // p<-_{s-2}
    const double qf1 = remap0(pdf_to(scene, y, &ym, z));  // q->_{t-1}
    // eq. (40)
    const double wl = h(pr1) * (lrec[s - 1].dvcm + h(pr2) * lrec[s - 1].dvc + (vm ? h(eta) : 0.0));
    // eq. (41)
    double inner = crec[t - 1].dvcm + (vm ? h(eta) : 0.0);
    if (t >= 3) inner += h(remap0(pdf_to(scene, z, &y, zm))) * crec[t - 1].dvc;
    const double wc = h(qf1) * inner;
    return 1.0 / (1.0 + wl + wc);
}

double VcmWeights::light_trace(const Scene& scene, const PathVertex& z0, const PathVertex* light, const VcmMis* lrec,
                               int s) const {
    const PathVertex& y = light[s - 1];
    const PathVertex& ym = light[s - 2];
    const double pr1 = remap0(film_pixels * camera_pdf_a(scene, z0, y));  // the camera's per-pixel density of y
    const double pr2 = remap0(pdf_to(scene, y, &z0, ym));
    // eq. (46): h(p_cam / n_L), light tracing's n_L samples; the camera side is 0 (eq. (47)).
    const double wl = h(pr1 / n_light) * (lrec[s - 1].dvcm + h(pr2) * lrec[s - 1].dvc + (vm ? h(eta) : 0.0));
    return 1.0 / (1.0 + wl);
}

double VcmWeights::merge(const Scene& scene, const PathVertex* cam, const VcmMis* crec, int t, const PathVertex* light,
                         const VcmMis* lrec, int i) const {
    const PathVertex& ym = light[i - 1];
    const PathVertex& z = cam[t - 1];
    const PathVertex& zm = cam[t - 2];
    // eq. (38): the camera BSDF at the merge point sampling y_{i-1}
    const double pr = remap0(pdf_to(scene, z, &zm, ym));
    const double wl = lrec[i].dvcm / h(eta) + h(pr) * lrec[i].dvm;
    // eq. (39): the camera BSDF sampled from the light's side towards z_{t-2}
    double wc = crec[t - 1].dvcm / h(eta);
    if (t >= 3) wc += h(remap0(pdf_to(scene, z, &ym, zm))) * crec[t - 1].dvm;
    return 1.0 / (1.0 + wl + wc);
}

namespace {

enum class Mode { Vcm, Bpm, Ppm };
enum class RangeSearch { HashGrid, KdTree };

std::unique_ptr<Integrator> make_vcm(ParamReader& p);
std::unique_ptr<Integrator> make_bpm(ParamReader& p);
std::unique_ptr<Integrator> make_ppm(ParamReader& p);

std::vector<ParamSpec> shared_params(bool mis) {
    std::vector<ParamSpec> v = {
        max_depth_param().described("longest path in segments"),
        rr_depth_param().described("subpath depth (segments) from which Russian roulette may stop a subpath"),
        hide_emitters_param(),
        ParamSpec::real("radius", 0.01,
                        "initial merging radius r_1, relative to the scene's bounding-sphere radius (SmallVCM's "
                        "radius factor)")
            .greater_than(0)
            .at_most(1),
        ParamSpec::real("alpha", 0.75, "radius reduction: r_i = r_1 i^((alpha - 1) / 2) (Georgiev et al. 2012)")
            .greater_than(0)
            .less_than(1),
        // at most 2^24: every vertex of an iteration's light paths is kept
        // (192 bytes each with its quantities, 4 to 5 per path on the
        // Cornell box, measured: about 15 GiB at the limit)
        ParamSpec::integer("light_paths", 0, "light subpaths per iteration")
            .at_least(1)
            .at_most(1 << 24)
            .with_special(int64_t(0), "the pixel count"),
        ParamSpec::string("range_search", "hash_grid", "the merge queries' structure").one_of({"hash_grid", "kd_tree"}),
        strategy_images_param().described(
            "keep one image per technique up to this path depth: connections (s, t) and merges (i, t) of light "
            "vertex y_i at camera vertex z_{t-1}"),
    };
    if (mis) {
        v.push_back(mis_param());
        v.push_back(mis_beta_param());
    }
    return v;
}

[[maybe_unused]] const bool kRegisteredVcm = register_estimator([] {
    EstimatorInfo e;
    e.name = "vcm";
    e.doc =
        "vertex connection and merging: bidirectional connections and photon merging combined by MIS "
        "(Georgiev et al. 2012)";
    e.params = shared_params(true);
    e.params.push_back(ParamSpec::boolean("connections", true, "the connection techniques (off: bpm)"));
    e.params.push_back(ParamSpec::boolean("merging", true, "the merging techniques (off: bidirectional path tracing)"));
    e.caps.driver = Driver::OwnPasses;
    e.caps.bias = Bias::Consistent;
    e.factory = make_vcm;
    return e;
}());

[[maybe_unused]] const bool kRegisteredBpm = register_estimator([] {
    EstimatorInfo e;
    e.name = "bpm";
    e.doc = "bidirectional photon mapping: merging at every camera vertex, MIS over the merge vertex (Vorba 2011)";
    e.params = shared_params(true);
    e.caps.driver = Driver::OwnPasses;
    e.caps.bias = Bias::Consistent;
    e.factory = make_bpm;
    return e;
}());

[[maybe_unused]] const bool kRegisteredPpm = register_estimator([] {
    EstimatorInfo e;
    e.name = "ppm";
    e.doc =
        "progressive photon mapping: merging at the first non-specular camera vertex, a global shrinking radius "
        "(Hachisuka et al. 2008; Knaus & Zwicker 2011)";
    e.params = shared_params(false);
    e.caps.driver = Driver::OwnPasses;
    e.caps.bias = Bias::Consistent;
    e.factory = make_ppm;
    return e;
}());

using Clock = std::chrono::steady_clock;

// SmallVCM's hash grid (hashgrid.hxx): cells of size 2r, hashed into as
// many buckets as points, a counting sort of the points by bucket (stable:
// each bucket keeps the points in index order); a query visits the (at
// most 8) buckets of the cells its radius touches, each once.
class HashGrid {
public:
    void build(const std::vector<Vec3>& pts, float r) {
        cell_ = 2.f * r;
        inv_ = 1.f / cell_;
        lo_ = Vec3(std::numeric_limits<float>::infinity());
        for (const Vec3& p : pts)
            for (int a = 0; a < 3; ++a) lo_[a] = std::min(lo_[a], p[a]);
        size_t n = std::max<size_t>(pts.size(), 1);
        start_.assign(n + 1, 0);
        order_.assign(pts.size(), 0);
        std::vector<uint32_t> bucket(pts.size());
        for (size_t k = 0; k < pts.size(); ++k) {
            bucket[k] = hash(cell_of(pts[k]));
            ++start_[bucket[k] + 1];
        }
        for (size_t b = 0; b < n; ++b) start_[b + 1] += start_[b];
        std::vector<uint32_t> fill(start_.begin(), start_.end() - 1);
        for (size_t k = 0; k < pts.size(); ++k) order_[fill[bucket[k]]++] = uint32_t(k);
        pts_ = &pts;
    }
    template <class Fn>
    void query(const Vec3& q, float r2, Fn fn) const {
        if (!pts_ || pts_->empty()) return;
        const float r = 0.5f * cell_;
        int c0[3], c1[3];
        for (int a = 0; a < 3; ++a) {
            c0[a] = cell_coord(q[a] - r, a);
            c1[a] = cell_coord(q[a] + r, a);
        }
        uint32_t seen[8];
        int n_seen = 0;
        for (int x = c0[0]; x <= c1[0]; ++x)
            for (int y = c0[1]; y <= c1[1]; ++y)
                for (int z = c0[2]; z <= c1[2]; ++z) {
                    uint32_t b = hash({x, y, z});
                    if (std::find(seen, seen + n_seen, b) != seen + n_seen) continue;
                    if (n_seen < 8) seen[n_seen++] = b;
                    for (uint32_t k = start_[b]; k < start_[b + 1]; ++k) {
                        uint32_t idx = order_[k];
                        if (length_sq((*pts_)[idx] - q) <= r2) fn(idx);
                    }
                }
    }

private:
    struct Cell {
        int x, y, z;
    };
    int cell_coord(float v, int a) const {
        float c = std::floor((v - lo_[a]) * inv_);
        return int(std::clamp(c, -1e9f, 1e9f));
    }
    Cell cell_of(const Vec3& p) const { return {cell_coord(p.x, 0), cell_coord(p.y, 1), cell_coord(p.z, 2)}; }
    uint32_t hash(Cell c) const {
        uint32_t v = (uint32_t(c.x) * 73856093u) ^ (uint32_t(c.y) * 19349663u) ^ (uint32_t(c.z) * 83492791u);
        return v % uint32_t(start_.size() - 1);
    }
    float cell_ = 1.f, inv_ = 1.f;
    Vec3 lo_;
    std::vector<uint32_t> start_, order_;
    const std::vector<Vec3>* pts_ = nullptr;
};

// One light-tracing contribution of an iteration, before its filter.
struct LtSplat {
    Vec2 film;
    int effect;
    Color value;
    int tech;      // its technique image (-1: none)
    float weight;  // its MIS weight
};

// The technique images of depth <= D: the connections in strategy_index
// order, then the merges (i, t) of depth d = i + t - 1, i = 1 .. d - 1.
inline int merge_index(int i, int t, int D) {
    int d = i + t - 1;
    return num_strategies(D) + (d - 1) * (d - 2) / 2 + (i - 1);
}
inline int num_techniques(int D) { return D > 0 ? num_strategies(D) + D * (D - 1) / 2 : 0; }

}  // namespace

class VcmIntegrator final : public Integrator {
    friend class VcmMisProbeImpl;

public:
    VcmIntegrator(ParamReader& p, Mode mode)
        : mode_(mode),
          max_depth_(p.get_int("max_depth")),
          rr_depth_(p.get_int("rr_depth")),
          hide_(p.get_bool("hide_emitters")),
          radius_(p.get_float("radius")),
          alpha_(p.get_float("alpha")),
          light_paths_(p.get_int("light_paths")),
          range_(p.get_string("range_search") == "kd_tree" ? RangeSearch::KdTree : RangeSearch::HashGrid),
          tech_depth_(p.get_int("strategy_images")) {
        if (mode != Mode::Ppm) {
            const std::string mis = p.get_string("mis");
            balance_ = mis == "balance";
            const float beta = p.get_float("beta");
            beta_ = mis == "uniform" ? 0.f : beta;  // h(x) = x^0: uniform weights
        }
        vc_ = mode == Mode::Vcm;
        vm_ = true;
        if (mode == Mode::Vcm) {
            vc_ = p.get_bool("connections");
            vm_ = p.get_bool("merging");
            if (!vc_ && !vm_) p.fail("merging", "connections and merging cannot both be off");
        }
    }

    void sample(const Scene&, Sampler&, const Ray&, EffectRadiance&, ThreadStats&) const override {
        throw std::logic_error("integrator '" + type + "' renders through its own driver");
    }
    RenderOutput drive(const Scene& scene, const RenderOptions& opts, const PollFn& poll) const override;

    class Passes;

private:
    int n_light(const Scene& scene) const {
        return light_paths_ > 0 ? light_paths_ : scene.sensor->width * scene.sensor->height;
    }
    // The radius of iteration `it` (0-based): r_1 (it + 1)^((alpha - 1) / 2).
    double iteration_radius(const Scene& scene, int it) const {
        Vec3 c;
        float R;
        scene.bounding_sphere(c, R);
        double r1 = double(radius_) * double(R);
        return std::max(r1 * std::pow(double(it + 1), 0.5 * (double(alpha_) - 1.0)), 1e-7 * double(R));
    }
    VcmWeights weights(const Scene& scene, int it) const {
        VcmWeights w;
        w.vc = vc_;
        w.vm = vm_;
        w.balance = balance_;
        w.beta = beta_;
        double r = iteration_radius(scene, it);
        w.n_light = n_light(scene);
        w.eta = double(kPi) * r * r * w.n_light;
        w.film_pixels = double(scene.sensor->width) * double(scene.sensor->height);
        return w;
    }
    Sampler light_sampler(uint64_t seed, uint64_t g, int it) const {
        return Sampler(mix64(seed + 0x76636d6c69676874ULL), g, uint64_t(it));
    }

    // A light subpath and its quantities (the visitor: each vertex's as it is made).
    void light_path(const Scene& scene, const VcmWeights& w, Sampler& sampler, std::vector<PathVertex>& light,
                    std::vector<VcmMis>& rec, ThreadStats& stats) const {
        rec.clear();
        auto update = [&](const std::vector<PathVertex>& p) {
            rec.resize(p.size());
            w.light_update(scene, p.data(), int(p.size()) - 1, rec.data());
            return true;
        };
        const VertexVisitor visit(update);
        EmissionSample es;
        int max_light = max_depth_ < 0 ? INT_MAX : max_depth_;  // y0 .. y_{max_depth - 1}
        if (!light_subpath(scene, sampler, max_light, rr_depth_, light, es, stats, &visit)) {
            light.clear();
            rec.clear();
        }
    }

    // The camera subpath of `pixel` and its quantities (ppm: up to its
    // first vertex with a smooth lobe).
    void camera_path(const Scene& scene, const VcmWeights& w, const FilterSampler& filter, Sampler& sampler, int pixel,
                     std::vector<PathVertex>& cam, std::vector<VcmMis>& rec, ThreadStats& stats) const {
        const Sensor& sensor = *scene.sensor;
        cam.clear();
        ++stats.paths;
        SensorRay sr = sample_camera_ray(sensor, filter, pixel, sampler);
        PathVertex z0;
        z0.type = VType::Camera;
        z0.it.p = sr.ray.o;
        z0.it.n = sr.n;
        z0.beta = sr.weight;
        z0.pdf_fwd = 1.f;
        z0.delta = !sensor.has_importance();
        cam.push_back(z0);
        int max_cam = max_depth_ < 0 ? INT_MAX : max_depth_ + 1;
        if (mode_ == Mode::Ppm) {
            auto at_smooth = [](const std::vector<PathVertex>& p) {
                const PathVertex& v = p.back();
                return !(v.type == VType::Surface && v.bsdf->has_smooth());
            };
            const VertexVisitor stop(at_smooth);
            random_walk(scene, sampler, sr.ray, sr.weight, TransportMode::Radiance, max_cam, rr_depth_, cam, stats,
                        &stop);
        } else {
            random_walk(scene, sampler, sr.ray, sr.weight, TransportMode::Radiance, max_cam, rr_depth_, cam, stats);
        }
        rec.assign(cam.size(), VcmMis());
        for (int j = 1; j < int(cam.size()); ++j) w.camera_update(cam.data(), j, rec.data());
    }

    Mode mode_;
    int max_depth_, rr_depth_;
    bool hide_;
    float radius_, alpha_;
    int light_paths_;
    RangeSearch range_;
    int tech_depth_;  // technique images up to this depth (0: none)
    bool balance_ = false;
    float beta_ = 2.f;
    bool vc_ = true, vm_ = true;
};

// The iterations on the pass loop (one per spp).
class VcmIntegrator::Passes final : public PassStep {
public:
    Passes(const VcmIntegrator& v, const Scene& scene)
        : v_(v),
          scene_(scene),
          filter_(scene.sensor_desc.rfilter, scene.sensor_desc.filter_radius, scene.sensor_desc.filter_stddev),
          W_(scene.sensor->width),
          H_(scene.sensor->height),
          sums_(size_t(W_) * size_t(H_)) {
        const size_t px = size_t(W_) * size_t(H_);
        // Light tracing's splats: the crop window's (by default the film's),
        // as the light driver's (camera samples stay inside it: camera_sample.cpp).
        const Sensor& sn = *scene.sensor;
        cx0_ = sn.crop_x, cx1_ = sn.crop_x + sn.crop_w, cy0_ = sn.crop_y, cy1_ = sn.crop_y + sn.crop_h;
        norm_x_ = splat_norms(filter_, W_, cx0_, cx1_);
        norm_y_ = splat_norms(filter_, H_, cy0_, cy1_);
        n_tech_ = num_techniques(v.tech_depth_);
        tech_iter_.assign(px * size_t(n_tech_) * 6, 0.0);
        tech_sum_.assign(px * size_t(n_tech_) * 6, 0.0);
        pms_.name = v.type;
        pms_.bytes_per_photon = double(sizeof(PathVertex) + sizeof(VcmMis));
    }

    int pass(PassLoop& loop, int s0, int s1) override {
        for (int s = s0; s < s1; ++s)
            if (!iteration(loop, s)) return s;
        return s1;
    }

    void develop(int n, std::vector<float>& image, std::vector<float>& variance,
                 std::vector<std::vector<float>>* effects) const override {
        sums_.develop(n, image, variance, effects);
    }

    void finish(RenderOutput& out) const override {
        if (v_.vm_) out.photon_maps.push_back(pms_);
        if (n_tech_ == 0) return;
        // The technique images (weighted, unweighted) over the iterations kept.
        const size_t px = size_t(W_) * size_t(H_);
        const int D = v_.tech_depth_;
        auto image = [&](int k, int off) {
            std::vector<float> img(3 * px, 0.f);
            if (sums_.passes() > 0)
                for (size_t p = 0; p < px; ++p)
                    for (int c = 0; c < 3; ++c)
                        img[3 * p + c] = float(tech_sum_[(p * n_tech_ + k) * 6 + off + c] / sums_.passes());
            return img;
        };
        for (int k = 0; k < num_strategies(D); ++k) {
            out.strategies.push_back(image(k, 0));
            out.strategies_unweighted.push_back(image(k, 3));
        }
        for (int d = 2; d <= D; ++d)
            for (int i = 1; i < d; ++i) {
                int k = merge_index(i, d + 1 - i, D);
                out.merge_keys.push_back({i, d + 1 - i});
                out.merges.push_back(image(k, 0));
                out.merges_unweighted.push_back(image(k, 3));
            }
    }

private:
    static constexpr size_t kItem = 256;  // light paths per work item

    struct Item {
        std::vector<PathVertex> v;
        std::vector<VcmMis> m;
        std::vector<uint32_t> len;  // vertices per path
        std::vector<LtSplat> splats;
    };

    bool iteration(PassLoop& loop, int it) {
        const Scene& scene = scene_;
        const VcmWeights w = v_.weights(scene, it);
        const int nl = v_.n_light(scene);
        const double r = v_.iteration_radius(scene, it);
        const float r2 = float(r * r);
        // 1. Light subpaths, in items of kItem paths, each on its own stream.
        const size_t n_items = (size_t(nl) + kItem - 1) / kItem;
        items_.resize(n_items);
        auto t0 = Clock::now();
        auto trace_item = [&](size_t i, int th) {
            Item& item = items_[i];
            item.v.clear();
            item.m.clear();
            item.len.clear();
            item.splats.clear();
            ThreadStats& stats = loop.stats(th);
            std::vector<PathVertex> light;
            std::vector<VcmMis> rec;
            size_t g1 = std::min(size_t(nl), (i + 1) * kItem);
            for (size_t g = i * kItem; g < g1; ++g) {
                if (loop.cancelled()) return;
                Sampler sampler = v_.light_sampler(loop.seed(), g, it);
                v_.light_path(scene, w, sampler, light, rec, stats);
                if (w.vc) light_trace(light, rec, w, sampler, stats, item.splats);
                item.v.insert(item.v.end(), light.begin(), light.end());
                item.m.insert(item.m.end(), rec.begin(), rec.end());
                item.len.push_back(uint32_t(light.size()));
            }
        };
        if (!loop.parallel_for(n_items, trace_item)) return false;
        // 2. The light vertices in path order, and the merge structure.
        lv_.clear();
        lm_.clear();
        start_.assign(1, 0);
        for (const Item& item : items_) {
            lv_.insert(lv_.end(), item.v.begin(), item.v.end());
            lm_.insert(lm_.end(), item.m.begin(), item.m.end());
            for (uint32_t n : item.len) start_.push_back(start_.back() + n);
        }
        pms_.trace_seconds += std::chrono::duration<double>(Clock::now() - t0).count();
        pms_.paths += uint64_t(nl);
        auto tb = Clock::now();
        merge_idx_.clear();
        merge_path_.clear();
        merge_pos_.clear();
        if (w.vm) {
            for (size_t g = 0; g + 1 < start_.size(); ++g)
                for (uint32_t k = start_[g] + 1; k < start_[g + 1]; ++k)
                    if (vcm_mergeable_end(lv_[k])) {
                        merge_idx_.push_back(k);
                        merge_path_.push_back(uint32_t(g));
                        merge_pos_.push_back(lv_[k].it.p);
                    }
            pms_.photons += merge_idx_.size();
            if (v_.range_ == RangeSearch::HashGrid) {
                grid_.build(merge_pos_, float(r));
            } else {
                std::vector<Photon> ph(merge_pos_.size());
                for (size_t k = 0; k < ph.size(); ++k) ph[k].p = merge_pos_[k];
                kd_ = PhotonMap();
                kd_.build(std::move(ph), loop.threads(), true);
            }
        }
        pms_.build_seconds += std::chrono::duration<double>(Clock::now() - tb).count();
        // 3. Camera subpaths, row by row, into this iteration's buffer.
        sums_.clear_pass();
        std::fill(tech_iter_.begin(), tech_iter_.end(), 0.0);
        auto row = [&](size_t y, int th) { camera_row(loop, it, int(y), w, nl, r2, loop.stats(th)); };
        if (!loop.parallel_for(size_t(H_), row)) return false;
        // 4. Light tracing's splats, in item order, and the commit.
        const double inv_nl = 1.0 / double(nl);
        for (const Item& item : items_)
            for (const LtSplat& sp : item.splats) splat(sp, inv_nl);
        sums_.commit();
        for (size_t k = 0; k < tech_iter_.size(); ++k) tech_sum_[k] += tech_iter_[k];
        return true;
    }

    // t = 1: each non-delta light vertex y_{s-1}, s >= 2, connected to the camera.
    void light_trace(const std::vector<PathVertex>& light, const std::vector<VcmMis>& rec, const VcmWeights& w,
                     Sampler& sampler, ThreadStats& stats, std::vector<LtSplat>& out) const {
        for (int s = 2; s <= int(light.size()); ++s) {
            if (v_.max_depth_ >= 0 && s > v_.max_depth_) break;
            const PathVertex& y = light[s - 1];
            if (y.type != VType::Surface || !y.connectible()) continue;
            ImportanceSample is;
            Color L = connect_to_sensor(scene_, y, is, stats, sampler);
            int effect = 0;
            PathVertex z0;
            z0.type = VType::Camera;
            z0.it.p = is.p;
            z0.it.n = is.n;
            z0.pdf_fwd = 1.f;
            effect = classify_vertices(&z0, 1, light.data(), s, true);
            if (is_black(L) || !v_.mask[effect]) continue;
            double wgt = w.light_trace(scene_, z0, light.data(), rec.data(), s);
            Color value = L * float(wgt);
            if (!keep_finite(stats, value)) continue;
            int tech = s <= v_.tech_depth_ ? strategy_index(s, 1) : -1;
            out.push_back({is.film, effect, value, tech, float(wgt)});
        }
    }

    // A light-tracing splat over the pixels whose filter covers it (film.h).
    void splat(const LtSplat& sp, double scale) {
        if (sp.film.x < float(cx0_) || sp.film.x > float(cx1_) || sp.film.y < float(cy0_) || sp.film.y > float(cy1_))
            return;
        for_each_splat_pixel(filter_, norm_x_, norm_y_, W_, 0, H_, sp.film.x, sp.film.y, [&](size_t p, double wgt) {
            double* e = sums_.pass_pixel(p) + sp.effect * 3;
            for (int c = 0; c < 3; ++c) e[c] += wgt * scale * double(sp.value[c]);
            if (sp.tech >= 0) add_tech(p, sp.tech, sp.value * float(wgt * scale), sp.weight);
        });
    }

    void camera_row(PassLoop& loop, int it, int y, const VcmWeights& w, int nl, float r2, ThreadStats& stats) {
        thread_local std::vector<PathVertex> cam;
        thread_local std::vector<VcmMis> crec;
        thread_local std::vector<Neighbour> nb;
        const Scene& scene = scene_;
        const EffectMask& mask = v_.mask;
        const int md = v_.max_depth_;
        const double vm_norm = 1.0 / (double(r2) * double(kPi) * double(nl));
        const int D = v_.tech_depth_;
        thread_local std::vector<std::pair<int, std::pair<Color, float>>> techs;
        for (int x = 0; x < W_; ++x) {
            const int p = y * W_ + x;
            Sampler sampler(loop.seed(), uint64_t(p), uint64_t(it));
            v_.camera_path(scene, w, filter_, sampler, p, cam, crec, stats);
            EffectRadiance er;
            techs.clear();
            // Adds a weighted contribution of technique k (-1: no image kept) to class cls.
            auto add = [&](int cls, const Color& value, int k, double wgt) {
                er.add(cls, value);
                if (k >= 0) techs.push_back({k, {value, float(wgt)}});
            };
            auto tech_of = [&](int s, int t) { return s + t - 1 <= D ? strategy_index(s, t) : -1; };
            const uint32_t lp = uint32_t(p % nl);
            const PathVertex* light = lv_.data() + start_[lp];
            const VcmMis* lrec = lm_.data() + start_[lp];
            const int nlv = int(start_[lp + 1] - start_[lp]);
            bool specular_prefix = true;  // z_1 .. z_{t-2} all delta
            for (int t = 2; t <= int(cam.size()); ++t) {
                const PathVertex& z = cam[t - 1];
                const int depth_cam = t - 1;  // segments from the camera to z
                // s = 0: the camera subpath found an emitter.
                bool emitter = z.infinite || (z.type == VType::Surface && z.emitter);
                if (emitter && (w.vc || specular_prefix) && !(hide_at(t))) {
                    int cls = classify_vertices(cam.data(), t, nullptr, 0, true);
                    if (mask[cls]) {
                        Color L(0.f);
                        if (z.infinite) {
                            for (const Emitter* env : scene.environment) L += env->eval_environment(-z.it.wi);
                            L = z.beta * L;
                        } else {
                            L = z.beta * z.emitter->eval(z.it, z.it.wi);
                        }
                        if (!is_black(L)) {
                            double wgt = w.vc ? w.emission(scene, cam.data(), crec.data(), t) : 1.0;
                            add(cls, L * float(wgt), tech_of(0, t), wgt);
                        }
                    }
                }
                if (z.type != VType::Surface) break;
                const bool conn = z.connectible();
                if (conn && w.vc) {
                    // s = 1: next event estimation (random numbers drawn whatever follows).
                    float u_pick = sampler.next_1d();
                    Vec2 u_l = sampler.next_2d();
                    float u_extra = sampler.next_1d();
                    if (md < 0 || depth_cam + 1 <= md) {
                        int cls = classify_vertices(cam.data(), t, nullptr, 1, true);
                        if (mask[cls]) {
                            PathVertex y0;
                            Color L = connect_emitter_sample(scene, z, u_pick, u_l, u_extra, sampler, stats, y0);
                            if (!is_black(L)) {
                                double wgt = w.nee(scene, cam.data(), crec.data(), t, y0);
                                add(cls, L * float(wgt), tech_of(1, t), wgt);
                            }
                        }
                    }
                    // s >= 2: connections to the light path of this pixel.
                    for (int s = 2; s <= nlv; ++s) {
                        if (md >= 0 && s + t - 1 > md) break;
                        const PathVertex& yv = light[s - 1];
                        if (yv.type != VType::Surface || !yv.connectible()) continue;
                        int cls = classify_vertices(cam.data(), t, light, s, true);
                        if (!mask[cls]) continue;
                        Color L = connect_vertices(z, yv, sampler, stats);
                        if (is_black(L)) continue;
                        double wgt = w.connect(scene, cam.data(), crec.data(), t, light, lrec, s);
                        add(cls, L * float(wgt), tech_of(s, t), wgt);
                    }
                }
                // Merging with the light vertices within r.
                if (conn && w.vm && !merge_idx_.empty() && (md < 0 || depth_cam + 1 <= md)) {
                    const Vec3 wi = z.it.to_local(z.it.wi);
                    BsdfContext ctx;
                    ctx.set(z.it);
                    auto process = [&](uint32_t q) {
                        const uint32_t k = merge_idx_[q];
                        const PathVertex& yv = lv_[k];
                        const uint32_t g = merge_path_[q];  // its light path
                        const int i = int(k - start_[g]);
                        if (md >= 0 && i + depth_cam > md) return;
                        const Vec3 wp = z.it.to_local(yv.it.wi);
                        const float c = std::fabs(wp.z);
                        if (!(c > 1e-7f)) return;
                        Color f = z.bsdf->eval(ctx, wi, wp) * (1.f / c);
                        if (is_black(f)) return;
                        const PathVertex* lpath = lv_.data() + start_[g];
                        int cls = classify_vertices(cam.data(), t, lpath, i, false);
                        if (!mask[cls]) return;
                        double wgt = v_.mode_ == Mode::Ppm
                                         ? 1.0
                                         : w.merge(scene, cam.data(), crec.data(), t, lpath, lm_.data() + start_[g], i);
                        add(cls, z.beta * f * yv.beta * float(wgt * vm_norm),
                            i + t - 1 <= D ? merge_index(i, t, D) : -1, wgt);
                    };
                    if (v_.range_ == RangeSearch::HashGrid) {
                        grid_.query(z.it.p, r2, process);
                    } else {
                        kd_.range(z.it.p, r2, nb);
                        for (const Neighbour& n : nb) process(kd_.ids()[n.idx]);
                    }
                    if (v_.mode_ == Mode::Ppm) break;
                }
                specular_prefix = specular_prefix && z.delta;
            }
            Color tot = er.total();
            if (!keep_finite(stats, tot)) continue;
            double* e = sums_.pass_pixel(size_t(p));
            for (int k = 0; k < kNumEffects; ++k)
                for (int c = 0; c < 3; ++c) e[k * 3 + c] += double(er.by_effect[k][c]);
            for (const auto& tc : techs) add_tech(size_t(p), tc.first, tc.second.first, tc.second.second);
        }
        loop.add_done(uint64_t(W_));
    }

    bool hide_at(int t) const { return v_.hide_ && t == 2; }

    // A contribution `value` (MIS weight `w` in it) to technique image k of pixel p.
    void add_tech(size_t p, int k, const Color& value, float w) {
        double* d = &tech_iter_[(p * size_t(n_tech_) + size_t(k)) * 6];
        double inv = w > 0.f ? 1.0 / double(w) : 0.0;
        for (int c = 0; c < 3; ++c) {
            d[c] += double(value[c]);
            d[3 + c] += double(value[c]) * inv;
        }
    }

    // y_{s-1} and z_{t-1} connected: f_L f_E / d^2 with visibility (Veach
    // 1997, eq. 10.8), as bdpt's.
    Color connect_vertices(const PathVertex& z, const PathVertex& y, Sampler& sampler, ThreadStats& stats) const {
        Vec3 d = y.it.p - z.it.p;
        float d2 = length_sq(d);
        if (!(d2 > 0.f)) return Color(0.f);
        float dist = std::sqrt(d2);
        d = d / dist;
        Color fz = scatter_value(z, d, TransportMode::Radiance);
        if (is_black(fz)) return Color(0.f);
        Color fy = scatter_value(y, -d, TransportMode::Importance);
        if (is_black(fy)) return Color(0.f);
        DirectSample ds;
        ds.p = y.it.p;
        ds.n = y.it.n;
        ds.eps = y.it.eps;
        ds.d = d;
        ds.dist = dist;
        Color tr = connection_transmittance(scene_, z, ds, sampler, stats);
        if (is_black(tr)) return Color(0.f);
        return z.beta * fz * tr * fy * y.beta / d2;
    }

    const VcmIntegrator& v_;
    const Scene& scene_;
    FilterSampler filter_;
    int W_, H_;
    int cx0_ = 0, cx1_ = 0, cy0_ = 0, cy1_ = 0;  // the crop window
    std::vector<double> norm_x_, norm_y_;
    PassSums sums_;
    int n_tech_ = 0;
    std::vector<double> tech_iter_, tech_sum_;  // [pixel][technique][weighted rgb, unweighted rgb]
    std::vector<Item> items_;
    std::vector<PathVertex> lv_;
    std::vector<VcmMis> lm_;
    std::vector<uint32_t> start_;
    std::vector<uint32_t> merge_idx_, merge_path_;  // merge candidates: vertex index, light path
    std::vector<Vec3> merge_pos_;
    HashGrid grid_;
    PhotonMap kd_;
    PhotonMapStats pms_;
};

RenderOutput VcmIntegrator::drive(const Scene& scene, const RenderOptions& opts, const PollFn& poll) const {
    // What an iteration holds (memory.h): the per-pixel sums, the light
    // vertices (each path's items and their concatenation; 5 vertices per
    // path, the Cornell box's 4 to 5 measured) and the merge structure.
    const int W = scene.sensor->width, H = scene.sensor->height;
    const double px = double(W) * double(H), nl = double(n_light(scene));
    const double vertex = double(sizeof(PathVertex) + sizeof(VcmMis));
    const int techs = num_techniques(tech_depth_);
    const std::string paths = "light_paths";
    check_memory(
        type, W, H,
        {{"per-pixel sums", px * 8.0 * (2.0 * kNumEffects * 3 + 6 + 12.0 * techs),
          techs > 0 ? "the resolution (film width, height) or strategy_images" : "the resolution (film width, height)"},
         {"light vertices (" + std::to_string(int64_t(nl)) + " light paths per iteration)", 2.0 * 5.0 * nl * vertex,
          paths},
         {"merge search",
          vm_ ? (range_ == RangeSearch::KdTree ? photon_map_build_bytes(4.0 * nl) : 4.0 * nl * (12.0 + 8.0 + 8.0))
              : 0.0,
          paths},
         output_memory(opts, W, H)});
    PassLoop loop(scene, opts, poll);
    Passes passes(*this, scene);
    return loop.run(passes);
}

namespace {

std::unique_ptr<Integrator> make_vcm(ParamReader& p) { return std::make_unique<VcmIntegrator>(p, Mode::Vcm); }
std::unique_ptr<Integrator> make_bpm(ParamReader& p) { return std::make_unique<VcmIntegrator>(p, Mode::Bpm); }
std::unique_ptr<Integrator> make_ppm(ParamReader& p) { return std::make_unique<VcmIntegrator>(p, Mode::Ppm); }

}  // namespace

// The test hook's view (vcm_internal.h): the production code, forwarded.
class VcmMisProbeImpl final : public VcmMisProbe {
public:
    VcmMisProbeImpl(const Scene& scene, const VcmIntegrator& v)
        : v_(v), filter_(scene.sensor_desc.rfilter, scene.sensor_desc.filter_radius, scene.sensor_desc.filter_stddev) {}
    VcmWeights weights(const Scene& scene, int it) const override { return v_.weights(scene, it); }
    void generate(const Scene& scene, const VcmWeights& w, Sampler& cs, Sampler& ls, int pixel,
                  std::vector<PathVertex>& cam, std::vector<VcmMis>& crec, std::vector<PathVertex>& light,
                  std::vector<VcmMis>& lrec) const override {
        ThreadStats stats;
        v_.light_path(scene, w, ls, light, lrec, stats);
        v_.camera_path(scene, w, filter_, cs, pixel, cam, crec, stats);
    }
    int max_depth() const override { return v_.max_depth_; }
    bool ppm() const override { return v_.mode_ == Mode::Ppm; }

private:
    const VcmIntegrator& v_;
    FilterSampler filter_;
};

std::unique_ptr<VcmMisProbe> make_vcm_mis_probe(const Scene& scene, const Integrator& vcm) {
    const auto* v = dynamic_cast<const VcmIntegrator*>(&vcm);
    if (!v) throw std::invalid_argument("vcm_mis_check: integrator '" + vcm.type + "' is not vcm, bpm or ppm");
    return std::make_unique<VcmMisProbeImpl>(scene, *v);
}

}  // namespace rm
