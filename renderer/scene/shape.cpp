#include "scene/shape.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#ifdef __SSE2__
#include <emmintrin.h>
#endif

#include "core/warp.h"
#include "scene/light_sampler.h"

namespace rm {

namespace {
// A triangle's point p0 b0 + p1 b1 + p2 b2 and its error bound
// (|p0 b0| + |p1 b1| + |p2 b2|) gamma_7 (PBR4 eq. 6.21), from corners
// given as three floats each with a fourth readable after them (Mesh's
// positions are padded for Embree's 16-byte loads); and a point o + d t
// along a ray with its bound (|o| + |d t|) gamma_7 (PBR4 eq. 6.24). With
// SSE2 the three coordinates share one register: the same IEEE products
// and sums in the same order as the scalar code, so the same bits, in
// about a third of the instructions (the hit record and area sampling
// both take them).
constexpr float kGamma7 = 7.f * 0x1p-24f / (1.f - 7.f * 0x1p-24f);
#ifdef __SSE2__
inline Vec3 to_vec3(__m128 v) {
    alignas(16) float f[4];
    _mm_store_ps(f, v);
    return {f[0], f[1], f[2]};
}
inline __m128 abs4(__m128 v) { return _mm_and_ps(v, _mm_castsi128_ps(_mm_set1_epi32(0x7fffffff))); }
#endif
inline void bary_point(const float* v0, const float* v1, const float* v2, float b0, float b1, float b2, Vec3& p,
                       Vec3& err) {
#ifdef __SSE2__
    const __m128 a = _mm_mul_ps(_mm_loadu_ps(v0), _mm_set1_ps(b0));
    const __m128 b = _mm_mul_ps(_mm_loadu_ps(v1), _mm_set1_ps(b1));
    const __m128 c = _mm_mul_ps(_mm_loadu_ps(v2), _mm_set1_ps(b2));
    p = to_vec3(_mm_add_ps(_mm_add_ps(a, b), c));
    err = to_vec3(_mm_mul_ps(_mm_add_ps(_mm_add_ps(abs4(a), abs4(b)), abs4(c)), _mm_set1_ps(kGamma7)));
#else
    const Vec3 p0(v0[0], v0[1], v0[2]), p1(v1[0], v1[1], v1[2]), p2(v2[0], v2[1], v2[2]);
    p = p0 * b0 + p1 * b1 + p2 * b2;
    err = (abs(p0 * b0) + abs(p1 * b1) + abs(p2 * b2)) * kGamma7;
#endif
}
inline void ray_point(const Ray& ray, float t, Vec3& p, Vec3& err) {
#ifdef __SSE2__
    static_assert(sizeof(Ray) == 8 * sizeof(float), "Ray: o, d, tmin, tmax");
    const __m128 o = _mm_loadu_ps(&ray.o.x), dt = _mm_mul_ps(_mm_loadu_ps(&ray.d.x), _mm_set1_ps(t));
    p = to_vec3(_mm_add_ps(o, dt));
    err = to_vec3(_mm_mul_ps(_mm_add_ps(abs4(o), abs4(dt)), _mm_set1_ps(kGamma7)));
#else
    p = ray.o + ray.d * t;
    err = (abs(ray.o) + abs(ray.d * t)) * kGamma7;
#endif
}

// The shading frame about n whose tangent is dp/du made orthogonal to n
// (Mitsuba 3's SurfaceInteraction::initialize_sh_frame); the default frame
// about n where dp/du is zero, parallel to n or not finite.
Frame tangent_frame(const Vec3& n, const Vec3& dp_du) {
    Vec3 s = dp_du - n * dot(n, dp_du);
    float l = length(s);
    if (!(l > 0.f) || !std::isfinite(l)) return Frame(n);
    Frame f;
    f.n = n;
    f.s = s / l;
    f.t = cross(n, f.s);
    return f;
}
}  // namespace

// ---------------------------------------------------------------- mesh
Mesh::Mesh(std::vector<float> positions, std::vector<uint32_t> indices, std::vector<float> normals,
           std::vector<float> uvs)
    : pos_(std::move(positions)), indices_(std::move(indices)), normals_(std::move(normals)), uvs_(std::move(uvs)) {
    size_t nv = pos_.size() / 3;
    lo_ = Vec3(kInf);
    hi_ = Vec3(-kInf);
    for (size_t i = 0; i < nv; ++i) {
        lo_ = vmin(lo_, vertex(uint32_t(i)));
        hi_ = vmax(hi_, vertex(uint32_t(i)));
    }
    // Triangle areas in double for the sampling CDF; degenerate triangles get
    // zero area, so they are never sampled (and never produce a 1/0 pdf).
    area_cdf_.resize(triangle_count());
    double acc = 0;
    for (size_t f = 0; f < triangle_count(); ++f) {
        Vec3 a = vertex(indices_[3 * f]), b = vertex(indices_[3 * f + 1]), c = vertex(indices_[3 * f + 2]);
        double ar = 0.5 * double(length(cross(b - a, c - a)));
        if (!std::isfinite(ar)) ar = 0;
        acc += ar;
        area_cdf_[f] = float(acc);
    }
    total_area_ = float(acc);
    inv_total_area_ = total_area_ > 0.f ? 1.f / total_area_ : 0.f;
    num_vertices_ = nv;
    // The guide table: one bucket per triangle. area_bucket is monotone in
    // the target (a product by a positive constant, then truncated and
    // clamped), which is all the exactness of the search needs.
    const size_t nf = triangle_count();
    const float scale = float(nf) / total_area_;
    if (nf > 0 && total_area_ > 0.f && std::isfinite(total_area_) && std::isfinite(scale) && scale > 0.f &&
        nf < (size_t(1) << 31)) {
        area_guide_scale_ = scale;
        area_guide_.assign(nf + 1, 0);
        for (size_t k = 0; k < nf; ++k) ++area_guide_[area_bucket(area_cdf_[k]) + 1];
        for (size_t j = 0; j < nf; ++j) area_guide_[j + 1] += area_guide_[j];
    }
    pos_.push_back(0.f);  // Embree reads the last vertex with a 16-byte load
}

RTCGeometry Mesh::create_geometry(RTCDevice device, unsigned geom_id) {
    // Per-face data the hit and sampling code would otherwise recompute.
    size_t nf = triangle_count();
    face_n_.resize(nf);
    for (size_t f = 0; f < nf; ++f) {
        Vec3 p0 = vertex(indices_[3 * f]), p1 = vertex(indices_[3 * f + 1]), p2 = vertex(indices_[3 * f + 2]);
        Vec3 c = cross(p1 - p0, p2 - p0);
        float l = length(c);
        Vec3 n = (l > 0 && std::isfinite(l)) ? c / l : Vec3(0, 0, 1);
        face_n_[f] = flip_normals ? -n : n;
    }
    // The parts of the hit record that depend on the face alone.
    face_frame_.clear();
    if (normals_.empty()) {
        face_frame_.reserve(nf);
        for (size_t f = 0; f < nf; ++f) face_frame_.emplace_back(face_n_[f]);
    }
    face_off_origin_.resize(nf);
    for (size_t f = 0; f < nf; ++f) {
        Vec3 p0 = vertex(indices_[3 * f]), p1 = vertex(indices_[3 * f + 1]), p2 = vertex(indices_[3 * f + 2]);
        float mag = std::max(max_component(abs(p0)), std::max(max_component(abs(p1)), max_component(abs(p2))));
        face_off_origin_[f] = mag > 0.f ? 1 : 0;
    }
    RTCGeometry g = rtcNewGeometry(device, RTC_GEOMETRY_TYPE_TRIANGLE);
    rtcSetSharedGeometryBuffer(g, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3, pos_.data(), 0, 3 * sizeof(float),
                               num_vertices_);
    rtcSetSharedGeometryBuffer(g, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3, indices_.data(), 0, 3 * sizeof(uint32_t),
                               triangle_count());
    rtcCommitGeometry(g);
    return g;
}

void Mesh::normal_cone(Vec3& w, float& cos_theta) const {
    DirectionCone c;
    for (const Vec3& n : face_n_) c = cone_union(c, cone_of(n));
    for (size_t i = 0; i + 2 < normals_.size(); i += 3) {
        Vec3 n(normals_[i], normals_[i + 1], normals_[i + 2]);
        float l = length(n);
        if (!(l > 0.f) || !std::isfinite(l)) continue;
        c = cone_union(c, cone_of(flip_normals ? -(n / l) : n / l));
    }
    w = c.w;
    cos_theta = c.empty ? -1.f : c.cos_theta;
    // Interpolated shading normals stay inside a cone narrower than a
    // hemisphere (it is convex), not inside a wider one.
    if (!normals_.empty() && cos_theta < 0.f) cos_theta = -1.f;
}

void Mesh::fill_interaction(const Ray& ray, const RTCHit& hit, float t, Interaction& it) const {
    uint32_t f = hit.primID;
    uint32_t i0 = indices_[3 * f], i1 = indices_[3 * f + 1], i2 = indices_[3 * f + 2];
    float b1 = hit.u, b2 = hit.v, b0 = 1.f - b1 - b2;
    Vec3 n = face_n_[f];
    it.n = n;
    // The hit point from whichever computation has the smaller error bound:
    // barycentric interpolation errs by ~eps |v_i| (PBR4 eq. 6.21; Embree's
    // u, v carry a similar error relative to the triangle), the ray by
    // ~eps (|o| + t |d|) (PBR4 eq. 6.24). A huge floor seen from close by
    // needs the ray: interpolating 1e4-sized vertices misplaces the point by
    // 1e-3, which smears the shadow of a 1e-3 object into streaks.
    Vec3 p_bary, err_bary, p_ray, err_ray;
    bary_point(&pos_[3 * size_t(i0)], &pos_[3 * size_t(i1)], &pos_[3 * size_t(i2)], b0, b1, b2, p_bary, err_bary);
    ray_point(ray, t, p_ray, err_ray);
    if (max_component(err_ray) < max_component(err_bary) && face_off_origin_[f]) {
        it.p = p_ray;
        it.eps = offset_epsilon(it.p, n, err_ray);
    } else {
        it.p = p_bary;
        it.eps = offset_epsilon(it.p, n, err_bary);
    }
    Vec3 ns = n;
    if (!normals_.empty()) {
        auto nv = [&](uint32_t i) { return Vec3(normals_[3 * i], normals_[3 * i + 1], normals_[3 * i + 2]); };
        Vec3 s = nv(i0) * b0 + nv(i1) * b1 + nv(i2) * b2;
        float l = length(s);
        if (l > 0 && std::isfinite(l)) ns = flip_normals ? -(s / l) : s / l;
        it.sh = Frame(ns);
    } else {
        it.sh = face_frame_[f];  // Frame(n), made once per face
    }
    it.uv = surface_uv(f, b1, b2);
    if (uv_frame) {
        const Vec3 p0 = vertex(i0), p1 = vertex(i1), p2 = vertex(i2);
        if (!uvs_.empty()) {
            // dp/du and dp/dv of the triangle's uv parametrisation (Mitsuba 3
            // src/render/mesh.cpp, compute_surface_interaction): solve
            // [dp0 dp1] = [dp/du dp/dv] [duv0 duv1]; a degenerate
            // parametrisation gets coordinate_system(n), as Mitsuba's.
            auto uv = [&](uint32_t i) { return Vec2(uvs_[2 * i], uvs_[2 * i + 1]); };
            const Vec2 duv0 = uv(i1) - uv(i0), duv1 = uv(i2) - uv(i0);
            const float det = duv0.x * duv1.y - duv0.y * duv1.x;
            if (det != 0.f) {
                const float inv = 1.f / det;
                it.dp_du = ((p1 - p0) * duv1.y - (p2 - p0) * duv0.y) * inv;
                it.dp_dv = ((p2 - p0) * duv0.x - (p1 - p0) * duv1.x) * inv;
                it.sh = tangent_frame(ns, it.dp_du);
            } else {
                const Frame cs(n);
                it.dp_du = cs.s;
                it.dp_dv = cs.t;
            }
        } else {
            // Mitsuba's mesh without texture coordinates: uv = (b1, b2), so
            // dp/du and dp/dv are the triangle's edges.
            it.dp_du = p1 - p0;
            it.dp_dv = p2 - p0;
        }
    }
}

// Inlined into both callers (fill_interaction, sample_position): as a call
// it cost about 40 instructions a hit, half of them its record's copy.
[[gnu::always_inline]] inline SurfaceUv Mesh::surface_uv(uint32_t f, float b1, float b2) const {
    SurfaceUv out;
    if (!uvs_.empty()) {
        const uint32_t i0 = indices_[3 * f], i1 = indices_[3 * f + 1], i2 = indices_[3 * f + 2];
        auto uv = [&](uint32_t i) { return Vec2(uvs_[2 * i], uvs_[2 * i + 1]); };
        out = uv(i0) * (1.f - b1 - b2) + uv(i1) * b1 + uv(i2) * b2;
    } else {
        out = Vec2(b1, b2);
    }
    if (!attributes_.list.empty()) {
        out.prim = int(f);
        out.bary = Vec2(b1, b2);
        out.attributes = &attributes_;
    }
    return out;
}

void Mesh::add_attribute(MeshAttribute a) {
    const size_t n = a.per_face ? triangle_count() : num_vertices_;
    if (a.channels != 1 && a.channels != 3)
        throw std::invalid_argument("shape '" + id + "': attribute '" + a.name + "' must have 1 or 3 channels");
    if (a.data.size() != n * size_t(a.channels))
        throw std::invalid_argument("shape '" + id + "': attribute '" + a.name + "' must have " + std::to_string(n) +
                                    " x " + std::to_string(a.channels) + " values");
    for (auto& b : attributes_.list)
        if (b.name == a.name) throw std::invalid_argument("shape '" + id + "': attribute '" + a.name + "' given twice");
    attributes_.list.push_back(std::move(a));
    attributes_.indices = indices_.data();
}

namespace {
constexpr size_t kShortCdf = 8;  // CDF ranges searched by a scan
}  // namespace

size_t Mesh::area_bucket(float target) const {
    const size_t n = triangle_count();
    const float x = target * area_guide_scale_;
    if (!(x < float(n))) return n - 1;  // NaN included
    if (!(x > 0.f)) return 0;
    return std::min(size_t(x), n - 1);
}

[[gnu::always_inline]] inline size_t Mesh::area_triangle(float target) const {
    const float* cdf = area_cdf_.data();
    size_t lo = 0, hi = area_cdf_.size();
    // A few triangles (a rectangle light has two): no table.
    if (hi > kShortCdf && !area_guide_.empty()) {
        // Entries below area_guide_[j] have a lower bucket than the
        // target's, so are at or below it; entries from area_guide_[j + 1]
        // on have a higher bucket, so are above it.
        const size_t j = area_bucket(target);
        lo = area_guide_[j];
        hi = area_guide_[j + 1];
    }
    // upper_bound over [lo, hi): the first entry above the target (hi if
    // none; a NaN target is above none, as in upper_bound), by a scan
    // where the range is short.
    if (hi - lo > kShortCdf) return size_t(std::upper_bound(cdf + lo, cdf + hi, target) - cdf);
    while (lo < hi && !(target < cdf[lo])) ++lo;
    return lo;
}

PositionSample Mesh::sample_position(Vec2 u, float u_extra) const {
    PositionSample ps;
    if (total_area_ <= 0) return ps;
    float target = u_extra * total_area_;
    size_t f = area_triangle(target);
    if (f >= triangle_count()) f = triangle_count() - 1;
    Vec2 b = warp::square_to_uniform_triangle(u);
    float b0 = 1.f - b.x - b.y;
    Vec3 err;
    bary_point(&pos_[3 * size_t(indices_[3 * f])], &pos_[3 * size_t(indices_[3 * f + 1])],
               &pos_[3 * size_t(indices_[3 * f + 2])], b0, b.x, b.y, ps.p, err);
    ps.n = face_n_[f];
    ps.eps = offset_epsilon(ps.p, ps.n, err);
    ps.pdf_a = inv_total_area_;
    ps.uv = surface_uv(uint32_t(f), b.x, b.y);
    return ps;
}

// ---------------------------------------------------------------- analytic shapes through Embree user geometry
namespace {

// Embree calls these with N == 1 for rtcIntersect1/rtcOccluded1 and with
// the packet's width for Scene::intersect_packet (camera rays): user_query
// below runs the one-ray test on each valid lane.
template <class S>
void user_bounds(const RTCBoundsFunctionArguments* args) {
    const S* s = static_cast<const S*>(args->geometryUserPtr);
    Vec3 lo = s->bbox_min(), hi = s->bbox_max();
    args->bounds_o->lower_x = lo.x;
    args->bounds_o->lower_y = lo.y;
    args->bounds_o->lower_z = lo.z;
    args->bounds_o->upper_x = hi.x;
    args->bounds_o->upper_y = hi.y;
    args->bounds_o->upper_z = hi.z;
}

// Sphere roots in double, after Haines et al., "Precision Improvements for
// Ray/Sphere Intersection", Ray Tracing Gems (2019), ch. 7, eqs. 8 and 10.
bool sphere_roots(const Sphere& s, const RTCRay& r, double& t0, double& t1) {
    double ox = r.org_x - s.cx_, oy = r.org_y - s.cy_, oz = r.org_z - s.cz_;
    double dx = r.dir_x, dy = r.dir_y, dz = r.dir_z;
    double a = dx * dx + dy * dy + dz * dz;
    double b = -(ox * dx + oy * dy + oz * dz);  // -b/2 in the usual notation
    double fx = ox + (b / a) * dx, fy = oy + (b / a) * dy, fz = oz + (b / a) * dz;
    double disc = a * (s.r_ * s.r_ - (fx * fx + fy * fy + fz * fz));
    if (disc < 0) return false;
    double q = b + std::copysign(std::sqrt(disc), b);
    t0 = q / a;
    // c / q with c = |o|^2 - r^2 (eq. 10): the second root without cancellation.
    double c = ox * ox + oy * oy + oz * oz - s.r_ * s.r_;
    t1 = (q != 0) ? c / q : t0;
    if (t0 > t1) std::swap(t0, t1);
    return true;
}

template <bool kOccluded>
void sphere_intersect_impl(const Sphere& s, RTCRay& ray, RTCHit* hit, unsigned geom_id, unsigned inst_id, int* valid) {
    if (!valid[0]) return;
    double t0, t1;
    if (!sphere_roots(s, ray, t0, t1)) return;
    double t = t0;
    if (t <= ray.tnear || t >= ray.tfar) {
        t = t1;
        if (t <= ray.tnear || t >= ray.tfar) return;
    }
    if (kOccluded) {
        ray.tfar = -kInf;
        return;
    }
    ray.tfar = float(t);
    double px = ray.org_x + t * ray.dir_x - s.cx_, py = ray.org_y + t * ray.dir_y - s.cy_,
           pz = ray.org_z + t * ray.dir_z - s.cz_;
    hit->Ng_x = float(px);
    hit->Ng_y = float(py);
    hit->Ng_z = float(pz);
    hit->u = 0;
    hit->v = 0;
    hit->primID = 0;
    hit->geomID = geom_id;
    hit->instID[0] = inst_id;  // the instance being traversed, if any
}

template <bool kOccluded>
void disk_intersect_impl(const Disk& d, RTCRay& ray, RTCHit* hit, unsigned geom_id, unsigned inst_id, int* valid) {
    if (!valid[0]) return;
    const auto& M = d.xf_.inv;
    double o[3] = {ray.org_x, ray.org_y, ray.org_z}, v[3] = {ray.dir_x, ray.dir_y, ray.dir_z};
    double lo[3], lv[3];
    for (int i = 0; i < 3; ++i) {
        lo[i] = M[i][0] * o[0] + M[i][1] * o[1] + M[i][2] * o[2] + M[i][3];
        lv[i] = M[i][0] * v[0] + M[i][1] * v[1] + M[i][2] * v[2];
    }
    if (lv[2] == 0) return;
    double t = -lo[2] / lv[2];
    if (!(t > ray.tnear && t < ray.tfar)) return;
    double x = lo[0] + t * lv[0], y = lo[1] + t * lv[1];
    if (x * x + y * y > 1.0) return;
    if (kOccluded) {
        ray.tfar = -kInf;
        return;
    }
    ray.tfar = float(t);
    hit->u = float(x);
    hit->v = float(y);
    hit->Ng_x = 0;
    hit->Ng_y = 0;
    hit->Ng_z = 1;
    hit->primID = 0;
    hit->geomID = geom_id;
    hit->instID[0] = inst_id;  // the instance being traversed, if any
}
// The open tube x^2 + y^2 = r^2, 0 <= z <= length, in its local frame
// (Mitsuba 3's cylinder, src/shapes/cylinder.cpp), in double: the ray is
// taken into the frame by the rigid map's transpose, and the roots come
// from the closest approach in the xy-plane as the sphere's do (Haines et
// al. 2019, eqs. 8 and 10), which keeps them for grazing rays. The nearer
// root within the tube's length and (tnear, tfar) is the hit.
template <bool kOccluded>
void cylinder_intersect_impl(const Cylinder& c, RTCRay& ray, RTCHit* hit, unsigned geom_id, unsigned inst_id,
                             int* valid) {
    if (!valid[0]) return;
    const double w[3] = {ray.org_x - c.t_[0], ray.org_y - c.t_[1], ray.org_z - c.t_[2]};
    const double v[3] = {ray.dir_x, ray.dir_y, ray.dir_z};
    double o[3], d[3];
    for (int i = 0; i < 3; ++i) {
        o[i] = c.q_[0][i] * w[0] + c.q_[1][i] * w[1] + c.q_[2][i] * w[2];
        d[i] = c.q_[0][i] * v[0] + c.q_[1][i] * v[1] + c.q_[2][i] * v[2];
    }
    const double a = d[0] * d[0] + d[1] * d[1];
    if (!(a > 0)) return;  // along the axis: never crosses the tube
    const double b = -(o[0] * d[0] + o[1] * d[1]);
    const double fx = o[0] + (b / a) * d[0], fy = o[1] + (b / a) * d[1];
    const double disc = a * (c.r_ * c.r_ - (fx * fx + fy * fy));
    if (disc < 0) return;
    const double q = b + std::copysign(std::sqrt(disc), b);
    const double cc = o[0] * o[0] + o[1] * o[1] - c.r_ * c.r_;
    double t0 = q / a, t1 = (q != 0) ? cc / q : t0;
    if (t0 > t1) std::swap(t0, t1);
    double t = 0;
    bool found = false;
    for (double tc : {t0, t1}) {
        const double z = o[2] + tc * d[2];
        if (tc > ray.tnear && tc < ray.tfar && z >= 0 && z <= c.len_) {
            t = tc;
            found = true;
            break;
        }
    }
    if (!found) return;
    if (kOccluded) {
        ray.tfar = -kInf;
        return;
    }
    ray.tfar = float(t);
    hit->Ng_x = float(o[0] + t * d[0]);
    hit->Ng_y = float(o[1] + t * d[1]);
    hit->Ng_z = 0;
    hit->u = 0;
    hit->v = 0;
    hit->primID = 0;
    hit->geomID = geom_id;
    hit->instID[0] = inst_id;
}
// A user geometry's query over Embree's N rays (SoA, RTCRayHitN) with their
// valid mask: N == 1 in place; otherwise each valid lane gathered into one
// RTCRay / RTCHit, tested by Impl<kOccluded> and written back when it hit.
template <class S, bool kOccluded, void (*Impl)(const S&, RTCRay&, RTCHit*, unsigned, unsigned, int*)>
void user_query(void* user, const int* valid, unsigned geom_id, unsigned inst_id, unsigned N, RTCRayN* rays,
                RTCHitN* hits) {
    const S& shape = *static_cast<const S*>(user);
    if (N == 1) {
        int v = valid[0];
        RTCRay& r = *reinterpret_cast<RTCRay*>(rays);
        Impl(shape, r, kOccluded ? nullptr : reinterpret_cast<RTCHit*>(hits), geom_id, inst_id, &v);
        return;
    }
    for (unsigned i = 0; i < N; ++i) {
        if (!valid[i]) continue;
        RTCRay r;
        r.org_x = RTCRayN_org_x(rays, N, i);
        r.org_y = RTCRayN_org_y(rays, N, i);
        r.org_z = RTCRayN_org_z(rays, N, i);
        r.dir_x = RTCRayN_dir_x(rays, N, i);
        r.dir_y = RTCRayN_dir_y(rays, N, i);
        r.dir_z = RTCRayN_dir_z(rays, N, i);
        r.tnear = RTCRayN_tnear(rays, N, i);
        r.tfar = RTCRayN_tfar(rays, N, i);
        const float before = r.tfar;
        RTCHit h{};  // written by Impl only on a hit, read only then
        int one = -1;
        Impl(shape, r, kOccluded ? nullptr : &h, geom_id, inst_id, &one);
        if (r.tfar == before) continue;
        RTCRayN_tfar(rays, N, i) = r.tfar;
        if (kOccluded) continue;
        RTCHitN_Ng_x(hits, N, i) = h.Ng_x;
        RTCHitN_Ng_y(hits, N, i) = h.Ng_y;
        RTCHitN_Ng_z(hits, N, i) = h.Ng_z;
        RTCHitN_u(hits, N, i) = h.u;
        RTCHitN_v(hits, N, i) = h.v;
        RTCHitN_primID(hits, N, i) = h.primID;
        RTCHitN_geomID(hits, N, i) = h.geomID;
        RTCHitN_instID(hits, N, i, 0) = h.instID[0];
    }
}

template <class S, void (*Impl)(const S&, RTCRay&, RTCHit*, unsigned, unsigned, int*)>
void user_intersect(const RTCIntersectFunctionNArguments* a) {
    user_query<S, false, Impl>(a->geometryUserPtr, a->valid, a->geomID, a->context->instID[0], a->N,
                               RTCRayHitN_RayN(a->rayhit, a->N), RTCRayHitN_HitN(a->rayhit, a->N));
}
template <class S, void (*Impl)(const S&, RTCRay&, RTCHit*, unsigned, unsigned, int*)>
void user_occluded(const RTCOccludedFunctionNArguments* a) {
    user_query<S, true, Impl>(a->geometryUserPtr, a->valid, a->geomID, 0, a->N, a->ray, nullptr);
}

}  // namespace

// ---------------------------------------------------------------- sphere
Sphere::Sphere(Vec3 center, float radius, const Matrix4& to_world)
    : cx_(center.x), cy_(center.y), cz_(center.z), r_(radius) {
    for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j) rot_[i][j] = to_world[size_t(4 * i + j)] / double(radius);
}
Vec3 Sphere::bbox_min() const {
    return Vec3(float(cx_ - r_), float(cy_ - r_), float(cz_ - r_)) -
           abs(Vec3(float(cx_), float(cy_), float(cz_))) * 1e-6f - Vec3(float(r_) * 1e-6f);
}
Vec3 Sphere::bbox_max() const {
    return Vec3(float(cx_ + r_), float(cy_ + r_), float(cz_ + r_)) +
           abs(Vec3(float(cx_), float(cy_), float(cz_))) * 1e-6f + Vec3(float(r_) * 1e-6f);
}

