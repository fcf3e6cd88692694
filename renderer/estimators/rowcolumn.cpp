// `rowcolumn`: matrix row-column sampling (Hasan, Pellacini and Bala 2007,
// "Matrix Row-Column Sampling for the Many-Light Problem") on the VPLs of
// `vpl` (vpl_internal.h: the same light paths, camera samples and clamped
// contributions). The pass's lighting matrix A has one row per pixel (its
// gather points) and one column per VPL; the full VPL sum of a pixel is
// its row sum, which `vpl` computes. Here, per pass:
//   1. `rows` pixels, one drawn in each of `rows` equal runs of the pixel
//      index (stratified), and their full rows: the reduced matrix R
//      (rows x VPLs; each entry the sum of its RGB, one float), with a
//      shadow ray per entry;
//   2. the columns clustered by their reduced vectors rho_j (sec. 4 of the
//      paper): the cost of a cluster C is the sum over its pairs of
//      |rho_i| |rho_j| |rho_i / |rho_i| - rho_j / |rho_j||^2, which is
//      (sum |rho_j|)^2 - |sum rho_j|^2 (so a cluster's cost needs only its
//      two sums). First 2/3 of the clusters by sampling: centres drawn with
//      probability proportional to |rho_j|, each column assigned to the
//      centre of the nearest direction rho / |rho| (the paper's sampling
//      clustering, whose scaled centres all have the same norm); then the
//      costliest cluster split until there are `columns`: its members
//      projected on a random direction, sorted, cut where the two halves'
//      costs sum to the least (top-down splitting). Columns no sampled row
//      sees (|rho_j| = 0) form one cluster of their own;
//   3. one representative per cluster, drawn with probability w_j / W_C
//      (w_j = |rho_j|; the VPL's flux in the cluster of unseen columns),
//      rendered at every pixel with the weight W_C / w_j: the cluster's
//      total over its representative's share. Given the VPLs, each
//      cluster's estimate is unbiased for its full column sum at every
//      pixel, so the image's expectation is the full VPL sum's; the error
//      against it shrinks with `columns` (equal to it once every column is
//      its own cluster: columns >= the VPL count).
// res.stats["photon_maps"]["vpl"]: the VPLs and light paths of all passes,
// the seconds of tracing them and (build_seconds) of steps 1 and 2. The
// error against the full VPL sum per pixel: `vpl` with the same seed and
// parameters renders that sum from the same VPLs and camera samples
// (tests/test_vpl.py, benchmarks/studies/rowcolumn_scale.py).
// Bias: as vpl's without compensation (clamping; declared Biased).
#include <algorithm>
#include <chrono>
#include <cmath>
#include <numeric>
#include <queue>

#include "estimators/vpl_internal.h"
#include "render/memory.h"

namespace rm {

namespace {

using Clock = std::chrono::steady_clock;
double since(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }

std::unique_ptr<Integrator> make_rowcolumn(ParamReader& p);

[[maybe_unused]] const bool kRegistered = register_estimator([] {
    EstimatorInfo e;
    e.name = "rowcolumn";
    e.doc =
        "matrix row-column sampling on the VPLs of instant radiosity: sampled rows, clustered columns, one "
        "representative per cluster (Hasan, Pellacini & Bala 2007)";
    e.params = vpl_shared_params();
    e.params.push_back(ParamSpec::integer("rows", 32,
                                          "pixels whose full rows are computed per pass (the reduced "
                                          "matrix)")
                           .at_least(1)
                           .at_most(1 << 16));
    e.params.push_back(ParamSpec::integer("columns", 32, "clusters of VPLs per pass, one representative each")
                           .at_least(1)
                           .at_most(1 << 20));
    e.caps.driver = Driver::OwnPasses;
    e.caps.bias = Bias::Biased;                          // clamping, as vpl's
    e.caps.effects = effect_mask({kEmission, kDirect});  // as vpl's
    e.factory = make_rowcolumn;
    return e;
}());

class RowColumn final : public Integrator {
public:
    explicit RowColumn(ParamReader& p)
        : cfg_(read_vpl_config(p)), rows_(p.get_int("rows")), columns_(p.get_int("columns")) {}
    void sample(const Scene&, Sampler&, const Ray&, EffectRadiance&, ThreadStats&) const override {
        throw std::logic_error("integrator 'rowcolumn' renders through its own driver");
    }
    RenderOutput drive(const Scene& scene, const RenderOptions& opts, const PollFn& poll) const override;

