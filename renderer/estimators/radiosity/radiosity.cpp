// `radiosity`: the finite-element solution of the rendering equation on
// diffuse scenes (Goral, Torrance, Greenberg and Battaile 1984), solved by
// progressive refinement (Cohen, Chen, Wallace and Greenberg 1988,
// "A Progressive Refinement Approach to Fast Radiosity Image Generation"),
// and displayed either per patch or by a final gather from the solution.
//
// 1. Patches (patches.h): every shape cut to a target edge length
//    (`patch_size`, or the size that gives about `max_patches`). Each
//    patch has two elements, its front and back side, each with the
//    albedo of its BSDF on that side (pi f(n, n)) and its emitted
//    radiosity E = pi Le (area emitters emit on the front only).
// 2. Form factors: the whole matrix, before the shooting (Cohen et al.
//    1988 compute a row per shot to save memory; here the rows must be
//    balanced together, step 3). As Wallace, Elmquist and Haines 1989 ("A
//    Ray Tracing Algorithm for Progressive Radiosity") a factor is
//    evaluated at the receiver's sample points y_t: the form factor from
//    the differential area at y_t to the other element's polygon in closed
//    form (Lambert's formula in vector form, Baum, Rushmeier and Winget
//    1989, "Improving Radiosity Solutions Through the Use of Analytically
//    Determined Form-Factors", eq. 5: F = 1 / (2 pi) sum_e beta_e
//    n . Gamma_e, the polygon first clipped to y's upper half-space),
//    times the visibility of one ray from y_t to a point of the other
//    element (Embree). Curved patches (sphere, disk) scale their corner
//    polygon's factor by area / polygon area. G_ij = A_i F_ij is the mean
//    of the estimates from both ends, so reciprocity (G symmetric) holds
//    exactly.
// 3. Conservation: an element from which at most 1 % of `kEscapeRays`
//    stratified cosine rays (and a ring at the horizon) leave the scene is
//    closed; the closed rows are balanced
//    to sum_j F_ij = 1 by a symmetric diagonal scaling of G (Sinkhorn-
//    Knopp, symmetric form), which keeps reciprocity, so a closed scene
//    neither loses nor gains power to form-factor error, and a uniform
//    closed furnace has the exact constant solution. An open row is only
//    capped at 1; its remainder 1 - sum_j F_ij escapes.
// 4. Shooting (Cohen et al. 1988, fig. 3): the element with the most
//    unshot power dPhi_i shoots it: each receiver j gets dPhi_i F_ij, keeps
//    rho_j of it as new radiosity and unshot power and absorbs the rest;
//    1 - sum_j F_ij escapes. Stops when the unshot power left is at most
//    `residual` times the emitted power. With a finite `max_depth` the
//    shooting goes by generations instead (Jacobi: every element shoots
//    the power of bounce g before any of bounce g + 1), so that the
//    solution holds exactly the paths of at most max_depth segments.
//    The books: emitted = absorbed + escaped + unshot, to rounding
//    (res.stats: emitted_power, absorbed_power, escaped_power,
//    unshot_power, residual, shots).
// 5. Display (`display`): "patch" shows B / pi of the element a camera
//    ray hits (piecewise constant: the mesh, shadow leaks and Mach bands
//    show); "vertex" interpolates it between the mesh vertices (below);
//    "gather" renders emission and direct light as `direct` does
//    (`direct_samples` light samples, unbiased) and the indirect light by `gather_rays`
//    cosine-sampled rays per sample that read the solution's reflected
//    radiosity where they land (the final gather of Reichert 1992 and
//    Lischinski, Tampieri and Greenberg 1993).
//    "vertex" (Cohen and Wallace 1993, "Radiosity and Realistic Image
//    Synthesis", ch. 9, rendering: element values averaged to the nodes,
//    then interpolated over each element): each mesh vertex gets, per side,
//    the area-weighted mean B_v = sum_p A_p B_p / sum_p A_p of the patches
//    that have it as a corner, and a hit reads sum_c w_c B_{v_c}, the
//    barycentric (sub-triangle) or bilinear (cell) weights w_c of its
//    patch's corners. A vertex joins only patches of one shape with the
//    same surface normal at that point (patches.h), so the edge between two
//    walls or two objects stays sharp: the radiosity is discontinuous there
//    and an average across it would blur light into shadow. A vertex on
//    the rim of its surface reads a plane fitted to the patches around it
//    instead of their mean (vertex_values). The emission
//    stays per element (constant on an emitter). The solution is the same;
//    only what the camera reads of it changes.
// 6. Hierarchical refinement (`hierarchical`, off by default; Hanrahan,
//    Salzman and Aupperle 1991, "A Rapid Hierarchical Radiosity
//    Algorithm"; Cohen and Wallace 1993, ch. 7): the patches of step 1 are
//    the roots of quadtrees (a mesh triangle splits at its edge midpoints;
//    sphere and disk cells are not split). Refine (their Refine): a pair of
//    elements r (receiver) and s (sender) is linked when the estimated
//    error of r's radiosity through it, rho_r B_s max(F_rs, F_sr) (their
//    BF refinement; F unoccluded from each centre to the other's polygon by
//    the closed form of step 2, B_s relative to the emitted power per unit
//    area), is at most `hr_epsilon`, or neither is larger than `min_area`;
//    otherwise the end that looks larger from the other is split and its
//    children are refined against the other end. A link's form factor is
//    the estimate of step 2 (the same function) at the smaller end's points
//    (always a curved cell's against a triangle; reciprocity converts). A link
//    partly occluded (some rays blocked) is refined at 1/8 of the threshold
//    in the next round (ours: the oracle cannot see shadows); rounds of
//    refine and solve repeat (at most 8) while any link changes, the oracle
//    reading the last solution. Solve (their SolveSystem): Jacobi steps of
//    gather (H_r = sum over r's links of F_rs B_s), push (a leaf's
//    irradiance is its own plus its ancestors'), B = E + rho H at the
//    leaves, pull (a parent's B is its children's area-weighted mean),
//    until the unshot power sum A (B_new - B_old) is at most `residual`,
//    or max_depth - 1 iterations. Conservation: a closed leaf's gathered
//    factors (its own links and its ancestors') are normalised to sum 1,
//    an open leaf's capped at 1 (no symmetric balancing: the links are not
//    reciprocal). Books per step: absorbed sum A (1 - rho) H, escaped
//    sum A B_old - sum A H, unshot as above (an identity: emitted =
//    absorbed + escaped + unshot). Displays "patch" and "gather" read the
//    leaf under the hit; "vertex" is refused (the leaves share no mesh
//    vertices).
// Effect classes: emission (E seen directly), direct (one reflection of
// the emission: the solution's first bounce, or light sampling under
// "gather"), indirect (the rest). Bias: discretisation (patch size, the
// form-factor points), the residual and, under "gather", only in the
// indirect class: declared biased.
#include "estimators/radiosity/radiosity.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <stdexcept>
#include <unordered_map>

#include "core/warp.h"
#include "estimators/radiosity/patches.h"
#include "render/pass_loop.h"
#include "render/registry.h"
#include "transport/common.h"