RTCGeometry Sphere::create_geometry(RTCDevice device, unsigned geom_id) {
    RTCGeometry g = rtcNewGeometry(device, RTC_GEOMETRY_TYPE_USER);
    rtcSetGeometryUserPrimitiveCount(g, 1);
    rtcSetGeometryUserData(g, this);
    rtcSetGeometryBoundsFunction(g, user_bounds<Sphere>, nullptr);
    rtcSetGeometryIntersectFunction(g, user_intersect<Sphere, sphere_intersect_impl<false>>);
    rtcSetGeometryOccludedFunction(g, user_occluded<Sphere, sphere_intersect_impl<true>>);
    rtcCommitGeometry(g);
    return g;
}

void Sphere::fill_interaction(const Ray& ray, const RTCHit& hit, float t, Interaction& it) const {
    // Re-project the hit onto the sphere (double) so it lies on the surface.
    double px = double(ray.o.x) + double(t) * ray.d.x - cx_, py = double(ray.o.y) + double(t) * ray.d.y - cy_,
           pz = double(ray.o.z) + double(t) * ray.d.z - cz_;
    double l = std::sqrt(px * px + py * py + pz * pz);
    if (l > 0) {
        px /= l;
        py /= l;
        pz /= l;
    } else {
        px = 0;
        py = 0;
        pz = 1;
    }
    it.p = Vec3(float(cx_ + r_ * px), float(cy_ + r_ * py), float(cz_ + r_ * pz));
    Vec3 n{float(px), float(py), float(pz)};
    // Mitsuba 3's sphere uv (src/shapes/sphere.cpp, compute_surface_interaction):
    // (phi / 2pi, theta / pi) of the hit in the object frame, i.e. after
    // to_world's inverse; rot_ is orthogonal, so its inverse is its transpose.
    const double lx = rot_[0][0] * px + rot_[1][0] * py + rot_[2][0] * pz;
    const double ly = rot_[0][1] * px + rot_[1][1] * py + rot_[2][1] * pz;
    const double lz = rot_[0][2] * px + rot_[1][2] * py + rot_[2][2] * pz;
    it.uv = uv_of(px, py, pz);
    if (flip_normals) n = -n;
    it.n = n;
    it.sh = Frame(n);
    if (uv_frame) {
        // Mitsuba's sphere: dp/du = to_world (-y, x, 0) of the local point, times 2 pi.
        const Vec3 du(float(-rot_[0][0] * ly + rot_[0][1] * lx), float(-rot_[1][0] * ly + rot_[1][1] * lx),
                      float(-rot_[2][0] * ly + rot_[2][1] * lx));
        it.sh = tangent_frame(n, du);
        // dp/dv = to_world (z cos phi, z sin phi, -sin theta) times pi
        // (src/shapes/sphere.cpp), with the radius: both for bump maps.
        const double rd = std::sqrt(lx * lx + ly * ly);
        const double cp = rd > 0 ? lx / rd : 1.0, sp = rd > 0 ? ly / rd : 0.0;
        const double dv_l[3] = {lz * cp, lz * sp, -rd};
        Vec3 dv;
        for (int i = 0; i < 3; ++i)
            dv[i] = float((rot_[i][0] * dv_l[0] + rot_[i][1] * dv_l[1] + rot_[i][2] * dv_l[2]) * r_ * kPi);
        it.dp_du = du * float(2.0 * kPi * r_);
        it.dp_dv = dv;
    }
    // Reprojected in double: the error is the rounding of p to float, plus
    // the sphere's own size for the Embree-side float bounds.
    it.eps = hit_epsilon(it.p, float(r_));
}