    VplConfig cfg_;
    int rows_, columns_;
};

// x . y over n floats, in 8 independent partial sums (vectorisable without
// reassociation flags: the clustering's inner loop).
inline float dot_rows(const float* x, const float* y, int n) {
    float acc[8] = {0.f, 0.f, 0.f, 0.f, 0.f, 0.f, 0.f, 0.f};
    int q = 0;
    for (; q + 8 <= n; q += 8)
        for (int k = 0; k < 8; ++k) acc[k] += x[q + k] * y[q + k];
    float s = ((acc[0] + acc[1]) + (acc[2] + acc[3])) + ((acc[4] + acc[5]) + (acc[6] + acc[7]));
    for (; q < n; ++q) s += x[q] * y[q];
    return s;
}

// A cluster of columns and its two sums (cost = S^2 - |V|^2).
struct Cluster {
    std::vector<uint32_t> members;
    double cost = 0;
};

class RcPasses final : public PassStep {
public:
    RcPasses(const RowColumn& rc, const Scene& scene)
        : rc_(rc),
          scene_(scene),
          eng_(scene, rc.cfg_, rc.mask, rc.type),
          W_(scene.sensor->width),
          H_(scene.sensor->height),
          sums_(size_t(W_) * size_t(H_)) {
        const size_t px = size_t(W_) * size_t(H_);
        er_.resize(px);
        gp_.resize(px * kMaxGather);
        ngp_.assign(px, 0);
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
        if (!eng_.needs_vpls()) return;
        PhotonMapStats st = eng_.stats_out;
        st.build_seconds = t_rows_ + t_cluster_;  // the reduced matrix and the clustering
        out.photon_maps.push_back(st);
    }

private:
    bool iteration(PassLoop& loop, int s) {
        if (!eng_.trace(loop, s, vpls_)) return false;
        // Step 2 of vpl_internal.h: every pixel's camera sample and gather points.
        auto cam = [&](size_t y, int th) {
            ThreadStats& stats = loop.stats(th);
            for (int x = 0; x < W_; ++x) {
                const size_t p = y * size_t(W_) + size_t(x);
                Sampler sampler(loop.seed(), p, uint64_t(s));
                er_[p] = EffectRadiance();
                ngp_[p] = eng_.camera_sample(sampler, int(p), er_[p], &gp_[p * kMaxGather], stats);
            }
        };
        if (!loop.parallel_for(size_t(H_), cam)) return false;
        // 1.-3. of the top of the file.
        const size_t n = vpls_.size();
        reps_.clear();
        if (n > 0 && !choose_representatives(loop, s)) return false;
        sums_.clear_pass();
        auto row = [&](size_t y, int th) {
            ThreadStats& stats = loop.stats(th);
            for (int x = 0; x < W_; ++x) {
                if (loop.cancelled()) return;
                const size_t p = y * size_t(W_) + size_t(x);
                EffectRadiance er = er_[p];
                for (int k = 0; k < ngp_[p]; ++k) {
                    const GatherPoint& g = gp_[p * kMaxGather + k];
                    Color L(0.f);
                    for (const auto& rep : reps_)
                        L += rep.second * eng_.contribution(g.v, g.depth, vpls_[rep.first], stats);
                    er.add(g.cls, g.v.beta * L);
                }
                if (!keep_finite(stats, er.total())) continue;
                sums_.set(p, er);
            }
            loop.add_done(uint64_t(W_));
        };
        if (!loop.parallel_for(size_t(H_), row)) return false;
        sums_.commit();
        return true;
    }