namespace rm {

namespace {

constexpr double kPiD = 3.14159265358979323846;
constexpr int kEscapeRays = 256;  // per element, over its sample points (plus a ring at the horizon)
// Hierarchical refinement: rounds of refine-and-solve at most, and the share
// of hr_epsilon at which a partly occluded link is refined.
constexpr int kMaxRounds = 8;
constexpr double kPartialShare = 0.125;

Vec3d unit(const Vec3d& v) {
    double l = length(v);
    return l > 0 ? v * (1.0 / l) : Vec3d();
}
Vec3d mul(const Vec3d& a, const Vec3d& b) { return {a.x * b.x, a.y * b.y, a.z * b.z}; }
double avg(const Vec3d& c) { return (c.x + c.y + c.z) / 3.0; }
Color to_color(const Vec3d& c) { return Color(float(c.x), float(c.y), float(c.z)); }

// The form factor from the differential area at y (unit normal ny) to the
// polygon v[0..nv) (Baum et al. 1989, eq. 5), the polygon first clipped to
// the half-space in front of y (Sutherland-Hodgman with one plane).
double point_polygon_factor(const Vec3d& y, const Vec3d& ny, const Vec3d* v, int nv) {
    Vec3d c[Patch::kMaxCorners + 2];
    int nc = 0;
    for (int i = 0; i < nv; ++i) {
        const Vec3d &a = v[i], &b = v[(i + 1) % nv];
        double da = dot(a - y, ny), db = dot(b - y, ny);
        if (da >= 0) c[nc++] = a;
        if ((da >= 0) != (db >= 0)) c[nc++] = a + (b - a) * (da / (da - db));
    }
    if (nc < 3) return 0.0;
    double sum = 0;
    for (int i = 0; i < nc; ++i) {
        Vec3d ua = unit(c[i] - y), ub = unit(c[(i + 1) % nc] - y);
        Vec3d cr = cross(ua, ub);
        double l = length(cr);
        if (!(l > 1e-14)) continue;  // a zero-length or collinear edge
        sum += std::atan2(l, dot(ua, ub)) * dot(cr, ny) / l;
    }
    double f = std::fabs(sum) / (2.0 * kPiD);
    return std::isfinite(f) ? std::min(f, 1.0) : 0.0;
}

struct Element {
    int patch = -1;
    int side = 0;  // 0 front, 1 back
    Vec3d rho, E;  // albedo, emitted radiosity (pi Le)
    bool shoots() const { return rho.x > 0 || rho.y > 0 || rho.z > 0 || E.x > 0 || E.y > 0 || E.z > 0; }
};

// Hierarchical radiosity (Hanrahan, Salzman and Aupperle 1991, "A Rapid
// Hierarchical Radiosity Algorithm"): a quadtree of elements over every
// side of a patch (a mesh triangle splits at its edge midpoints into 4;
// sphere and disk cells stay whole), links between elements at the level
// the oracle asks for, gathering over the links and push-pull.
struct HNode {
    Patch g;                      // geometry; g.first_point indexes Hierarchy::pts / nrm
    int root = 0;                 // its patch side (element 2 p + side), the root node's index
    int parent = -1, child = -1;  // child: the first of 4 contiguous children; -1: a leaf
    bool splittable = false;      // a triangle larger than min_area
    bool curved = false;          // a sphere's or disk's cell (its centre's tangent plane is not its plane)
};
struct HLink {
    int r = 0, s = 0;      // receiver, sender
    double F = 0;          // form factor F_rs (receiver-side estimate)
    bool partial = false;  // some of its visibility rays blocked, some not
};
struct Hierarchy {
    std::vector<HNode> nodes;  // nodes[e] for e < elements: the root of element e
    std::vector<Vec3d> pts, nrm;
    std::vector<HLink> links;
    std::vector<double> scale;  // per node: the normalisation of a leaf's gathered factors
    std::vector<char> closed;   // per root element
    double min_area = 0;
    int iterations = 0, rounds = 0;
    size_t leaves = 0;
};

struct Solution {
    PatchMesh mesh;
    std::vector<Element> el;
    // Reflected radiosity by bounce: direct (1), indirect (2 .. max_depth - 2,
    // or all >= 2 when unbounded), last (max_depth - 1 when that is >= 2).
    std::vector<Vec3d> Bd, Bi, Blast;
    // Display "vertex": per vertex v and side s (index 2 v + s) the
    // area-weighted mean of the direct and of the other reflected radiosity.
    std::vector<Vec3d> vBd, vBi;
    std::vector<double> G, esc;  // form factors F_ij (row i: i * N + j), escaping fraction of each row
    std::vector<char> closed;    // rows from which no escape ray left the scene
    int balance_iterations = 0;
    double emitted = 0, absorbed = 0, escaped = 0, unshot = 0, residual = 0;
    uint64_t shots = 0, rays = 0;
    double seconds = 0, patch_size = 0;
    bool hierarchical = false;
    Hierarchy h;
    // The element whose radiosity a value index e (into Bd, Bi, Blast) belongs
    // to: itself, or under hierarchical refinement the root of node e.
    size_t element_of(size_t e) const { return hierarchical ? size_t(h.nodes[e].root) : e; }
    std::vector<std::pair<std::string, double>> stats() const {
        std::vector<std::pair<std::string, double>> s = base_stats();
        if (hierarchical)
            s.insert(s.end(), {{"hr_elements", double(h.leaves)},
                               {"hr_nodes", double(h.nodes.size())},
                               {"hr_links", double(h.links.size())},
                               {"hr_iterations", double(h.iterations)},
                               {"hr_rounds", double(h.rounds)},
                               {"hr_min_area", h.min_area}});
        return s;
    }
    std::vector<std::pair<std::string, double>> base_stats() const {
        return {{"patches", double(mesh.patches.size())},
                {"elements", double(el.size())},
                {"patch_size", patch_size},
                {"shots", double(shots)},
                {"balance_iterations", double(balance_iterations)},
                {"closed_rows", double(std::count(closed.begin(), closed.end(), char(1)))},
                {"form_factor_rays", double(rays)},
                {"residual", residual},
                {"emitted_power", emitted},
                {"absorbed_power", absorbed},
                {"escaped_power", escaped},
                {"unshot_power", unshot},
                {"solve_seconds", seconds}};
    }
};

class RadiosityIntegrator final : public Integrator {
public:
    struct Config {
        std::string display;
        double patch_size = 0;
        int max_patches = 1000, ff_samples = 2, max_depth = -1, gather_rays = 8, direct_samples = 8;
        double residual = 1e-3;
        bool hierarchical = false;
        double hr_epsilon = 0.05, min_area = 0;
    };
    explicit RadiosityIntegrator(Config c) : c_(std::move(c)) {}