Vec2 Sphere::uv_of(double px, double py, double pz) const {
    const double lx = rot_[0][0] * px + rot_[1][0] * py + rot_[2][0] * pz;
    const double ly = rot_[0][1] * px + rot_[1][1] * py + rot_[2][1] * pz;
    const double lz = rot_[0][2] * px + rot_[1][2] * py + rot_[2][2] * pz;
    double phi = std::atan2(ly, lx);
    if (phi < 0) phi += 2 * 3.14159265358979323846;
    return Vec2(float(phi / (2 * 3.14159265358979323846)),
                float(std::acos(std::min(1.0, std::max(-1.0, lz))) / 3.14159265358979323846));
}

PositionSample Sphere::sample_position(Vec2 u, float) const {
    PositionSample ps;
    Vec3 d = warp::square_to_uniform_sphere(u);
    ps.p = Vec3(float(cx_ + r_ * d.x), float(cy_ + r_ * d.y), float(cz_ + r_ * d.z));
    ps.n = flip_normals ? -d : d;
    ps.uv = uv_of(d.x, d.y, d.z);
    ps.pdf_a = 1.f / area();
    ps.eps = hit_epsilon(ps.p, float(r_));
    return ps;
}

// Cone sampling (PBR4 sec. 6.2.4; Shirley and Wang 1994): from a point
// outside, the sphere covers the cone of half-angle theta_max, sin^2 =
// r^2 / d_c^2; directions uniform in that cone have density
// 1 / (2 pi (1 - cos theta_max)), and each maps to the nearer intersection,
// found from the angle alpha at the centre (PBR4 eqs. 6.9-6.10) rather than
// by a ray cast. Everything in double: for a small sphere far away,
// 1 - cos theta_max ~ sin^2 / 2 keeps no bits in float32 (the bias measured
// in Mitsuba 3's float32 version, reference_scenes/veach_mis/card.md); here
// it is computed as sin^2 / (1 + cos). Inside the sphere (or on it), and for
// inward-facing spheres, area sampling stands.
namespace {
bool sphere_cone(const Sphere& s, const Vec3& ref, double& dc, double& sin2max, double& one_minus_cosmax) {
    if (s.flip_normals) return false;
    double vx = s.cx_ - ref.x, vy = s.cy_ - ref.y, vz = s.cz_ - ref.z;
    double dc2 = vx * vx + vy * vy + vz * vz, r2 = s.r_ * s.r_;
    if (!(dc2 > r2 * (1.0 + 1e-5))) return false;
    dc = std::sqrt(dc2);
    sin2max = r2 / dc2;
    double cosmax = std::sqrt(std::max(0.0, 1.0 - sin2max));
    one_minus_cosmax = sin2max / (1.0 + cosmax);
    // A sphere too small to have a float density (r / d below ~1e-19) falls
    // back on area sampling, in sample_direction and pdf_direction alike.
    float pdf = float(1.0 / (2.0 * 3.14159265358979323846 * one_minus_cosmax));
    return one_minus_cosmax > 0.0 && std::isfinite(pdf);
}
}  // namespace