    // Pixel p's full-row entry for VPL j: the sum of RGB over its gather points.
    float entry(size_t p, const Vpl& y, ThreadStats& stats) const {
        Color L(0.f);
        for (int k = 0; k < ngp_[p]; ++k) {
            const GatherPoint& g = gp_[p * kMaxGather + k];
            L += g.v.beta * eng_.contribution(g.v, g.depth, y, stats);
        }
        return L.x + L.y + L.z;
    }

    // Steps 1-3: reps_ = (VPL, weight) per cluster; false when cancelled.
    bool choose_representatives(PassLoop& loop, int s) {
        const size_t n = vpls_.size();
        const size_t c = size_t(rc_.columns_);
        if (c >= n) {  // every column its own cluster: the full sum
            for (size_t j = 0; j < n; ++j) reps_.push_back({uint32_t(j), 1.f});
            return true;
        }
        const size_t px = size_t(W_) * size_t(H_);
        const int r = rc_.rows_;
        Sampler rng(mix64(loop.seed() + 0x726f77636f6cULL), 0, uint64_t(s));
        // 1. Rows: one pixel in each of r equal runs of the pixel index.
        std::vector<size_t> rows(static_cast<size_t>(r));
        for (int k = 0; k < r; ++k)
            rows[size_t(k)] = std::min(px - 1, size_t((double(k) + double(rng.next_1d())) * double(px) / double(r)));
        auto t0 = Clock::now();
        R_.assign(n * size_t(r), 0.f);
        constexpr size_t kCols = 256;
        auto block = [&](size_t b, int th) {
            ThreadStats& stats = loop.stats(th);
            for (size_t j = b * kCols; j < std::min(n, (b + 1) * kCols); ++j) {
                if (loop.cancelled()) return;
                for (int k = 0; k < r; ++k) R_[j * size_t(r) + size_t(k)] = entry(rows[size_t(k)], vpls_[j], stats);
            }
        };
        if (!loop.parallel_for((n + kCols - 1) / kCols, block)) return false;
        t_rows_ += since(t0);
        auto t1 = Clock::now();
        std::vector<double> norm(n);
        for (size_t j = 0; j < n; ++j) {
            double a = 0;
            for (int k = 0; k < r; ++k) a += double(R_[j * r + k]) * double(R_[j * r + k]);
            norm[j] = std::sqrt(a);
        }
        std::vector<Cluster> clusters;
        if (!cluster(loop, rng, norm, c, clusters)) return false;
        // 3. A representative per cluster, with probability w_j / W_C.
        for (const Cluster& cl : clusters) {
            const bool unseen = norm[cl.members[0]] == 0.0;
            auto w = [&](uint32_t j) { return unseen ? double(max_component(vpls_[j].v.beta)) : norm[j]; };
            double W = 0;
            for (uint32_t j : cl.members) W += w(j);
            if (!(W > 0)) continue;
            double u = double(rng.next_1d()) * W, acc = 0;
            uint32_t pick = cl.members.back();
            for (uint32_t j : cl.members) {
                acc += w(j);
                if (u < acc && w(j) > 0) {
                    pick = j;
                    break;
                }
            }
            if (!(w(pick) > 0)) continue;
            const float scale = float(W / w(pick));
            reps_.push_back({pick, scale});
        }
        std::sort(reps_.begin(), reps_.end());
        t_cluster_ += since(t1);
        return true;
    }