    void check_scene(const Scene& scene) const override {
        for (const auto& s : scene.shapes) {
            // Patches are cut from meshes, spheres and disks only (patches.cpp).
            if (!dynamic_cast<const Mesh*>(s.get()) && !dynamic_cast<const Sphere*>(s.get()) &&
                !dynamic_cast<const Disk*>(s.get()))
                throw std::invalid_argument("integrator 'radiosity' cannot render shape '" + s->id +
                                            "': it cuts patches from meshes, spheres and disks only, not from "
                                            "cylinders or shapegroup instances; use 'path' or 'bdpt'");
            if (s->bsdf < 0) continue;
            const Bsdf& b = *scene.bsdfs[size_t(s->bsdf)];
            if (b.flags() != kDiffuseReflection)
                throw std::invalid_argument("integrator 'radiosity' cannot render shape '" + s->id +
                                            "': its BSDF is not diffuse (radiosity solves diffuse reflection "
                                            "only; use 'path' or 'bdpt')");
            if (b.textured())
                throw std::invalid_argument("integrator 'radiosity' cannot render shape '" + s->id +
                                            "': its BSDF is textured (a patch has one reflectance; use 'path' "
                                            "or 'bdpt')");
        }
        for (const auto& e : scene.emitters) {
            if (e->is_delta() || e->is_infinite() || e->is_environment())
                throw std::invalid_argument("integrator 'radiosity' cannot render emitter '" + e->id +
                                            "': only area emitters (on shapes) are patches; use 'path' or "
                                            "'bdpt'");
            if (e->textured())
                throw std::invalid_argument("integrator 'radiosity' cannot render emitter '" + e->id +
                                            "': its radiance is textured (a patch has one emission; use 'path' "
                                            "or 'bdpt')");
        }
    }
    void sample(const Scene&, Sampler&, const Ray&, EffectRadiance&, ThreadStats&) const override {
        throw std::logic_error("integrator 'radiosity' renders through its own driver");
    }
    RenderOutput drive(const Scene& scene, const RenderOptions& opts, const PollFn& poll) const override;
    // Meshes and solves; false when cancelled.
    bool solve(PassLoop& loop, Solution& sol) const;
    void shade(const Scene& scene, const Solution& sol, Sampler& sampler, const Ray& ray, EffectRadiance& out,
               ThreadStats& stats) const;

private:
    void setup(const Scene& scene, Solution& sol) const;
    static void vertex_values(Solution& sol);
    double receiver_estimate(const Scene& scene, const Solution& sol, size_t j, size_t i, float scale,
                             uint64_t& rays) const;
    // The form-factor matrix (sol.G: F_ij at i * N + j), escape fractions; false when cancelled.
    bool form_factors(PassLoop& loop, Solution& sol, std::vector<uint64_t>& rays) const;
    // Hierarchical refinement (Hanrahan et al. 1991): links, gathering, push-pull; false when cancelled.
    bool solve_hierarchical(PassLoop& loop, Solution& sol) const;
    void refine(Solution& sol, int r, int s, double b_scale, bool partial, std::vector<HLink>& out) const;
    void split(Solution& sol, int n) const;
    // The node whose element holds the hit (its leaf under hierarchical refinement), or -1.
    int value_index(const Scene& scene, const Solution& sol, const Interaction& h) const;
    Config c_;
};

void RadiosityIntegrator::setup(const Scene& scene, Solution& sol) const {
    double size = c_.patch_size;
    if (size > 0) {
        size_t n = count_patches(scene, size);
        if (n > size_t(c_.max_patches))
            throw std::invalid_argument("integrator 'radiosity': patch_size " + std::to_string(size) + " makes " +
                                        std::to_string(n) + " patches, more than max_patches " +
                                        std::to_string(c_.max_patches) + "; raise max_patches or patch_size");
    } else {
        size = patch_size_for(scene, size_t(c_.max_patches));
    }
    sol.patch_size = size;
    sol.mesh = build_patches(scene, size, c_.ff_samples);
    const size_t P = sol.mesh.patches.size();
    sol.el.resize(2 * P);
    BsdfContext ctx;
    for (size_t p = 0; p < P; ++p) {
        const Patch& q = sol.mesh.patches[p];
        const Shape& sh = *scene.shapes[size_t(q.shape)];
        for (int side = 0; side < 2; ++side) {
            Element& e = sol.el[2 * p + size_t(side)];
            e.patch = int(p);
            e.side = side;
            const float z = side ? -1.f : 1.f;
            if (sh.bsdf >= 0) {
                Color f = scene.bsdfs[size_t(sh.bsdf)]->eval(ctx, Vec3(0, 0, z), Vec3(0, 0, z));
                e.rho = Vec3d(f * kPi);
            }
            if (sh.emitter >= 0) {
                Interaction it;
                it.p = q.c.f();
                it.n = q.n.f();
                it.sh = Frame(it.n);
                Color le = scene.emitters[size_t(sh.emitter)]->eval(it, it.n * z);
                e.E = Vec3d(le * kPi);
            }
        }
    }
    size_t N = sol.el.size();
    sol.Bd.assign(N, Vec3d());
    sol.Bi.assign(N, Vec3d());
    sol.Blast.assign(N, Vec3d());
}

// One side of a surface piece as the form factor sees it: the geometry
// (polygon, centre, front normal, areas), the side (+1 front, -1 back) and
// its k sample points and front normals. Patches of the uniform mesh and
// the elements of the hierarchical quadtrees are both read through it.
struct SideView {
    const Patch* p;
    double side;
    const Vec3d* pts;
    const Vec3d* nrm;
};

// The receiver-side estimate of A_r F_rs for the receiver r gathering from
// the sender s: a_r times the mean over r's k points y_t of the
// point-to-polygon factor to s's polygon (Baum et al. 1989, eq. 5), each
// times the visibility of one ray to a point of s (paired by index, shifted
// by `pair`). With a_r = 1 it is the form factor F_rs itself; `blocked`
// (if given) counts the rays that were occluded.
double receiver_factor(const Scene& scene, const SideView& snd, const SideView& rcv, int k, size_t pair, double a_r,
                       float scale, uint64_t& rays, int* blocked = nullptr) {
    const Patch& pi = *snd.p;
    const double si = snd.side, sj = rcv.side;
    const Vec3d ni = pi.n * si;
    auto eps_at = [&](const Vec3d& p) { return 1e-5f * scale + 4e-6f * max_component(abs(p.f())) + 1e-30f; };
    double acc = 0;
    for (int s = 0; s < k; ++s) {
        const Vec3d& y = rcv.pts[s];
        const Vec3d ny = rcv.nrm[s] * sj;
        if (!(dot(y - pi.c, ni) > 0)) continue;  // behind the shooter's side
        double f = point_polygon_factor(y, ny, pi.v, pi.nv);
        if (!(f > 0)) continue;
        const uint32_t xs = uint32_t((size_t(s) + pair) % size_t(k));
        const Vec3d& x = snd.pts[xs];
        const Vec3d nx = snd.nrm[xs] * si;
        Vec3d o = y + ny * double(eps_at(y)), to = x + nx * double(eps_at(x));
        Vec3d d = to - o;
        double dist = length(d);
        ++rays;
        if (dist > 0) {
            Ray r;
            r.o = o.f();
            r.d = (d * (1.0 / dist)).f();
            r.tmin = 0.f;
            r.tmax = float(dist) * (1.f - 1e-5f);
            if (scene.occluded(r)) {
                if (blocked) ++*blocked;
                continue;
            }
        }
        acc += f;
    }
    double g = acc / k * pi.poly_scale * a_r;
    return std::isfinite(g) ? g : 0.0;
}

// Whether the side `v` is closed: at most 1 % of about kEscapeRays
// stratified cosine-distributed rays from its k points (and a ring just
// above the horizon) leave the scene (rays slipping through the seams
// between touching shapes must not open a closed box).
bool side_is_closed(const Scene& scene, const SideView& v, int k, float R, uint64_t& rays) {
    const double si = v.side;
    int q = std::max(1, int(std::lround(std::sqrt(double(kEscapeRays) / k))));
    int cast = 0, escaped = 0;
    for (int s = 0; s < k; ++s) {
        const Vec3d& x = v.pts[s];
        Vec3 nx = (v.nrm[s] * si).f();
        Frame fr(nx);
        // q x q cosine-distributed directions, then a ring just above the
        // horizon (where a cell-centred grid never looks: an open
        // scene's light may leave only at grazing angles).
        for (int a = 0; a < q + 1; ++a)
            for (int b = 0; b < q; ++b) {
                Vec3 w;
                if (a < q) {
                    w = fr.to_world(warp::square_to_cosine_hemisphere(Vec2((a + 0.5f) / q, (b + 0.5f) / q)));
                } else {
                    float phi = 2.f * kPi * (b + 0.5f) / q, ct = 0.02f, st = std::sqrt(1.f - ct * ct);
                    w = fr.to_world(Vec3(st * std::cos(phi), st * std::sin(phi), ct));
                }
                Ray r;
                r.o = (x + Vec3d(nx) * double(1e-5f * R + 4e-6f * max_component(abs(x.f())))).f();
                r.d = w;
                ++rays;
                ++cast;
                if (!scene.occluded(r)) ++escaped;
            }
    }
    return escaped * 100 <= cast;
}

SideView side_view(const PatchMesh& M, const Element& e) {
    const Patch& p = M.patches[size_t(e.patch)];
    return {&p, e.side ? -1.0 : 1.0, &M.pts[p.first_point], &M.nrm[p.first_point]};
}

// The receiver-side estimate of A_j F_ji for element j receiving from element i.
double RadiosityIntegrator::receiver_estimate(const Scene& scene, const Solution& sol, size_t j, size_t i, float scale,
                                              uint64_t& rays) const {
    const PatchMesh& M = sol.mesh;
    const Element &ei = sol.el[i], &ej = sol.el[j];
    return receiver_factor(scene, side_view(M, ei), side_view(M, ej), M.k, i + j, M.patches[size_t(ej.patch)].area,
                           scale, rays);
}

bool RadiosityIntegrator::form_factors(PassLoop& loop, Solution& sol, std::vector<uint64_t>& rays) const {
    const Scene& scene = loop.scene();
    const PatchMesh& M = sol.mesh;
    const size_t N = sol.el.size();
    Vec3 c;
    float R;
    scene.bounding_sphere(c, R);
    sol.G.assign(N * N, 0.0);
    sol.closed.assign(N, 0);
    // Symmetric by construction: G_ij = G_ji = the mean of the two
    // receiver-side estimates of A_i F_ij = A_j F_ji (reciprocity exact).
    bool done = loop.parallel_for(N, [&](size_t i, int t) {
        const Element& ei = sol.el[i];
        for (size_t j = i + 1; j < N; ++j) {
            if (sol.el[j].patch == ei.patch) continue;
            // The estimate whose points sample the smaller element (its
            // error shrinks with the sampled element's size; the other
            // end's polygon is integrated exactly); equal areas: the mean.
            const double ai = M.patches[size_t(ei.patch)].area, aj = M.patches[size_t(sol.el[j].patch)].area;
            double g;
            if (aj < ai * (1 - 1e-9))
                g = receiver_estimate(scene, sol, j, i, R, rays[size_t(t)]);
            else if (ai < aj * (1 - 1e-9))
                g = receiver_estimate(scene, sol, i, j, R, rays[size_t(t)]);
            else
                g = 0.5 * (receiver_estimate(scene, sol, j, i, R, rays[size_t(t)]) +
                           receiver_estimate(scene, sol, i, j, R, rays[size_t(t)]));
            sol.G[i * N + j] = g;
        }
        // Escape test: stratified cosine-distributed rays from i's points.
        sol.closed[i] = side_is_closed(scene, side_view(M, ei), M.k, R, rays[size_t(t)]) ? 1 : 0;
    });
    if (!done) return false;
    for (size_t i = 0; i < N; ++i)
        for (size_t j = i + 1; j < N; ++j) sol.G[j * N + i] = sol.G[i * N + j];
    // Closed rows (nothing escapes from the element) must pass on all of
    // their power: symmetric diagonal scaling G -> D G D (Knight 2008, "The
    // Sinkhorn-Knopp algorithm", the symmetric iteration d <- sqrt(d t /
    // (G d))) until sum_j G_ij = A_i on every closed row; the symmetry,
    // and with it reciprocity, stays. Open rows keep d_i = 1.
    std::vector<double> d(N, 1.0), Gd(N);
    auto area = [&](size_t i) { return M.patches[size_t(sol.el[i].patch)].area; };
    for (int it = 0; it < 300; ++it, ++sol.balance_iterations) {
        double worst = 0;
        for (size_t i = 0; i < N; ++i) {
            double sum = 0;
            const double* row = &sol.G[i * N];
            for (size_t j = 0; j < N; ++j) sum += row[j] * d[j];
            Gd[i] = sum;
            if (sol.closed[i] && sum > 0) worst = std::max(worst, std::fabs(d[i] * sum / area(i) - 1.0));
        }
        if (worst < 1e-12) break;
        for (size_t i = 0; i < N; ++i)
            if (sol.closed[i] && Gd[i] > 0) d[i] = std::sqrt(d[i] * area(i) / Gd[i]);
    }
    for (size_t i = 0; i < N; ++i)
        for (size_t j = 0; j < N; ++j) sol.G[i * N + j] *= d[i] * d[j];
    // Form factors F_ij = G_ij / A_i; an open row summing over 1 (estimation
    // error) is scaled to 1; the rest of a row escapes.
    sol.esc.assign(N, 0.0);
    for (size_t i = 0; i < N; ++i) {
        double* row = &sol.G[i * N];
        double S = 0;
        const double inv = 1.0 / area(i);
        for (size_t j = 0; j < N; ++j) S += (row[j] *= inv);
        if (S > 1.0) {
            for (size_t j = 0; j < N; ++j) row[j] /= S;
            S = 1.0;
        }
        sol.esc[i] = std::max(0.0, 1.0 - S);
    }
    return true;
}

void RadiosityIntegrator::vertex_values(Solution& sol) {
    const PatchMesh& M = sol.mesh;
    const size_t V = M.vertex_count, P = M.patches.size();
    // The corner c of patch p counts once per vertex (a pole or the disk's
    // centre is two corners of one cell).
    auto first_at = [&](size_t p, int c) {
        const int v = M.corner_vertex[4 * p + size_t(c)];
        if (v < 0) return false;
        for (int d = 0; d < c; ++d)
            if (M.corner_vertex[4 * p + size_t(d)] == v) return false;
        return true;
    };
    // Vertex -> its patches (compressed rows).
    std::vector<uint32_t> start(V + 1, 0), adj;
    for (size_t p = 0; p < P; ++p)
        for (int c = 0; c < 4; ++c)
            if (first_at(p, c)) ++start[size_t(M.corner_vertex[4 * p + size_t(c)]) + 1];
    for (size_t v = 0; v < V; ++v) start[v + 1] += start[v];
    adj.resize(start[V]);
    {
        std::vector<uint32_t> fill(start.begin(), start.end() - 1);
        for (size_t p = 0; p < P; ++p)
            for (int c = 0; c < 4; ++c)
                if (first_at(p, c)) adj[fill[size_t(M.corner_vertex[4 * p + size_t(c)])]++] = uint32_t(p);
    }
    // Boundary vertices: on an edge that only one patch has (the rim of a
    // shape's plane: a wall's edge, a crease, a T-junction's long side).
    std::vector<char> boundary(V, 0);
    {
        std::unordered_map<uint64_t, int> edges;
        auto each_edge = [&](size_t p, auto&& f) {
            static const int tri[3][2] = {{0, 1}, {1, 2}, {2, 0}}, cell[4][2] = {{0, 1}, {1, 3}, {3, 2}, {2, 0}};
            const bool is_tri = M.corner_vertex[4 * p + 3] < 0;
            for (int e = 0; e < (is_tri ? 3 : 4); ++e) {
                const int* ab = is_tri ? tri[e] : cell[e];
                int a = M.corner_vertex[4 * p + size_t(ab[0])], b = M.corner_vertex[4 * p + size_t(ab[1])];
                if (a < 0 || b < 0 || a == b) continue;
                f(a, b, uint64_t(uint32_t(std::min(a, b))) << 32 | uint32_t(std::max(a, b)));
            }
        };
        for (size_t p = 0; p < P; ++p) each_edge(p, [&](int, int, uint64_t k) { ++edges[k]; });
        for (size_t p = 0; p < P; ++p)
            each_edge(p, [&](int a, int b, uint64_t k) {
                if (edges[k] == 1) boundary[size_t(a)] = boundary[size_t(b)] = 1;
            });
    }
    sol.vBd.assign(2 * V, Vec3d());
    sol.vBi.assign(2 * V, Vec3d());
    auto value = [&](size_t p, size_t side, bool direct) {
        const size_t e = 2 * p + side;
        return direct ? sol.Bd[e] : sol.Bi[e] + sol.Blast[e];
    };
    std::vector<uint32_t> ring;
    for (size_t v = 0; v < V; ++v) {
        if (start[v] == start[v + 1]) continue;
        // Interior: the area-weighted mean of the patches at the vertex.
        double wsum = 0;
        for (uint32_t k = start[v]; k < start[v + 1]; ++k) wsum += M.patches[adj[k]].area;
        for (size_t side = 0; side < 2; ++side)
            for (int direct = 0; direct < 2; ++direct) {
                Vec3d acc;
                for (uint32_t k = start[v]; k < start[v + 1]; ++k)
                    acc = acc + value(adj[k], side, direct) * M.patches[adj[k]].area;
                (direct ? sol.vBd : sol.vBi)[2 * v + side] = wsum > 0 ? acc * (1.0 / wsum) : Vec3d();
            }
        if (!boundary[v]) continue;
        // Boundary: the mean would be the value about half a patch inside;
        // instead the plane B(x) = a + g . (x - v) fitted by area-weighted
        // least squares to the patch centres of the vertex's two rings of
        // patches, read at the vertex (a), kept >= 0. Too few or collinear
        // centres (a rim corner with one patch): the mean stays.
        ring.clear();
        for (uint32_t k = start[v]; k < start[v + 1]; ++k)
            for (int c = 0; c < 4; ++c) {
                const int u = M.corner_vertex[4 * size_t(adj[k]) + size_t(c)];
                if (u < 0) continue;
                for (uint32_t m = start[size_t(u)]; m < start[size_t(u) + 1]; ++m) ring.push_back(adj[m]);
            }
        std::sort(ring.begin(), ring.end());
        ring.erase(std::unique(ring.begin(), ring.end()), ring.end());
        const Vec3d n = unit(M.vnrm[v]);
        const Vec3d t1 = unit(std::fabs(n.x) > 0.5 ? cross(n, Vec3d(0, 1, 0)) : cross(n, Vec3d(1, 0, 0)));
        const Vec3d t2 = cross(n, t1);
        double h2 = 0, W = 0;
        for (uint32_t p : ring) h2 += M.patches[p].area, W += M.patches[p].area;
        const double h = std::sqrt(h2 / double(ring.size()));
        if (!(h > 0) || !(W > 0) || ring.size() < 3) continue;
        double A[3][3] = {};
        for (uint32_t p : ring) {
            const Vec3d d = M.patches[p].c - M.vpos[v];
            const double w = M.patches[p].area / W, r[3] = {1.0, dot(d, t1) / h, dot(d, t2) / h};
            for (int a = 0; a < 3; ++a)
                for (int b = 0; b < 3; ++b) A[a][b] += w * r[a] * r[b];
        }
        auto det3 = [](const double m[3][3]) {
            return m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1]) -
                   m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0]) +
                   m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0]);
        };
        const double det = det3(A);
        if (!(std::fabs(det) > 1e-6)) continue;
        for (size_t side = 0; side < 2; ++side)
            for (int direct = 0; direct < 2; ++direct) {
                double out[3];
                for (int ch = 0; ch < 3; ++ch) {
                    double rhs[3] = {};
                    for (uint32_t p : ring) {
                        const Vec3d d = M.patches[p].c - M.vpos[v];
                        const Vec3d b = value(p, side, direct);
                        const double bc = ch == 0 ? b.x : ch == 1 ? b.y : b.z;
                        const double w = M.patches[p].area / W, r[3] = {1.0, dot(d, t1) / h, dot(d, t2) / h};
                        for (int a = 0; a < 3; ++a) rhs[a] += w * r[a] * bc;
                    }
                    double Ax[3][3];  // Cramer: the first column replaced by rhs
                    for (int a = 0; a < 3; ++a)
                        for (int b = 0; b < 3; ++b) Ax[a][b] = b == 0 ? rhs[a] : A[a][b];
                    const double x = det3(Ax) / det;
                    out[ch] = std::isfinite(x) ? std::max(0.0, x) : 0.0;
                }
                (direct ? sol.vBd : sol.vBi)[2 * v + side] = Vec3d(out[0], out[1], out[2]);
            }
    }
}