bool Sphere::sample_direction(const Vec3& ref, Vec2 u, PositionSample& ps, float& pdf_w) const {
    double dc, sin2max, omc;
    if (!sphere_cone(*this, ref, dc, sin2max, omc)) return false;
    double a = double(u.x) * omc;  // 1 - cos theta, uniform on [0, 1 - cos theta_max]
    double cos_t = 1.0 - a, sin2_t = a * (2.0 - a);
    double sin_max = std::sqrt(sin2max);
    double cos_alpha = sin2_t / sin_max + cos_t * std::sqrt(std::max(0.0, 1.0 - sin2_t / sin2max));
    cos_alpha = std::min(1.0, std::max(-1.0, cos_alpha));
    double sin_alpha = std::sqrt(std::max(0.0, 1.0 - cos_alpha * cos_alpha));
    double phi = 2.0 * 3.14159265358979323846 * double(u.y);
    // Frame about the axis z from the centre towards ref; the normal leaves
    // the centre at alpha from it.
    double zx = (ref.x - cx_) / dc, zy = (ref.y - cy_) / dc, zz = (ref.z - cz_) / dc;
    Frame fr(normalize(Vec3(float(zx), float(zy), float(zz))));
    double lx = sin_alpha * std::cos(phi), ly = sin_alpha * std::sin(phi);
    double nx = fr.s.x * lx + fr.t.x * ly + zx * cos_alpha;
    double ny = fr.s.y * lx + fr.t.y * ly + zy * cos_alpha;
    double nz = fr.s.z * lx + fr.t.z * ly + zz * cos_alpha;
    double nl = std::sqrt(nx * nx + ny * ny + nz * nz);
    nx /= nl, ny /= nl, nz /= nl;
    ps.p = Vec3(float(cx_ + r_ * nx), float(cy_ + r_ * ny), float(cz_ + r_ * nz));
    ps.n = Vec3(float(nx), float(ny), float(nz));
    ps.uv = uv_of(nx, ny, nz);
    ps.eps = hit_epsilon(ps.p, float(r_));
    ps.pdf_a = 0.f;  // not by area
    pdf_w = float(1.0 / (2.0 * 3.14159265358979323846 * omc));
    return std::isfinite(pdf_w) && pdf_w > 0.f;
}