    // Step 2: `c` clusters of the columns of R_.
    bool cluster(PassLoop& loop, Sampler& rng, const std::vector<double>& norm, size_t c, std::vector<Cluster>& out) {
        const size_t n = norm.size();
        const int r = rc_.rows_;
        std::vector<uint32_t> seen, unseen;
        for (size_t j = 0; j < n; ++j) (norm[j] > 0 ? seen : unseen).push_back(uint32_t(j));
        const size_t cs_total = std::max<size_t>(1, unseen.empty() ? c : c - 1);
        if (!unseen.empty()) out.push_back({unseen, 0.0});
        if (seen.empty()) return true;
        if (seen.size() <= cs_total) {
            for (uint32_t j : seen) out.push_back({{j}, 0.0});
            return true;
        }
        // Sampling clustering: centres drawn in proportion to |rho_j|.
        const size_t n_sample = std::max<size_t>(1, 2 * cs_total / 3);
        std::vector<double> cdf(seen.size());
        double acc = 0;
        for (size_t i = 0; i < seen.size(); ++i) cdf[i] = acc += norm[seen[i]];
        std::vector<uint32_t> centres;
        for (size_t k = 0; k < n_sample; ++k) {
            double u = double(rng.next_1d()) * acc;
            size_t i = size_t(std::upper_bound(cdf.begin(), cdf.end(), u) - cdf.begin());
            centres.push_back(seen[std::min(i, seen.size() - 1)]);
        }
        std::sort(centres.begin(), centres.end());
        centres.erase(std::unique(centres.begin(), centres.end()), centres.end());
        const size_t m = centres.size();
        std::vector<float> dir(m * size_t(r));
        for (size_t k = 0; k < m; ++k)
            for (int q = 0; q < r; ++q) dir[k * r + q] = float(R_[size_t(centres[k]) * r + q] / norm[centres[k]]);
        std::vector<uint32_t> assign(seen.size());
        constexpr size_t kChunk = 512;
        auto nearest = [&](size_t b, int) {
            for (size_t i = b * kChunk; i < std::min(seen.size(), (b + 1) * kChunk); ++i) {
                const float* x = &R_[size_t(seen[i]) * r];
                float best = -std::numeric_limits<float>::infinity();
                uint32_t arg = 0;
                for (size_t k = 0; k < m; ++k) {
                    const float* d = &dir[k * r];
                    float dp = dot_rows(x, d, r);
                    if (dp > best) best = dp, arg = uint32_t(k);
                }
                assign[i] = arg;
            }
        };
        if (!loop.parallel_for((seen.size() + kChunk - 1) / kChunk, nearest)) return false;
        std::vector<Cluster> cl(m);
        for (size_t i = 0; i < seen.size(); ++i) cl[assign[i]].members.push_back(seen[i]);
        // Top-down splitting of the costliest cluster.
        auto cmp = [](const std::pair<double, size_t>& a, const std::pair<double, size_t>& b) {
            return a.first < b.first || (a.first == b.first && a.second > b.second);
        };
        std::priority_queue<std::pair<double, size_t>, std::vector<std::pair<double, size_t>>, decltype(cmp)> heap(cmp);
        auto push = [&](Cluster&& k) {
            if (k.members.empty()) return;
            k.cost = cost(k.members, norm);
            cl.push_back(std::move(k));
            heap.push({cl.back().cost, cl.size() - 1});
        };
        std::vector<Cluster> initial = std::move(cl);
        cl.clear();
        for (Cluster& k : initial) push(std::move(k));
        size_t count = heap.size();
        while (count < cs_total && !heap.empty()) {
            auto [cost_top, idx] = heap.top();
            if (!(cost_top > 0) || cl[idx].members.size() < 2) break;
            heap.pop();
            Cluster a, b;
            split(cl[idx].members, norm, rng, a.members, b.members);
            cl[idx].members.clear();
            push(std::move(a));
            push(std::move(b));
            ++count;
        }
        for (Cluster& k : cl)
            if (!k.members.empty()) out.push_back(std::move(k));
        return true;
    }

    double cost(const std::vector<uint32_t>& mem, const std::vector<double>& norm) const {
        const int r = rc_.rows_;
        double S = 0;
        std::vector<double> V(size_t(r), 0.0);
        for (uint32_t j : mem) {
            S += norm[j];
            for (int q = 0; q < r; ++q) V[size_t(q)] += R_[size_t(j) * r + q];
        }
        double v2 = 0;
        for (double v : V) v2 += v * v;
        return std::max(0.0, S * S - v2);
    }