bool RadiosityIntegrator::solve(PassLoop& loop, Solution& sol) const {
    auto t0 = std::chrono::steady_clock::now();
    setup(loop.scene(), sol);
    if (c_.hierarchical) {
        if (!solve_hierarchical(loop, sol)) return false;
        sol.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
        return true;
    }
    const size_t N = sol.el.size();
    const double bytes = double(N) * double(N) * sizeof(double);
    if (bytes > 3e9)
        throw std::invalid_argument("integrator 'radiosity': " + std::to_string(sol.mesh.patches.size()) +
                                    " patches need " + std::to_string(bytes / 1e9) +
                                    " GB of form factors; lower max_patches or raise patch_size");
    std::vector<uint64_t> rays(size_t(loop.threads()), 0);
    if (!form_factors(loop, sol, rays)) return false;
    std::vector<Vec3d> unshot_e(N), unshot_r(N);
    double emitted = 0;
    for (size_t i = 0; i < N; ++i) {
        const Patch& p = sol.mesh.patches[size_t(sol.el[i].patch)];
        unshot_e[i] = sol.el[i].E * p.area;
        emitted += avg(unshot_e[i]);
    }
    sol.emitted = emitted;
    double absorbed = 0, escaped = 0;
    // Shoots element i's unshot power (emitted part pe, reflected pr) into
    // the next unshot pool `next` and the radiosity bin of each receiver.
    auto shoot = [&](size_t i, const Vec3d& pe, const Vec3d& pr, std::vector<Vec3d>& next,
                     std::vector<Vec3d>& bin_r) -> bool {
        const double* row = &sol.G[i * N];
        ++sol.shots;
        const Vec3d P = pe + pr;
        escaped += avg(P) * sol.esc[i];
        for (size_t j = 0; j < N; ++j) {
            double f = row[j];
            if (f == 0) continue;
            const Element& ej = sol.el[j];
            const double Aj = sol.mesh.patches[size_t(ej.patch)].area;
            Vec3d got = P * f, kept = mul(got, ej.rho);
            absorbed += avg(got) - avg(kept);
            next[j] = next[j] + kept;
            sol.Bd[j] = sol.Bd[j] + mul(pe * f, ej.rho) * (1.0 / Aj);
            bin_r[j] = bin_r[j] + mul(pr * f, ej.rho) * (1.0 / Aj);
        }
        return true;
    };
    const double target = c_.residual * emitted;
    if (c_.max_depth < 0) {
        // Progressive refinement: the most unshot power first (ties: lowest index).
        const uint64_t max_shots = uint64_t(std::max<size_t>(1000, 200 * N));
        while (sol.shots < max_shots) {
            size_t best = N;
            double best_p = 0, left = 0;
            for (size_t i = 0; i < N; ++i) {
                double p = avg(unshot_e[i]) + avg(unshot_r[i]);
                left += p;
                if (p > best_p) best_p = p, best = i;
            }
            if (best == N || left <= target) break;
            Vec3d pe = unshot_e[best], pr = unshot_r[best];
            unshot_e[best] = unshot_r[best] = Vec3d();
            if (!shoot(best, pe, pr, unshot_r, sol.Bi)) return false;
        }
    } else {
        // Generations: bounce g's power all shot before bounce g + 1's.
        // Power of bounce g (0: emission) lands in bounce g + 1's bin:
        // 1 direct, 2 .. D - 2 indirect, D - 1 last; D - 1 is the last shot.
        std::vector<Vec3d> cur = unshot_e, next(N);
        unshot_e.assign(N, Vec3d());
        for (int g = 0; g + 1 <= c_.max_depth - 1; ++g) {
            double left = 0;
            for (size_t i = 0; i < N; ++i) left += avg(cur[i]);
            if (left <= target && g > 0) break;
            next.assign(N, Vec3d());
            std::vector<Vec3d>& bin = (g + 1 == c_.max_depth - 1 && g + 1 >= 2) ? sol.Blast : sol.Bi;
            for (size_t i = 0; i < N; ++i) {
                if (avg(cur[i]) <= 0) continue;
                bool ok = g == 0 ? shoot(i, cur[i], Vec3d(), next, bin) : shoot(i, Vec3d(), cur[i], next, bin);
                if (!ok) return false;
            }
            cur.swap(next);
        }
        unshot_r = cur;
    }
    double left = 0;
    for (size_t i = 0; i < N; ++i) left += avg(unshot_e[i]) + avg(unshot_r[i]);
    sol.absorbed = absorbed;
    sol.escaped = escaped;
    sol.unshot = left;
    sol.residual = emitted > 0 ? left / emitted : 0.0;
    for (uint64_t r : rays) sol.rays += r;
    sol.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    return true;
}