float Sphere::pdf_direction(const Vec3& ref, const Vec3& p) const {
    double dc, sin2max, omc;
    if (!sphere_cone(*this, ref, dc, sin2max, omc)) return -1.f;
    return float(1.0 / (2.0 * 3.14159265358979323846 * omc));
}

// ---------------------------------------------------------------- disk
Disk::Disk(const Matrix4& to_world) {
    if (!xf_.set(to_world.data())) throw std::invalid_argument("disk: to_world is singular");
    Vec3 ex = xf_.vector(Vec3(1, 0, 0)), ey = xf_.vector(Vec3(0, 1, 0));
    Vec3 c = cross(ex, ey);
    area_ = kPi * length(c);
    normal_ = normalize(xf_.normal(Vec3(0, 0, 1)));
    Vec3 o = xf_.point(Vec3(0, 0, 0));
    // Bounding box of an ellipse: centre +- sqrt(ex_i^2 + ey_i^2) per axis.
    Vec3 ext(std::sqrt(ex.x * ex.x + ey.x * ey.x), std::sqrt(ex.y * ex.y + ey.y * ey.y),
             std::sqrt(ex.z * ex.z + ey.z * ey.z));
    ext = ext * 1.0001f + Vec3(1e-6f * max_component(abs(o)));
    lo_ = o - ext;
    hi_ = o + ext;
}