    // Splits `mem` along a random projection at the cut of least total cost.
    void split(const std::vector<uint32_t>& mem, const std::vector<double>& norm, Sampler& rng,
               std::vector<uint32_t>& a, std::vector<uint32_t>& b) const {
        const int r = rc_.rows_;
        std::vector<double> u(static_cast<size_t>(r));
        for (double& x : u) x = 2.0 * double(rng.next_1d()) - 1.0;
        std::vector<std::pair<double, uint32_t>> order;
        order.reserve(mem.size());
        for (uint32_t j : mem) {
            double p = 0;
            for (int q = 0; q < r; ++q) p += u[size_t(q)] * R_[size_t(j) * r + q];
            order.push_back({p / norm[j], j});
        }
        std::sort(order.begin(), order.end());
        // Totals, then the prefix sums S_L, V_L with |V_L|^2 and V.V_L kept as they grow.
        double S = 0;
        std::vector<double> V(size_t(r), 0.0), VL(size_t(r), 0.0);
        for (uint32_t j : mem) {
            S += norm[j];
            for (int q = 0; q < r; ++q) V[size_t(q)] += R_[size_t(j) * r + q];
        }
        double V2 = 0;
        for (double v : V) V2 += v * v;
        double SL = 0, VL2 = 0, VVL = 0, best = std::numeric_limits<double>::infinity();
        size_t cut = 1;
        for (size_t i = 0; i + 1 < order.size(); ++i) {
            const float* x = &R_[size_t(order[i].second) * r];
            double dot_l = 0, dot_v = 0, xx = 0;
            for (int q = 0; q < r; ++q) {
                dot_l += VL[size_t(q)] * x[q];
                dot_v += V[size_t(q)] * x[q];
                xx += double(x[q]) * x[q];
                VL[size_t(q)] += x[q];
            }
            SL += norm[order[i].second];
            VL2 += 2 * dot_l + xx;
            VVL += dot_v;
            const double SR = S - SL, VR2 = V2 - 2 * VVL + VL2;
            const double total = (SL * SL - VL2) + (SR * SR - VR2);
            if (total < best) best = total, cut = i + 1;
        }
        for (size_t i = 0; i < order.size(); ++i) (i < cut ? a : b).push_back(order[i].second);
        std::sort(a.begin(), a.end());
        std::sort(b.begin(), b.end());
    }

    const RowColumn& rc_;
    const Scene& scene_;
    VplEngine eng_;
    int W_, H_;
    PassSums sums_;
    std::vector<Vpl> vpls_;
    std::vector<EffectRadiance> er_;
    std::vector<GatherPoint> gp_;
    std::vector<int> ngp_;
    std::vector<float> R_;                          // the reduced matrix, column-major (rows_ per column)
    std::vector<std::pair<uint32_t, float>> reps_;  // (VPL, weight W_C / w_j) per cluster, by VPL index
    double t_rows_ = 0, t_cluster_ = 0;
};

RenderOutput RowColumn::drive(const Scene& scene, const RenderOptions& opts, const PollFn& poll) const {
    const int W = scene.sensor->width, H = scene.sensor->height;
    const double px = double(W) * double(H);
    const double vpls = 4.0 * double(cfg_.vpl_count);  // VPLs budgeted: 4 per light path
    check_memory(type, W, H,
                 {{"per-pixel sums", px * 8.0 * (2.0 * kNumEffects * 3 + 6), "the resolution (film width, height)"},
                  {"gather points", px * double(kMaxGather * sizeof(GatherPoint) + sizeof(EffectRadiance)),
                   "the resolution (film width, height)"},
                  {"VPLs", vpls * double(sizeof(Vpl)), "vpl_count"},
                  {"reduced matrix", vpls * double(rows_) * 4.0, "rows"},
                  output_memory(opts, W, H)});
    PassLoop loop(scene, opts, poll);
    RcPasses passes(*this, scene);
    return loop.run(passes);
}

std::unique_ptr<Integrator> make_rowcolumn(ParamReader& p) { return std::make_unique<RowColumn>(p); }

}  // namespace

}  // namespace rm