// Whether r and s can exchange light at all: some corner of each lies
// strictly in front of the other's side (coplanar or back-to-back pieces
// have no form factor). A curved cell's side is not a plane: it may see
// what lies behind its centre's tangent plane, so it is not tested.
bool facing(const HNode& r, double sr, const HNode& s, double ss, double tol) {
    auto front = [&](const Patch& a, double sa, const Patch& b) {
        const Vec3d n = a.n * sa;
        for (int i = 0; i < b.nv; ++i)
            if (dot(b.v[i] - a.c, n) > tol) return true;
        return false;
    };
    return (r.curved || front(r.g, sr, s.g)) && (s.curved || front(s.g, ss, r.g));
}

// Splits triangle node n at its edge midpoints into 4 children, each with
// the m^2 sample points build_patches gives a triangle (the centroids of its
// m x m similar sub-triangles); they start from n's radiosity (the oracle's).
void RadiosityIntegrator::split(Solution& sol, int n) const {
    Hierarchy& h = sol.h;
    const int m = c_.ff_samples;
    const Patch g = h.nodes[size_t(n)].g;
    const Vec3d a = g.v[0], b = g.v[1], c = g.v[2];
    const Vec3d ab = (a + b) * 0.5, bc = (b + c) * 0.5, ca = (c + a) * 0.5;
    const Vec3d tri[4][3] = {{a, ab, ca}, {ab, b, bc}, {ca, bc, c}, {ab, bc, ca}};
    h.nodes[size_t(n)].child = int(h.nodes.size());
    for (int k = 0; k < 4; ++k) {
        HNode ch;
        ch.root = h.nodes[size_t(n)].root;
        ch.parent = n;
        ch.g.shape = g.shape;
        ch.g.nv = 3;
        for (int i = 0; i < 3; ++i) ch.g.v[i] = tri[k][i];
        ch.g.area = g.area * 0.25;
        ch.g.n = g.n;
        ch.g.c = (tri[k][0] + tri[k][1] + tri[k][2]) * (1.0 / 3.0);
        ch.g.poly_scale = 1.0;
        ch.g.first_point = uint32_t(h.pts.size());
        const Vec3d g1 = (tri[k][1] - tri[k][0]) * (1.0 / m), g2 = (tri[k][2] - tri[k][0]) * (1.0 / m);
        for (int s = 0; s < m; ++s)
            for (int t = 0; t < m - s; ++t) {
                h.pts.push_back(tri[k][0] + g1 * (s + 1.0 / 3.0) + g2 * (t + 1.0 / 3.0));
                h.nrm.push_back(g.n);
                if (s + t <= m - 2) {
                    h.pts.push_back(tri[k][0] + g1 * (s + 2.0 / 3.0) + g2 * (t + 2.0 / 3.0));
                    h.nrm.push_back(g.n);
                }
            }
        ch.splittable = ch.g.area > h.min_area;
        h.nodes.push_back(ch);
        for (std::vector<Vec3d>* v : {&sol.Bd, &sol.Bi, &sol.Blast}) v->push_back((*v)[size_t(n)]);
    }
    h.scale.resize(h.nodes.size(), 1.0);
}