RTCGeometry Disk::create_geometry(RTCDevice device, unsigned geom_id) {
    RTCGeometry g = rtcNewGeometry(device, RTC_GEOMETRY_TYPE_USER);
    rtcSetGeometryUserPrimitiveCount(g, 1);
    rtcSetGeometryUserData(g, this);
    rtcSetGeometryBoundsFunction(g, user_bounds<Disk>, nullptr);
    rtcSetGeometryIntersectFunction(g, user_intersect<Disk, disk_intersect_impl<false>>);
    rtcSetGeometryOccludedFunction(g, user_occluded<Disk, disk_intersect_impl<true>>);
    rtcCommitGeometry(g);
    return g;
}

void Disk::fill_interaction(const Ray& ray, const RTCHit& hit, float t, Interaction& it) const {
    it.p = xf_.point(Vec3(hit.u, hit.v, 0.f));
    Vec3 n = flip_normals ? -normal_ : normal_;
    it.n = n;
    it.sh = Frame(n);
    float r = std::sqrt(hit.u * hit.u + hit.v * hit.v);
    // Mitsuba's disk: dp/du = to_world (cos phi, sin phi, 0), radial.
    if (uv_frame && r > 0.f) it.sh = tangent_frame(n, xf_.vector(Vec3(hit.u / r, hit.v / r, 0.f)));
    if (uv_frame) {  // dp/dv = to_world (-y, x, 0) 2 pi (src/shapes/disk.cpp)
        it.dp_du = r > 0.f ? xf_.vector(Vec3(hit.u / r, hit.v / r, 0.f)) : xf_.vector(Vec3(1.f, 0.f, 0.f));
        it.dp_dv = xf_.vector(Vec3(-hit.v, hit.u, 0.f)) * (2.f * kPi);
    }
    float phi = std::atan2(hit.v, hit.u);
    if (phi < 0) phi += 2 * kPi;
    it.uv = Vec2(r, phi * kInv2Pi);
    it.eps = hit_epsilon(it.p, std::sqrt(area_ / kPi));
}

PositionSample Disk::sample_position(Vec2 u, float) const {
    PositionSample ps;
    Vec2 d = warp::square_to_uniform_disk_concentric(u);
    ps.p = xf_.point(Vec3(d.x, d.y, 0.f));
    ps.n = flip_normals ? -normal_ : normal_;
    float phi = std::atan2(d.y, d.x);  // Mitsuba's disk uv (r, phi / 2 pi), as fill_interaction
    if (phi < 0) phi += 2 * kPi;
    ps.uv = Vec2(std::sqrt(d.x * d.x + d.y * d.y), phi * kInv2Pi);
    ps.pdf_a = 1.f / area_;
    ps.eps = hit_epsilon(ps.p, std::sqrt(area_ / kPi));
    return ps;
}

// ---------------------------------------------------------------- cylinder
Cylinder::Cylinder(const Matrix4& rigid, double radius, double length) : r_(radius), len_(length) {
    if (!(radius > 0) || !(length > 0) || !std::isfinite(radius) || !std::isfinite(length))
        throw std::invalid_argument("cylinder: needs a positive radius and length");
    for (int i = 0; i < 3; ++i) {
        for (int j = 0; j < 3; ++j) q_[i][j] = rigid[size_t(4 * i + j)];
        t_[i] = rigid[size_t(4 * i + 3)];
    }
    // The box around both end circles (Mitsuba's bbox()): per axis the
    // circle's half-extent r sqrt(q_i0^2 + q_i1^2), padded for rounding.
    const double e0[3] = {0, 0, 0}, e1[3] = {0, 0, len_};
    double p0[3], p1[3];
    to_world(e0, p0);
    to_world(e1, p1);
    Vec3 lo, hi;
    for (int i = 0; i < 3; ++i) {
        const double x = r_ * std::sqrt(q_[i][0] * q_[i][0] + q_[i][1] * q_[i][1]);
        const double pad = 1e-6 * (std::max(std::fabs(p0[i]), std::fabs(p1[i])) + r_ + len_);
        lo[i] = float(std::min(p0[i], p1[i]) - x - pad);
        hi[i] = float(std::max(p0[i], p1[i]) + x + pad);
    }
    lo_ = lo;
    hi_ = hi;
}

void Cylinder::to_world(const double l[3], double w[3]) const {
    for (int i = 0; i < 3; ++i) w[i] = q_[i][0] * l[0] + q_[i][1] * l[1] + q_[i][2] * l[2] + t_[i];
}

RTCGeometry Cylinder::create_geometry(RTCDevice device, unsigned geom_id) {
    RTCGeometry g = rtcNewGeometry(device, RTC_GEOMETRY_TYPE_USER);
    rtcSetGeometryUserPrimitiveCount(g, 1);
    rtcSetGeometryUserData(g, this);
    rtcSetGeometryBoundsFunction(g, user_bounds<Cylinder>, nullptr);
    rtcSetGeometryIntersectFunction(g, user_intersect<Cylinder, cylinder_intersect_impl<false>>);
    rtcSetGeometryOccludedFunction(g, user_occluded<Cylinder, cylinder_intersect_impl<true>>);
    rtcCommitGeometry(g);
    return g;
}