// Hanrahan et al. 1991's Refine, with their radiosity-weighted ("BF")
// oracle: the error of receiver r's radiosity
// through the link is about rho_r B_s F, F estimated unoccluded both ways
// by the point-to-polygon closed form from each centre to the other's
// polygon (F_rs large: s looks large from r, split s; F_sr large: split r).
// Below hr_epsilon (B_s relative to b_scale, the emitted power spread over
// all surfaces: a typical radiosity), or with neither end splittable
// (min_area), r and s are linked. A link found partly occluded (a shadow
// boundary crosses it) is refined at kPartialShare of the threshold (our
// rule: the oracle is unoccluded and would not see the shadow).
void RadiosityIntegrator::refine(Solution& sol, int r, int s, double b_scale, bool partial,
                                 std::vector<HLink>& out) const {
    Hierarchy& h = sol.h;
    const HNode &nr = h.nodes[size_t(r)], &ns = h.nodes[size_t(s)];
    const Element &er = sol.el[size_t(nr.root)], &es = sol.el[size_t(ns.root)];
    const double sr = er.side ? -1.0 : 1.0, ss = es.side ? -1.0 : 1.0;
    const bool split_r = nr.splittable, split_s = ns.splittable;
    const double w = b_scale > 0 ? avg(er.rho) * avg(sol.Bd[size_t(s)] + sol.Bi[size_t(s)] + es.E) / b_scale : 0.0;
    double f_rs = 0, f_sr = 0;
    if (w > 0 && (split_r || split_s)) {
        f_rs = point_polygon_factor(nr.g.c, nr.g.n * sr, ns.g.v, ns.g.nv) * ns.g.poly_scale;
        f_sr = point_polygon_factor(ns.g.c, ns.g.n * ss, nr.g.v, nr.g.nv) * nr.g.poly_scale;
    }
    if (!(w * std::max(f_rs, f_sr) > c_.hr_epsilon * (partial ? kPartialShare : 1.0))) {
        out.push_back({r, s, 0.0});
        return;
    }
    if (out.size() > size_t(50'000'000))
        throw std::invalid_argument(
            "integrator 'radiosity': hierarchical refinement made more than 5e7 links; "
            "raise hr_epsilon or min_area");
    const double tol = 1e-9 * std::sqrt(std::max(nr.g.area, ns.g.area));
    if ((f_rs >= f_sr && split_s) || !split_r) {
        if (h.nodes[size_t(s)].child < 0) split(sol, s);
        const int c0 = h.nodes[size_t(s)].child;
        for (int k = 0; k < 4; ++k)
            if (facing(h.nodes[size_t(r)], sr, h.nodes[size_t(c0 + k)], ss, tol))
                refine(sol, r, c0 + k, b_scale, false, out);
    } else {
        if (h.nodes[size_t(r)].child < 0) split(sol, r);
        const int c0 = h.nodes[size_t(r)].child;
        for (int k = 0; k < 4; ++k)
            if (facing(h.nodes[size_t(c0 + k)], sr, h.nodes[size_t(s)], ss, tol))
                refine(sol, c0 + k, s, b_scale, false, out);
    }
}

bool RadiosityIntegrator::solve_hierarchical(PassLoop& loop, Solution& sol) const {
    const Scene& scene = loop.scene();
    sol.hierarchical = true;
    Hierarchy& h = sol.h;
    const PatchMesh& M = sol.mesh;
    const size_t N = sol.el.size();
    Vec3 bc;
    float R;
    scene.bounding_sphere(bc, R);
    std::vector<uint64_t> rays(size_t(loop.threads()), 0);
    // The roots: every patch side as it is (a copy of its points).
    double largest = 0;
    for (size_t e = 0; e < N; ++e) {
        const Patch& p = M.patches[size_t(sol.el[e].patch)];
        HNode n;
        n.g = p;
        n.root = int(e);
        n.g.first_point = uint32_t(h.pts.size());
        for (int t = 0; t < M.k; ++t) {
            h.pts.push_back(M.pts[p.first_point + uint32_t(t)]);
            h.nrm.push_back(M.nrm[p.first_point + uint32_t(t)]);
        }
        n.splittable = M.cuts[size_t(p.shape)].kind == 0 && p.nv == 3;
        n.curved = M.cuts[size_t(p.shape)].kind != 0;
        if (n.splittable) largest = std::max(largest, p.area);
        h.nodes.push_back(n);
    }
    // min_area 0: 4 levels below the largest triangle (1/256 of its area).
    h.min_area = c_.min_area > 0 ? c_.min_area : largest / 256.0;
    for (HNode& n : h.nodes) n.splittable = n.splittable && n.g.area > h.min_area;
    h.scale.assign(N, 1.0);
    // Closed roots (the escape test of the uniform mesh); their leaves inherit it.
    h.closed.assign(N, 0);
    if (!loop.parallel_for(N, [&](size_t e, int t) {
            h.closed[e] = side_is_closed(scene, side_view(M, sol.el[e]), M.k, R, rays[size_t(t)]) ? 1 : 0;
        }))
        return false;
    double total_area = 0, emitted = 0;
    for (size_t e = 0; e < N; ++e) {
        emitted += avg(sol.el[e].E) * M.patches[size_t(sol.el[e].patch)].area;
        if (sol.el[e].side == 0) total_area += M.patches[size_t(sol.el[e].patch)].area;
    }
    sol.emitted = emitted;
    const double b_scale = total_area > 0 ? emitted / total_area : 0.0;
    // Per node: B (radiosity), the reflected part split as the effect
    // classes need it; the oracle reads the current solution (Bd + Bi + E).
    std::vector<Vec3d> Rr, Rold, Hown, Hd;
    auto view = [&](int n) {
        const HNode& x = h.nodes[size_t(n)];
        return SideView{&x.g, sol.el[size_t(x.root)].side ? -1.0 : 1.0, &h.pts[x.g.first_point],
                        &h.nrm[x.g.first_point]};
    };
    const int max_rounds = kMaxRounds;
    std::vector<HLink> next, fresh;
    for (int round = 0; round < max_rounds; ++round) {
        sol.Bd.resize(h.nodes.size());
        sol.Bi.resize(h.nodes.size());
        sol.Blast.resize(h.nodes.size());
        // 1. Refine (Hanrahan et al. 1991): the first round from every
        //    pair of root elements that face each other, later rounds every
        //    link again against the solution of the round before.
        next.clear();
        fresh.clear();
        size_t changed = 0;
        if (round == 0) {
            const double tol0 = 1e-9;
            for (size_t r = 0; r < N; ++r)
                for (size_t s = 0; s < N; ++s) {
                    if (sol.el[r].patch == sol.el[s].patch) continue;
                    const double sr = sol.el[r].side ? -1.0 : 1.0, ss = sol.el[s].side ? -1.0 : 1.0;
                    const double tol = tol0 * std::sqrt(std::max(h.nodes[r].g.area, h.nodes[s].g.area));
                    if (facing(h.nodes[r], sr, h.nodes[s], ss, tol)) refine(sol, int(r), int(s), b_scale, false, fresh);
                }
            changed = 1;
        } else {
            for (const HLink& l : h.links) {
                const size_t before = fresh.size();
                refine(sol, l.r, l.s, b_scale, l.partial, fresh);
                if (fresh.size() == before + 1 && fresh.back().r == l.r && fresh.back().s == l.s) {
                    fresh.pop_back();  // kept as it was: its factor is known
                    next.push_back(l);
                } else {
                    ++changed;
                }
            }
        }
        if (!changed) break;
        h.rounds = round + 1;
        // 2. The new links' form factors, in parallel (each depends only on
        //    its own pair): as the uniform mesh, estimated at the points of
        //    the smaller end, F_rs = A_s F_sr / A_r by reciprocity; but at a
        //    sphere's or disk's cell (never split) whenever the other end is
        //    a triangle, whose polygon is exact (a cell's chords are not).
        if (!loop.parallel_for(fresh.size(), [&](size_t i, int t) {
                HLink& l = fresh[i];
                int blocked = 0;
                const HNode &nr = h.nodes[size_t(l.r)], &ns = h.nodes[size_t(l.s)];
                const double ar = nr.g.area, as = ns.g.area;
                const bool cr = nr.curved, cs = ns.curved;
                const size_t pair = size_t(l.r) + size_t(l.s);
                if (cs != cr ? cs : as < ar * (1 - 1e-9))
                    l.F =
                        receiver_factor(scene, view(l.r), view(l.s), M.k, pair, as, R, rays[size_t(t)], &blocked) / ar;
                else
                    l.F = receiver_factor(scene, view(l.s), view(l.r), M.k, pair, 1.0, R, rays[size_t(t)], &blocked);
                l.partial = blocked > 0 && l.F > 0;
            }))
            return false;
        for (const HLink& l : fresh)
            if (l.F > 0) next.push_back(l);
        // Links in a fixed order (receiver, sender): the gather's sums do not
        // depend on how the rounds found them.
        std::sort(next.begin(), next.end(),
                  [](const HLink& a, const HLink& b) { return a.r != b.r ? a.r < b.r : a.s < b.s; });
        h.links.swap(next);
        // 3. Conservation: a closed leaf's factors (its own links and its
        //    ancestors') sum to 1; an open leaf's at most 1.
        const size_t Nn = h.nodes.size();
        std::vector<double> fsum(Nn, 0.0);
        for (const HLink& l : h.links) fsum[size_t(l.r)] += l.F;
        h.leaves = 0;
        for (size_t n = 0; n < Nn; ++n) {
            const HNode& x = h.nodes[n];
            if (x.parent >= 0) fsum[n] += fsum[size_t(x.parent)];
            if (x.child >= 0) continue;
            ++h.leaves;
            const double f = fsum[n];
            h.scale[n] = (h.closed[size_t(x.root)] && f > 0) || f > 1.0 ? 1.0 / f : 1.0;
        }
        // 4. Solve by Jacobi iteration (Hanrahan et al. 1991:
        //    gather over links, push the gathered irradiance down to the
        //    leaves, B = E + rho H there, pull the area-weighted mean up).
        //    Iteration g holds the paths of g reflections: max_depth D takes
        //    D - 1 of them; unbounded, until the unshot power is at most
        //    `residual` of the emitted.
        auto gather = [&](const std::vector<Vec3d>& Bsrc, bool with_e, std::vector<Vec3d>& Hleaf) {
            Hown.assign(Nn, Vec3d());
            for (const HLink& l : h.links) {
                const Vec3d b = with_e ? Bsrc[size_t(l.s)] + sol.el[size_t(h.nodes[size_t(l.s)].root)].E
                                       : sol.el[size_t(h.nodes[size_t(l.s)].root)].E;
                Hown[size_t(l.r)] = Hown[size_t(l.r)] + b * l.F;
            }
            Hleaf.assign(Nn, Vec3d());
            for (size_t n = 0; n < Nn; ++n) {
                const HNode& x = h.nodes[n];
                Hleaf[n] = Hown[n] + (x.parent >= 0 ? Hleaf[size_t(x.parent)] : Vec3d());
            }
            for (size_t n = 0; n < Nn; ++n) Hleaf[n] = Hleaf[n] * h.scale[n];
        };
        auto pull = [&](std::vector<Vec3d>& v) {
            for (size_t n = Nn; n-- > 0;) {
                const HNode& x = h.nodes[n];
                if (x.child < 0) continue;
                Vec3d acc;
                for (int k = 0; k < 4; ++k) acc = acc + v[size_t(x.child + k)] * h.nodes[size_t(x.child + k)].g.area;
                v[n] = acc * (1.0 / x.g.area);
            }
        };
        auto rho_of = [&](size_t n) { return sol.el[size_t(h.nodes[n].root)].rho; };
        // Direct: one reflection of the emission.
        std::vector<Vec3d> Hl;
        gather(Rr, false, Hd);
        std::vector<Vec3d> Rd(Nn);
        for (size_t n = 0; n < Nn; ++n)
            if (h.nodes[n].child < 0) Rd[n] = mul(rho_of(n), Hd[n]);
        pull(Rd);
        Rr.assign(Nn, Vec3d());
        Rold.assign(Nn, Vec3d());
        const int iters = c_.max_depth < 0 ? 10000 : std::max(0, c_.max_depth - 1);
        const double target = c_.residual * emitted;
        double absorbed = 0, escaped = 0, unshot = emitted;
        h.iterations = 0;
        for (int it = 0; it < iters; ++it) {
            gather(Rr, true, Hl);
            // The books of this step (B_old = E + Rr, B_new = E + rho H):
            // absorbed sum A (1 - rho) H, escaped sum A B_old - sum A H (what
            // left and arrived nowhere), unshot sum A (B_new - B_old).
            double arrive = 0, leave = 0, absb = 0, uns = 0;
            Rold = Rr;
            for (size_t n = 0; n < Nn; ++n) {
                const HNode& x = h.nodes[n];
                if (x.child >= 0) continue;
                const double A = x.g.area;
                const Vec3d Bold = sol.el[size_t(x.root)].E + Rr[n], kept = mul(rho_of(n), Hl[n]);
                arrive += A * avg(Hl[n]);
                leave += A * avg(Bold);
                absb += A * (avg(Hl[n]) - avg(kept));
                uns += A * (avg(kept) - avg(Rr[n]));
                Rr[n] = kept;
            }
            pull(Rr);
            absorbed = absb;
            escaped = leave - arrive;
            unshot = uns;
            ++h.iterations;
            if (c_.max_depth < 0 && std::fabs(uns) <= target) break;
            if (loop.cancelled()) return false;
        }
        // 5. The effect classes per node: direct, the rest, and the last
        //    bounce on its own where max_depth D makes it D - 1 >= 2.
        const bool last = c_.max_depth > 0 && c_.max_depth - 1 >= 2 && h.iterations == c_.max_depth - 1;
        for (size_t n = 0; n < Nn; ++n) {
            if (h.iterations == 0) {
                sol.Bd[n] = sol.Bi[n] = sol.Blast[n] = Vec3d();
                continue;
            }
            const Vec3d upto = last ? Rold[n] : Rr[n];
            sol.Bd[n] = Rd[n];
            auto pos = [](const Vec3d& v) { return Vec3d(std::max(0.0, v.x), std::max(0.0, v.y), std::max(0.0, v.z)); };
            sol.Bi[n] = pos(upto - Rd[n]);
            sol.Blast[n] = last ? pos(Rr[n] - Rold[n]) : Vec3d();
        }
        sol.absorbed = absorbed;
        sol.escaped = escaped;
        sol.unshot = unshot;
        sol.residual = emitted > 0 ? unshot / emitted : 0.0;
        sol.shots = uint64_t(h.iterations);
    }
    sol.closed.assign(h.closed.begin(), h.closed.end());
    for (uint64_t r : rays) sol.rays += r;
    return true;
}