void Cylinder::fill_interaction(const Ray& ray, const RTCHit&, float t, Interaction& it) const {
    // The hit in the local frame (double), put back on the tube (Mitsuba
    // shifts its point along the normal by the same radial error).
    const double w[3] = {double(ray.o.x) + double(t) * ray.d.x - t_[0], double(ray.o.y) + double(t) * ray.d.y - t_[1],
                         double(ray.o.z) + double(t) * ray.d.z - t_[2]};
    double l[3];
    for (int i = 0; i < 3; ++i) l[i] = q_[0][i] * w[0] + q_[1][i] * w[1] + q_[2][i] * w[2];
    double phi = std::atan2(l[1], l[0]);
    if (phi < 0) phi += 2 * 3.14159265358979323846;
    const double cp = std::cos(phi), sp = std::sin(phi);
    const double z = std::min(len_, std::max(0.0, l[2]));
    const double on[3] = {r_ * cp, r_ * sp, z};
    double p[3];
    to_world(on, p);
    it.p = Vec3(float(p[0]), float(p[1]), float(p[2]));
    it.uv = Vec2(float(phi / (2 * 3.14159265358979323846)), float(z / len_));
    // Radial, outwards: Q (cos phi, sin phi, 0), under a mirror too (as
    // Mitsuba 3.9's cylinder does, measured with its ray_intersect).
    Vec3 n(float(q_[0][0] * cp + q_[0][1] * sp), float(q_[1][0] * cp + q_[1][1] * sp),
           float(q_[2][0] * cp + q_[2][1] * sp));
    n = normalize(n);
    if (flip_normals) n = -n;
    it.n = n;
    it.sh = Frame(n);
    if (uv_frame)
        it.sh = tangent_frame(n, Vec3(float(q_[0][1] * cp - q_[0][0] * sp), float(q_[1][1] * cp - q_[1][0] * sp),
                                      float(q_[2][1] * cp - q_[2][0] * sp)));
    it.eps = hit_epsilon(it.p, float(std::max(r_, len_)));
}

PositionSample Cylinder::sample_position(Vec2 u, float) const {
    // Uniform by area (Mitsuba's sample_position): z = u.x length, phi = 2 pi u.y.
    PositionSample ps;
    const double phi = 2 * 3.14159265358979323846 * double(u.y);
    const double cp = std::cos(phi), sp = std::sin(phi);
    const double l[3] = {r_ * cp, r_ * sp, double(u.x) * len_};
    double p[3];
    to_world(l, p);
    ps.p = Vec3(float(p[0]), float(p[1]), float(p[2]));
    Vec3 n(float(q_[0][0] * cp + q_[0][1] * sp), float(q_[1][0] * cp + q_[1][1] * sp),
           float(q_[2][0] * cp + q_[2][1] * sp));
    n = normalize(n);
    ps.n = flip_normals ? -n : n;
    ps.pdf_a = 1.f / area();
    ps.eps = hit_epsilon(ps.p, float(std::max(r_, len_)));
    return ps;
}

// ---------------------------------------------------------------- instance
Instance::Instance(const Shape* member, const Matrix4& to_world) : member_(member) {
    if (!xf_.set(to_world.data())) throw std::invalid_argument("instance: to_world is singular");
    double nrm = 0;
    for (int i = 0; i < 3; ++i)
        nrm = std::max(nrm, std::fabs(xf_.m[i][0]) + std::fabs(xf_.m[i][1]) + std::fabs(xf_.m[i][2]));
    norm_ = float(nrm);
    bsdf = member->bsdf;
    flip_normals = member->flip_normals;
    medium_interior = member->medium_interior;
    medium_exterior = member->medium_exterior;
    uv_frame = member->uv_frame;
    // The box around the member's box's eight corners, mapped.
    Vec3 mlo = member->bbox_min(), mhi = member->bbox_max();
    lo_ = Vec3(kInf);
    hi_ = Vec3(-kInf);
    for (int c = 0; c < 8; ++c) {
        Vec3 p = xf_.point(Vec3(c & 1 ? mhi.x : mlo.x, c & 2 ? mhi.y : mlo.y, c & 4 ? mhi.z : mlo.z));
        lo_ = vmin(lo_, p);
        hi_ = vmax(hi_, p);
    }
    const Vec3 pad = (abs(lo_) + abs(hi_)) * 1e-6f;
    lo_ = lo_ - pad;
    hi_ = hi_ + pad;
}

RTCGeometry Instance::create_geometry(RTCDevice, unsigned) {
    throw std::logic_error("instance '" + id + "': Embree traces its shapegroup through Scene::add_instance");
}

void Instance::fill_interaction(const Ray& ray, const RTCHit& hit, float t, Interaction& it) const {
    // Embree traced the ray mapped by the inverse (direction not
    // renormalised, so t is the same); the member fills the record there.
    Ray local = ray;
    local.o = xf_.inv_point(ray.o);
    local.d = xf_.inv_vector(ray.d);
    member_->fill_interaction(local, hit, t, it);
    it.p = xf_.point(it.p);
    // Mitsuba 3's instance: normals by the inverse transpose, dp/du as a vector.
    it.n = normalize(xf_.normal(it.n));
    const Vec3 ns = normalize(xf_.normal(it.sh.n));
    it.sh = member_->uv_frame ? tangent_frame(ns, xf_.vector(it.sh.s)) : Frame(ns);
    // The member's offset stretched by the map, plus the rounding of the mapped point.
    it.eps = it.eps * norm_ + hit_epsilon(it.p, 0.f);
}

PositionSample Instance::sample_position(Vec2, float) const {
    throw std::logic_error("instance '" + id + "': shapes in a shapegroup are not sampled by area");
}

float Instance::area() const {
    throw std::logic_error("instance '" + id + "': shapes in a shapegroup have no area emitter or sensor");
}

}  // namespace rm