int RadiosityIntegrator::value_index(const Scene& scene, const Solution& sol, const Interaction& hit) const {
    int p = sol.mesh.locate(scene, hit);
    if (p < 0) return -1;
    int e = 2 * p + (dot(hit.wi, hit.n) >= 0.f ? 0 : 1);
    if (!sol.hierarchical) return e;
    // Down the quadtree: the child whose triangle holds the hit (the
    // largest smallest barycentric coordinate, robust at the edges).
    const Vec3d x(hit.p);
    while (sol.h.nodes[size_t(e)].child >= 0) {
        const int c0 = sol.h.nodes[size_t(e)].child;
        int best = c0;
        double best_w = -1e300;
        for (int k = 0; k < 4; ++k) {
            const Patch& g = sol.h.nodes[size_t(c0 + k)].g;
            const Vec3d e1 = g.v[1] - g.v[0], e2 = g.v[2] - g.v[0], w = x - g.v[0];
            const double a11 = dot(e1, e1), a12 = dot(e1, e2), a22 = dot(e2, e2), det = a11 * a22 - a12 * a12;
            if (!(det > 0)) continue;
            const double b1 = (a22 * dot(w, e1) - a12 * dot(w, e2)) / det;
            const double b2 = (a11 * dot(w, e2) - a12 * dot(w, e1)) / det;
            const double mn = std::min({b1, b2, 1.0 - b1 - b2});
            if (mn > best_w) best_w = mn, best = c0 + k;
        }
        e = best;
    }
    return e;
}

void RadiosityIntegrator::shade(const Scene& scene, const Solution& sol, Sampler& sampler, const Ray& ray,
                                EffectRadiance& out, ThreadStats& stats) const {
    ++stats.rays;
    ++stats.paths;
    Interaction it;
    if (!scene.intersect(ray, it)) return;  // no environment: refused by check_scene
    // The value the hit reads: its element's, or its leaf's under hierarchical refinement.
    auto element = [&](const Interaction& h) -> int { return value_index(scene, sol, h); };
    if (c_.display == "patch") {
        int e = element(it);
        if (e < 0) return;
        const float inv_pi = kInvPi;
        if (mask[kEmission]) out.add(kEmission, to_color(sol.el[sol.element_of(size_t(e))].E) * inv_pi);
        if (c_.max_depth < 0 || c_.max_depth >= 2)
            if (mask[kDirect]) out.add(kDirect, to_color(sol.Bd[size_t(e)]) * inv_pi);
        if (mask[kIndirect]) out.add(kIndirect, to_color(sol.Bi[size_t(e)] + sol.Blast[size_t(e)]) * inv_pi);
        return;
    }
    if (c_.display == "vertex") {
        double w[4];
        const int p = sol.mesh.locate(scene, it, w);
        if (p < 0) return;
        const size_t side = dot(it.wi, it.n) >= 0.f ? 0 : 1, e = 2 * size_t(p) + side;
        Vec3d bd, bi;
        for (int c = 0; c < 4; ++c) {
            const int v = sol.mesh.corner_vertex[4 * size_t(p) + size_t(c)];
            if (v < 0 || w[c] == 0) continue;
            bd = bd + sol.vBd[2 * size_t(v) + side] * w[c];
            bi = bi + sol.vBi[2 * size_t(v) + side] * w[c];
        }
        const float inv_pi = kInvPi;
        if (mask[kEmission]) out.add(kEmission, to_color(sol.el[e].E) * inv_pi);
        if (c_.max_depth < 0 || c_.max_depth >= 2)
            if (mask[kDirect]) out.add(kDirect, to_color(bd) * inv_pi);
        if (mask[kIndirect]) out.add(kIndirect, to_color(bi) * inv_pi);
        return;
    }
    // Final gather: emission and direct light as `direct`, indirect from the solution.
    const Shape& sh = *scene.shapes[size_t(it.shape)];
    if (sh.emitter >= 0 && mask[kEmission]) out.add(kEmission, scene.emitters[size_t(sh.emitter)]->eval(it, it.wi));
    if (c_.max_depth == 1 || sh.bsdf < 0) return;
    const Bsdf& bsdf = *scene.bsdfs[size_t(sh.bsdf)];
    const Vec3 wi = it.to_local(it.wi);
    Color direct(0.f);
    for (int d = 0; d < c_.direct_samples; ++d)
        direct += estimate_direct(scene, it, bsdf, wi, sampler, stats, 1.f, 0.f);  // draws 4 each
    if (mask[kDirect]) out.add(kDirect, direct / float(c_.direct_samples));
    if (!(c_.max_depth < 0 || c_.max_depth >= 3)) return;
    BsdfContext ctx;
    ctx.set(it);
    Color acc(0.f);
    for (int g = 0; g < c_.gather_rays; ++g) {
        float u1 = sampler.next_1d();
        Vec2 u2 = sampler.next_2d();
        BsdfSample bs = bsdf.sample(ctx, wi, u1, u2);
        if (is_black(bs.weight) || bs.is_delta) continue;
        Ray r = it.spawn(it.to_world(bs.wo));
        Interaction h;
        ++stats.rays;
        if (!scene.intersect(r, h)) continue;
        int e = element(h);
        if (e < 0) continue;
        acc += bs.weight * to_color(sol.Bd[size_t(e)] + sol.Bi[size_t(e)]) * kInvPi;
    }
    if (mask[kIndirect]) out.add(kIndirect, acc / float(c_.gather_rays));
}

RenderOutput RadiosityIntegrator::drive(const Scene& scene, const RenderOptions& opts, const PollFn& poll) const {
    check_scene(scene);
    PassLoop loop(scene, opts, poll);
    Solution sol;
    if (!solve(loop, sol)) return loop.cancelled_output();
    if (c_.display == "vertex") vertex_values(sol);
    CameraView view(*this, [&](const Scene& sc, Sampler& sampler, const Ray& ray, EffectRadiance& o,
                               ThreadStats& stats) { shade(sc, sol, sampler, ray, o, stats); });
    RenderOutput out = render_camera_paths(loop, view);
    out.stats.shadow_rays += sol.rays;
    for (auto& [name, v] : sol.stats()) out.estimator_stats.push_back({name, {v}});
    if (c_.display == "vertex") out.estimator_stats.push_back({"vertices", {double(sol.mesh.vertex_count)}});
    out.seconds = loop.elapsed();
    return out;
}

[[maybe_unused]] const bool kRegistered = register_estimator([] {
    EstimatorInfo e;
    e.name = "radiosity";
    e.doc =
        "radiosity (Goral et al. 1984; progressive refinement, Cohen et al. 1988): diffuse scenes cut into "
        "patches, form factors in closed form with ray-cast visibility, displayed per patch, interpolated between "
        "vertices or by a final gather";
    e.params = {
        ParamSpec::string("display", "gather",
                          "'patch': each patch's radiosity / pi; 'vertex': the radiosity averaged to the mesh "
                          "vertices and interpolated over each patch; 'gather': emission and direct light by "
                          "light sampling, indirect light gathered from the solution")
            .one_of({"patch", "vertex", "gather"}),
        ParamSpec::real("patch_size", 0.0, "target patch edge length in scene units (0: from max_patches)")
            .at_least(0.0),
        ParamSpec::integer("max_patches", 1000,
                           "patch budget: the patch size that gives at most this many (with patch_size > 0: a "
                           "bound on the count)")
            .at_least(1)
            .at_most(16000),
        ParamSpec::integer("ff_samples", 2, "form-factor points per patch side (m: m^2 points, each one ray)")
            .at_least(1)
            .at_most(4),
        ParamSpec::real("residual", 1e-3, "stop when the unshot power is at most this fraction of the emitted")
            .greater_than(0.0)
            .less_than(1.0),
        max_depth_param(),
        ParamSpec::integer("direct_samples", 8, "light samples per camera sample ('gather')").at_least(1).at_most(4096),
        ParamSpec::integer("gather_rays", 8, "final-gather rays per camera sample ('gather')")
            .at_least(1)
            .at_most(4096),
        ParamSpec::boolean("hierarchical", false,
                           "hierarchical refinement (Hanrahan et al. 1991): a quadtree of elements over every "
                           "triangle patch, linked at the level the oracle asks for; display 'patch' shows its "
                           "leaves"),
        ParamSpec::real("hr_epsilon", 0.05,
                        "hierarchical: link when rho_r B_s F / (the emitted power per unit area of all surfaces) is at "
                        "most this (F estimated unoccluded both ways)")
            .greater_than(0.0)
            .at_most(1.0),
        ParamSpec::real("min_area", 0.0,
                        "hierarchical: elements of at most this area (scene units^2) are not split (0: 1/256 of "
                        "the largest triangle patch's area)")
            .at_least(0.0),
    };
    e.caps.driver = Driver::OwnPasses;
    e.caps.bias = Bias::Biased;
    e.caps.effects = effect_mask({kEmission, kDirect, kIndirect});
    e.factory = [](ParamReader& p) {
        RadiosityIntegrator::Config c;
        c.display = p.get_string("display");
        c.patch_size = p.get_float("patch_size");
        c.max_patches = p.get_int("max_patches");
        c.ff_samples = p.get_int("ff_samples");
        c.residual = p.get_float("residual");
        c.max_depth = p.get_int("max_depth");
        c.gather_rays = p.get_int("gather_rays");
        c.direct_samples = p.get_int("direct_samples");
        c.hierarchical = p.get_bool("hierarchical");
        c.hr_epsilon = p.get_float("hr_epsilon");
        c.min_area = p.get_float("min_area");
        if (!c.hierarchical && (c.hr_epsilon != double(float(0.05)) || c.min_area != 0.0))
            p.fail(c.min_area != 0.0 ? "min_area" : "hr_epsilon",
                   "hr_epsilon and min_area only apply with hierarchical = true");
        if (c.hierarchical && c.display == "vertex")
            p.fail("display",
                   "display 'vertex' is not available with hierarchical = true (the quadtrees' leaves share no "
                   "mesh vertices); use 'patch' or 'gather'");
        return std::make_unique<RadiosityIntegrator>(c);
    };
    return e;
}());

}  // namespace

RadiositySolution radiosity_solution(const Scene& scene, const Integrator& integrator, int threads) {
    const auto* r = dynamic_cast<const RadiosityIntegrator*>(&integrator);
    if (!r) throw std::invalid_argument("radiosity_solution: integrator '" + integrator.type + "' is not radiosity");
    r->check_scene(scene);
    RenderOptions opts;
    opts.threads = threads;
    PassLoop loop(scene, opts, [](uint64_t, uint64_t) { return true; });
    Solution sol;
    if (!r->solve(loop, sol)) throw std::runtime_error("radiosity_solution: cancelled");
    RadiositySolution out;
    for (const Patch& p : sol.mesh.patches) {
        for (const Vec3d* v : {&p.c, &p.n}) {
            std::vector<double>& dst = v == &p.c ? out.centre : out.normal;
            dst.insert(dst.end(), {v->x, v->y, v->z});
        }
        for (int c = 0; c < 4; ++c) {  // the first 3 corners and the last (exact for triangles)
            const Vec3d& v = p.v[c < 3 ? std::min(c, p.nv - 1) : p.nv - 1];
            out.corners.insert(out.corners.end(), {v.x, v.y, v.z});
        }
        out.area.push_back(p.area);
        out.shape.push_back(p.shape);
    }
    for (size_t e = 0; e < sol.el.size(); ++e) {
        out.emitted.insert(out.emitted.end(), {sol.el[e].E.x, sol.el[e].E.y, sol.el[e].E.z});
        out.direct.insert(out.direct.end(), {sol.Bd[e].x, sol.Bd[e].y, sol.Bd[e].z});
        Vec3d ind = sol.Bi[e] + sol.Blast[e];
        out.indirect.insert(out.indirect.end(), {ind.x, ind.y, ind.z});
    }
    out.stats = sol.stats();
    return out;
}

}  // namespace rm
