#include "scene/scene.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <limits>
#include <mutex>
#include <stdexcept>
#include <string>
#ifdef __SSE2__
#include <emmintrin.h>
#endif

namespace rm {

namespace {
// Embree reports errors through a C callback; remember the last one so the
// next API call can raise it as an exception (never abort on user input).
thread_local std::string g_embree_error;
void embree_error(void*, RTCError code, const char* str) {
    if (code != RTC_ERROR_NONE) g_embree_error = std::string("Embree error: ") + (str ? str : "unknown");
}
void check_embree() {
    if (!g_embree_error.empty()) {
        std::string e = g_embree_error;
        g_embree_error.clear();
        throw std::runtime_error(e);
    }
}
}  // namespace

namespace detail {
RayLog* g_ray_log = nullptr;
}  // namespace detail
using detail::g_ray_log;

namespace {

std::mutex g_ray_log_mutex;  // a render on several threads records safely (in no fixed order)

[[gnu::noinline, gnu::cold]] void log_ray(const Ray& ray, bool shadow) {
    std::lock_guard<std::mutex> lock(g_ray_log_mutex);
    g_ray_log->rays.push_back(ray);
    g_ray_log->shadow.push_back(shadow ? 1 : 0);
    g_ray_log->sample.push_back(g_ray_log->samples);
}
}  // namespace

void attach_ray_log(RayLog* log) { g_ray_log = log; }
void ray_log_begin_sample() {
    std::lock_guard<std::mutex> lock(g_ray_log_mutex);
    if (g_ray_log) ++g_ray_log->samples;
}

Scene::Scene() {
    device_ = rtcNewDevice(nullptr);
    if (!device_) throw std::runtime_error("could not create an Embree device");
    rtcSetDeviceErrorFunction(device_, embree_error, nullptr);
    scene_ = rtcNewScene(device_);
    // Robust mode is decided at commit(), by the scene's geometry.
    rtcSetSceneBuildQuality(scene_, RTC_BUILD_QUALITY_HIGH);
}

Scene::~Scene() {
    if (scene_) rtcReleaseScene(scene_);
    for (ShapeGroup& g : groups_)
        if (g.scene) rtcReleaseScene(g.scene);
    if (device_) rtcReleaseDevice(device_);
}

int Scene::add_bsdf(const BsdfDesc& desc) {
    bsdfs.push_back(make_bsdf(desc));
    return int(bsdfs.size()) - 1;
}

int Scene::add_shape(std::unique_ptr<Shape> s, int bsdf, bool flip_normals, int group) {
    if (committed_) throw std::logic_error("scene is already committed");
    if (bsdf < 0 || bsdf >= int(bsdfs.size()))
        throw std::invalid_argument("shape '" + s->id + "': bsdf index out of range");
    s->bsdf = bsdf;
    s->flip_normals = flip_normals;
    s->uv_frame = bsdfs[size_t(bsdf)]->anisotropic();
    if (bsdfs[size_t(bsdf)]->perturbs_frame()) s->frame_map = bsdfs[size_t(bsdf)].get();
    Vec3 lo = s->bbox_min(), hi = s->bbox_max();
    if (!is_finite(lo) || !is_finite(hi)) throw std::invalid_argument("shape '" + s->id + "': non-finite geometry");
    if (group >= 0) {
        if (group >= int(groups_.size()))
            throw std::invalid_argument("shape '" + s->id + "': shapegroup index out of range");
        ShapeGroup& g = groups_[size_t(group)];
        if (g.scene)
            throw std::invalid_argument("shapegroup '" + g.id + "' is already instanced; shape '" + s->id +
                                        "' cannot join it");
        g.members.push_back(std::move(s));
        return int(g.members.size()) - 1;
    }
    bbox_lo = vmin(bbox_lo, lo);
    bbox_hi = vmax(bbox_hi, hi);
    unsigned geom_id = unsigned(shapes.size());
    RTCGeometry g = s->create_geometry(device_, geom_id);
    check_embree();
    rtcAttachGeometryByID(scene_, g, geom_id);
    rtcReleaseGeometry(g);
    check_embree();
    shapes.push_back(std::move(s));
    return int(geom_id);
}

int Scene::add_mesh(const std::string& id, std::vector<float> positions, std::vector<uint32_t> indices,
                    std::vector<float> normals, std::vector<float> uvs, int bsdf, bool flip_normals, int group) {
    size_t nv = positions.size() / 3;
    if (positions.size() % 3 != 0 || indices.size() % 3 != 0)
        throw std::invalid_argument("shape '" + id + "': positions and indices must come in triples");
    if (indices.empty()) throw std::invalid_argument("shape '" + id + "': mesh has no triangles");
    for (float v : positions)
        if (!std::isfinite(v)) throw std::invalid_argument("shape '" + id + "': non-finite vertex position");
    for (uint32_t i : indices)
        if (i >= nv)
            throw std::invalid_argument("shape '" + id + "': vertex index " + std::to_string(i) + " out of range");
    if (!normals.empty() && normals.size() != positions.size())
        throw std::invalid_argument("shape '" + id + "': normals must match positions");
    if (!uvs.empty() && uvs.size() != 2 * nv)
        throw std::invalid_argument("shape '" + id + "': uvs must match positions");
    auto m = std::make_unique<Mesh>(std::move(positions), std::move(indices), std::move(normals), std::move(uvs));
    m->id = id;
    return add_shape(std::move(m), bsdf, flip_normals, group);
}

void Scene::add_mesh_attribute(int shape, const MeshAttribute& attribute, int group) {
    if (committed_) throw std::logic_error("scene is already committed");
    Shape* target = nullptr;
    if (group >= 0) {  // `shape` is a member of that shapegroup (its instances read the member's attributes)
        target = editable_member(group, shape, "add_mesh_attribute");
    } else {
        if (shape < 0 || size_t(shape) >= shapes.size())
            throw std::invalid_argument("add_mesh_attribute: no such shape");
        target = shapes[size_t(shape)].get();
    }
    auto* mesh = dynamic_cast<Mesh*>(target);
    if (!mesh)
        throw std::invalid_argument("shape '" + target->id + "': attribute '" + attribute.name +
                                    "': only meshes carry attributes");
    for (float v : attribute.data)
        if (!std::isfinite(v))
            throw std::invalid_argument("shape '" + mesh->id + "': attribute '" + attribute.name + "' is not finite");
    mesh->add_attribute(attribute);
}

int Scene::add_sphere(const std::string& id, Vec3 center, float radius, int bsdf, bool flip_normals,
                      const Matrix4& to_world, int group) {
    if (!(radius > 0.f) || !std::isfinite(radius) || !is_finite(center))
        throw std::invalid_argument("shape '" + id + "': sphere needs a finite centre and a positive radius");
    auto s = std::make_unique<Sphere>(center, radius, to_world);
    s->id = id;
    return add_shape(std::move(s), bsdf, flip_normals, group);
}

int Scene::add_disk(const std::string& id, const Matrix4& to_world, int bsdf, bool flip_normals, int group) {
    std::unique_ptr<Disk> d;
    try {
        d = std::make_unique<Disk>(to_world);
    } catch (const std::invalid_argument& e) {
        throw std::invalid_argument("shape '" + id + "': " + e.what());
    }
    d->id = id;
    return add_shape(std::move(d), bsdf, flip_normals, group);
}

int Scene::add_cylinder(const std::string& id, const Matrix4& rigid, double radius, double length, int bsdf,
                        bool flip_normals, int group) {
    std::unique_ptr<Cylinder> c;
    try {
        c = std::make_unique<Cylinder>(rigid, radius, length);
    } catch (const std::invalid_argument& e) {
        throw std::invalid_argument("shape '" + id + "': " + e.what());
    }
    c->id = id;
    return add_shape(std::move(c), bsdf, flip_normals, group);
}

int Scene::add_shapegroup(const std::string& id) {
    if (committed_) throw std::logic_error("scene is already committed");
    groups_.push_back(ShapeGroup{id, {}, nullptr});
    return int(groups_.size()) - 1;
}

int Scene::add_instance(const std::string& id, int group, const Matrix4& to_world) {
    if (committed_) throw std::logic_error("scene is already committed");
    if (group < 0 || group >= int(groups_.size()))
        throw std::invalid_argument("instance '" + id + "': shapegroup index out of range");
    ShapeGroup& g = groups_[size_t(group)];
    if (g.members.empty()) return -1;
    if (!g.scene) {
        g.scene = rtcNewScene(device_);
        rtcSetSceneFlags(g.scene, RTC_SCENE_FLAG_ROBUST);
        rtcSetSceneBuildQuality(g.scene, RTC_BUILD_QUALITY_HIGH);
        for (size_t i = 0; i < g.members.size(); ++i) {
            RTCGeometry geom = g.members[i]->create_geometry(device_, unsigned(i));
            check_embree();
            rtcAttachGeometryByID(g.scene, geom, unsigned(i));
            rtcReleaseGeometry(geom);
            check_embree();
        }
        rtcCommitScene(g.scene);
        check_embree();
    }
    // One Instance per member at indices first .. first + n - 1; the
    // top-level instance geometry takes the id `first`, so a hit's shape is
    // instID + geomID (intersect()).
    const int first = int(shapes.size());
    std::vector<std::unique_ptr<Instance>> made;
    for (const auto& m : g.members) {
        try {
            made.push_back(std::make_unique<Instance>(m.get(), to_world));
        } catch (const std::invalid_argument& e) {
            throw std::invalid_argument("instance '" + id + "': " + e.what());
        }
        made.back()->id = id + " (" + m->id + ")";
        Vec3 lo = made.back()->bbox_min(), hi = made.back()->bbox_max();
        if (!is_finite(lo) || !is_finite(hi)) throw std::invalid_argument("instance '" + id + "': non-finite geometry");
    }
    RTCGeometry inst = rtcNewGeometry(device_, RTC_GEOMETRY_TYPE_INSTANCE);
    rtcSetGeometryInstancedScene(inst, g.scene);
    float xfm[12];
    for (int i = 0; i < 12; ++i) xfm[i] = float(to_world[size_t(i)]);
    rtcSetGeometryTransform(inst, 0, RTC_FORMAT_FLOAT3X4_ROW_MAJOR, xfm);
    rtcCommitGeometry(inst);
    rtcAttachGeometryByID(scene_, inst, unsigned(first));
    rtcReleaseGeometry(inst);
    check_embree();
    for (auto& m : made) {
        bbox_lo = vmin(bbox_lo, m->bbox_min());
        bbox_hi = vmax(bbox_hi, m->bbox_max());
        shapes.push_back(std::move(m));
    }
    return first;
}

void Scene::add_area_emitter(int shape, const EmitterDesc& desc) {
    if (shape < 0 || shape >= int(shapes.size())) throw std::invalid_argument("area emitter: shape index out of range");
    if (shapes[shape]->emitter >= 0)
        throw std::invalid_argument("shape '" + shapes[shape]->id + "' already has an emitter");
    emitters.push_back(make_area_emitter(desc, shapes[shape].get()));
    emitters.back()->index = int(emitters.size()) - 1;
    shapes[shape]->emitter = int(emitters.size()) - 1;
    features.has_area_emitters = true;
}

void Scene::add_emitter(const EmitterDesc& desc) {
    emitters.push_back(make_emitter(desc));
    emitters.back()->index = int(emitters.size()) - 1;
    const Emitter* e = emitters.back().get();
    if (e->is_environment()) {
        environment.push_back(e);
        features.has_environment = true;
    }
    if (e->is_delta()) features.has_delta_emitters = true;
}

void Scene::set_sensor(const SensorDesc& desc) {
    sensor_desc = desc;
    const Shape* s = nullptr;
    if (desc.type == "irradiancemeter") {
        if (desc.shape < 0 || desc.shape >= int(shapes.size()))
            throw std::invalid_argument("sensor: irradiancemeter shape index out of range");
        s = shapes[desc.shape].get();
    }
    sensor = make_sensor(desc, s);
    sensor_shape_ = desc.shape;
}

int Scene::add_medium(const MediumDesc& desc) {
    if (committed_) throw std::logic_error("scene is already committed");
    media.push_back(std::make_unique<Medium>(desc));
    return int(media.size()) - 1;
}

void Scene::set_shape_media(int shape, int interior, int exterior) {
    if (shape < 0 || shape >= int(shapes.size()))
        throw std::invalid_argument("set_shape_media: shape index out of range");
    for (int m : {interior, exterior})
        if (m < -1 || m >= int(media.size()))
            throw std::invalid_argument("shape '" + shapes[shape]->id + "': medium index out of range");
    shapes[shape]->medium_interior = interior;
    shapes[shape]->medium_exterior = exterior;
}

Shape* Scene::editable_member(int group, int member, const char* who) {
    if (group < 0 || group >= int(groups_.size()))
        throw std::invalid_argument(std::string(who) + ": shapegroup index out of range");
    ShapeGroup& g = groups_[size_t(group)];
    if (member < 0 || member >= int(g.members.size()))
        throw std::invalid_argument("shapegroup '" + g.id + "': member index out of range");
    if (g.scene) throw std::invalid_argument("shapegroup '" + g.id + "' is already instanced");
    return g.members[size_t(member)].get();
}

void Scene::set_member_media(int group, int member, int interior, int exterior) {
    Shape* m = editable_member(group, member, "set_member_media");
    for (int i : {interior, exterior})
        if (i < -1 || i >= int(media.size()))
            throw std::invalid_argument("shape '" + m->id + "': medium index out of range");
    m->medium_interior = interior;
    m->medium_exterior = exterior;
}

int Scene::add_dipole(int shape, const DipoleDesc& desc) {
    if (committed_) throw std::logic_error("scene is already committed");
    if (shape < 0 || shape >= int(shapes.size())) throw std::invalid_argument("add_dipole: shape index out of range");
    if (shapes[shape]->dipole >= 0)
        throw std::invalid_argument("shape '" + shapes[shape]->id + "' already has a subsurface model");
    dipoles.push_back(std::make_unique<Dipole>(desc));
    shapes[shape]->dipole = int(dipoles.size()) - 1;
    features.has_dipole = true;
    return shapes[shape]->dipole;
}

// Embree's single-ray queries require finite rays whose origin and direction
// components lie within +-1.844e18 (its FLT_LARGE; RayK::valid() in
// kernels/common/ray.h) and assert otherwise, which aborts the process. A
// ray outside that range has lost all float32 precision anyway, so it is an
// error that names the limit, raised as an exception (never an abort).
constexpr float kEmbreeRayLimit = 1.844e18f;
constexpr int32_t kRayLimitBits = __builtin_bit_cast(int32_t, kEmbreeRayLimit);

void Scene::commit() {
    if (!sensor) throw std::invalid_argument("scene has no sensor");
    if (sensor_desc.medium < -1 || sensor_desc.medium >= int(media.size()))
        throw std::invalid_argument("sensor: medium index out of range");
    // Embree's robust mode where the scene needs it: where triangles share
    // edges (every mesh, rectangles and cubes included), rays through those
    // edges slip between the triangles without it (tests/test_rays.py: 0.4 %
    // of rays aimed at a cube's edges with one direction component 0; none
    // robust). It costs 38 % of Embree's instructions, 13 % of `path`'s
    // (docs/performance.md), so scenes of analytic shapes alone (our own
    // double-precision sphere and disk tests, no shared edges) go without.
    // Any other kind of shape (a new one, or one that holds meshes) keeps it.
    robust_ = !std::all_of(shapes.begin(), shapes.end(), [](const std::unique_ptr<Shape>& s) {
        return dynamic_cast<const Sphere*>(s.get()) || dynamic_cast<const Disk*>(s.get());
    });
    rtcSetSceneFlags(scene_, robust_ ? RTC_SCENE_FLAG_ROBUST : RTC_SCENE_FLAG_NONE);
    rtcCommitScene(scene_);
    check_embree();
    // Refuse what float32 ray tracing cannot represent (check_ray below) before
    // any render starts: the sensor's position and the geometry's extent.
    const Matrix4& m = sensor_desc.to_world;
    double far_coord = std::max({std::fabs(m[3]), std::fabs(m[7]), std::fabs(m[11])});
    if (!(far_coord <= kEmbreeRayLimit))
        throw std::invalid_argument("sensor: its position (|coordinate| " + std::to_string(far_coord) +
                                    ") is beyond what float32 ray tracing represents (Embree's limit 1.8e18)");
    if (!shapes.empty()) {
        RTCBounds b;
        rtcGetSceneBounds(scene_, &b);
        double ext = std::max({std::fabs(b.lower_x), std::fabs(b.lower_y), std::fabs(b.lower_z), std::fabs(b.upper_x),
                               std::fabs(b.upper_y), std::fabs(b.upper_z)});
        if (!(ext <= kEmbreeRayLimit))
            throw std::invalid_argument("scene: its geometry reaches |coordinate| " + std::to_string(ext) +
                                        ", beyond what float32 ray tracing represents (Embree's limit 1.8e18)");
    }
    for (const auto& s : shapes) {
        uint32_t f = bsdfs[s->bsdf]->flags();
        // A null lobe beside others (mask) is a delta vertex of its paths.
        if ((f & (kDeltaReflection | kDeltaTransmission)) || ((f & kNull) && f != kNull))
            features.has_delta_bsdf = true;
        if ((f & kNull) && (f & kSmooth)) features.has_masked_smooth = true;
        if (bsdfs[s->bsdf]->frame_follows_wi()) features.has_incident_frame = true;
        if (f & kSmooth) features.has_smooth_bsdf = true;
        if (s->medium_interior >= 0 || s->medium_exterior >= 0) features.has_media = true;
        if (s->dipole >= 0) features.has_smooth_bsdf = true;  // the exit lobe (dipole.h)
    }
    if (sensor_desc.medium >= 0) features.has_media = true;
    committed_ = true;
    active_lights_ = &light_sampler(LightSamplerKind::Uniform);
}

const LightSampler& Scene::light_sampler(LightSamplerKind kind) const {
    if (!committed_) throw std::logic_error("light_sampler: the scene is not committed");
    std::lock_guard<std::mutex> lock(lights_mutex_);
    std::unique_ptr<LightSampler>& slot = lights_[int(kind)];
    if (!slot) {
        Vec3 c;
        float r;
        bounding_sphere(c, r);
        std::vector<LightBounds> b(emitters.size());
        std::vector<bool> inf(emitters.size());
        if (kind != LightSamplerKind::Uniform)
            for (size_t i = 0; i < emitters.size(); ++i) {
                inf[i] = kind == LightSamplerKind::Tree ? !emitters[i]->light_bounds(b[i]) : true;
                b[i].phi = emitters[i]->power(r);
            }
        slot = std::make_unique<LightSampler>(kind, std::move(b), std::move(inf));
    }
    return *slot;
}

LightSamplerUse::LightSamplerUse(const Scene& scene, LightSamplerKind kind) : scene_(scene) {
    const LightSampler& want = scene.light_sampler(kind);
    std::lock_guard<std::mutex> lock(scene.lights_mutex_);
    if (scene.lights_users_ > 0 && scene.active_lights_ != &want)
        throw std::invalid_argument(std::string("light_sampler '") + light_sampler_name(kind) +
                                    "': another render of this scene is running with light_sampler '" +
                                    light_sampler_name(scene.active_lights_->kind()) +
                                    "'; render them one after the other");
    scene.active_lights_ = &want;
    ++scene.lights_users_;
}

LightSamplerUse::~LightSamplerUse() {
    std::lock_guard<std::mutex> lock(scene_.lights_mutex_);
    if (--scene_.lights_users_ == 0) scene_.active_lights_ = scene_.lights_[int(LightSamplerKind::Uniform)].get();
}

static bool ray_in_range(const Ray& ray) {
#ifdef __SSE2__
    // The same test on two 4-wide integer registers (o.x o.y o.z d.x | d.y
    // d.z tmin tmax): for |x| as bits, x <= limit is bits <= the limit's
    // bits, and a NaN's bits exceed infinity's. About ten instructions.
    static_assert(sizeof(Ray) == 8 * sizeof(float), "Ray: o, d, tmin, tmax");
    static_assert(std::numeric_limits<float>::is_iec559, "IEEE floats");
    alignas(16) static const int32_t kAbs[4] = {0x7fffffff, 0x7fffffff, 0x7fffffff, 0x7fffffff};
    alignas(16) static const int32_t kLimA[4] = {kRayLimitBits, kRayLimitBits, kRayLimitBits, kRayLimitBits};
    alignas(16) static const int32_t kLimB[4] = {kRayLimitBits, kRayLimitBits, 0x7f800000, 0x7f800000};
    const __m128i abs = _mm_load_si128(reinterpret_cast<const __m128i*>(kAbs));
    const __m128i a = _mm_and_si128(_mm_loadu_si128(reinterpret_cast<const __m128i*>(&ray)), abs);
    const __m128i b = _mm_and_si128(_mm_loadu_si128(reinterpret_cast<const __m128i*>(&ray) + 1), abs);
    const __m128i bad = _mm_or_si128(_mm_cmpgt_epi32(a, _mm_load_si128(reinterpret_cast<const __m128i*>(kLimA))),
                                     _mm_cmpgt_epi32(b, _mm_load_si128(reinterpret_cast<const __m128i*>(kLimB))));
    return _mm_movemask_epi8(bad) == 0;
#else
    auto ok = [](const Vec3& v) {
        return std::fabs(v.x) <= kEmbreeRayLimit && std::fabs(v.y) <= kEmbreeRayLimit &&
               std::fabs(v.z) <= kEmbreeRayLimit;
    };
    return ok(ray.o) && ok(ray.d) && !std::isnan(ray.tmin) && !std::isnan(ray.tmax);
#endif
}

// The refusal, out of the intersection's line (its message buffer too).
[[gnu::noinline, gnu::cold]] static void ray_out_of_range(const Ray& ray) {
    char buf[320];
    std::snprintf(buf, sizeof buf,
                  "a ray left what float32 ray tracing can represent (origin (%g, %g, %g), direction (%g, %g, %g); "
                  "Embree's limit is |x| <= 1.8e18 and finite): the scene, the sensor or a medium's mean free path "
                  "is beyond the renderer's range",
                  ray.o.x, ray.o.y, ray.o.z, ray.d.x, ray.d.y, ray.d.z);
    throw std::domain_error(buf);
}

static void check_ray(const Ray& ray) {
    if (!ray_in_range(ray)) ray_out_of_range(ray);
}

// Embree's one-ray record of `ray` (intersect, occluded and the replay of
// the Embree-limit benchmark set it up alike).
static void to_rtc(const Ray& ray, RTCRay& r) {
    r.org_x = ray.o.x;
    r.org_y = ray.o.y;
    r.org_z = ray.o.z;
    r.dir_x = ray.d.x;
    r.dir_y = ray.d.y;
    r.dir_z = ray.d.z;
    r.tnear = ray.tmin;
    r.tfar = ray.tmax;
    r.mask = 0xFFFFFFFFu;
    r.flags = 0;
    r.time = 0;
}

bool Scene::intersect(const Ray& ray, Interaction& it) const {
    check_ray(ray);
    if (__builtin_expect(g_ray_log != nullptr, 0)) log_ray(ray, false);
    RTCIntersectContext ctx;
    rtcInitIntersectContext(&ctx);
    RTCRayHit rh;
    to_rtc(ray, rh.ray);
    rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
    rh.hit.instID[0] = RTC_INVALID_GEOMETRY_ID;
    rtcIntersect1(scene_, &ctx, &rh);
    if (rh.hit.geomID == RTC_INVALID_GEOMETRY_ID) {
        it.valid = false;
        return false;
    }
    fill_hit(ray, rh.hit, rh.ray.tfar, it);
    return true;
}

void Scene::fill_hit(const Ray& ray, const RTCHit& hit, float t, Interaction& it) const {
    // A hit inside a shapegroup's instance names the member by geomID and
    // the instance by instID, whose Instances start at index instID.
    const unsigned index = hit.instID[0] == RTC_INVALID_GEOMETRY_ID ? hit.geomID : hit.instID[0] + hit.geomID;
    const Shape& s = *shapes[index];
    // Every field is set here or by fill_interaction (no second zeroing).
    it.kind = VertexKind::Surface;
    it.medium_inside = s.medium_interior;
    it.medium_outside = s.medium_exterior;
    it.valid = true;
    it.t = t;
    it.shape = int(index);
    it.prim = int(hit.primID);
    it.wi = -ray.d;
    s.fill_interaction(ray, hit, t, it);
    it.n_base = Vec3(0.f, 0.f, 1.f);
    if (s.frame_map) s.frame_map->perturb_frame(it);  // normal and bump maps (Bsdf::perturb_frame)
}

// Lane k of an Embree N-wide ray-hit record from `ray` (intersect_packet
// and the grouped replay of the Embree-limit benchmark fill lanes alike).
template <typename RayHitN>
static void to_rtc_lane(const Ray& ray, RayHitN& rh, size_t k) {
    rh.ray.org_x[k] = ray.o.x;
    rh.ray.org_y[k] = ray.o.y;
    rh.ray.org_z[k] = ray.o.z;
    rh.ray.dir_x[k] = ray.d.x;
    rh.ray.dir_y[k] = ray.d.y;
    rh.ray.dir_z[k] = ray.d.z;
    rh.ray.tnear[k] = ray.tmin;
    rh.ray.tfar[k] = ray.tmax;
    rh.ray.mask[k] = 0xFFFFFFFFu;
    rh.ray.flags[k] = 0;
    rh.ray.time[k] = 0;
    rh.hit.geomID[k] = RTC_INVALID_GEOMETRY_ID;
    rh.hit.instID[0][k] = RTC_INVALID_GEOMETRY_ID;
}

void Scene::intersect_packet(const Ray* rays, int n, Interaction* its, bool* hit) const {
    static_assert(kPacket == 8, "rtcIntersect8 below");
    alignas(32) int valid[8] = {0, 0, 0, 0, 0, 0, 0, 0};
    RTCRayHit8 rh;
    for (int i = 0; i < n; ++i) {
        const Ray& ray = rays[i];
        check_ray(ray);
        if (__builtin_expect(g_ray_log != nullptr, 0)) log_ray(ray, false);
        valid[i] = -1;
        to_rtc_lane(ray, rh, size_t(i));
    }
    RTCIntersectContext ctx;
    rtcInitIntersectContext(&ctx);
    ctx.flags = RTC_INTERSECT_CONTEXT_FLAG_COHERENT;
    rtcIntersect8(valid, scene_, &ctx, &rh);
    for (int i = 0; i < n; ++i) {
        hit[i] = rh.hit.geomID[i] != RTC_INVALID_GEOMETRY_ID;
        if (!hit[i]) {
            its[i].valid = false;
            continue;
        }
        RTCHit h;
        h.Ng_x = rh.hit.Ng_x[i];
        h.Ng_y = rh.hit.Ng_y[i];
        h.Ng_z = rh.hit.Ng_z[i];
        h.u = rh.hit.u[i];
        h.v = rh.hit.v[i];
        h.primID = rh.hit.primID[i];
        h.geomID = rh.hit.geomID[i];
        h.instID[0] = rh.hit.instID[0][i];
        fill_hit(rays[i], h, rh.ray.tfar[i], its[i]);
    }
}

bool Scene::occluded(const Ray& ray) const {
    check_ray(ray);
    if (__builtin_expect(g_ray_log != nullptr, 0)) log_ray(ray, true);
    RTCIntersectContext ctx;
    rtcInitIntersectContext(&ctx);
    RTCRay r;
    to_rtc(ray, r);
    rtcOccluded1(scene_, &ctx, &r);
    return r.tfar < 0.f;
}

void Scene::set_robust(bool on) {
    // Instances leave gaps in the geometry ids (add_instance): not needed here.
    if (committed_ && !groups_.empty()) throw std::logic_error("set_robust: not for a scene with instances");
    robust_ = on;
    rtcSetSceneFlags(scene_, on ? RTC_SCENE_FLAG_ROBUST : RTC_SCENE_FLAG_NONE);
    if (committed_) {
        // Embree rebuilds a committed scene only when a geometry changed,
        // not for new flags alone: mark every geometry changed.
        for (unsigned id = 0; id < unsigned(shapes.size()); ++id) rtcCommitGeometry(rtcGetGeometry(scene_, id));
        rtcCommitScene(scene_);
    }
    check_embree();
}

namespace {
// One queue of a grouped replay: its rays copied out of the log in queue
// order, so the timed loop reads them contiguously (as a wavefront renderer
// reads its ray queues).
struct ReplayQueue {
    bool shadow;
    std::vector<Ray> rays;
};

// The log's rays as queues: in the log's order (closest-hit and shadow
// rays apart, each in order), or as a wavefront renderer queues them.
std::vector<ReplayQueue> replay_queues(const RayLog& log, bool wavefront) {
    std::vector<ReplayQueue> q;
    if (!wavefront) {
        q.push_back({false, {}});
        q.push_back({true, {}});
        for (size_t i = 0; i < log.rays.size(); ++i) q[log.shadow[i] ? 1 : 0].rays.push_back(log.rays[i]);
        return q;
    }
    // Rank of each ray among its sample's rays of the same kind; queue 2k
    // holds every sample's k-th closest-hit ray, 2k + 1 its k-th shadow ray.
    uint32_t cur = ~0u, rank[2] = {0, 0};
    for (size_t i = 0; i < log.rays.size(); ++i) {
        if (log.sample[i] != cur) {
            cur = log.sample[i];
            rank[0] = rank[1] = 0;
        }
        const int kind = log.shadow[i] ? 1 : 0;
        const size_t qi = 2 * size_t(rank[kind]++) + size_t(kind);
        while (q.size() <= qi) q.push_back({q.size() % 2 == 1, {}});
        q[qi].rays.push_back(log.rays[i]);
    }
    return q;
}

template <int N, typename RayHitN, typename RayN>
void replay_packets(RTCScene scene, const ReplayQueue& queue, ReplayTiming& t) {
    RTCIntersectContext ctx;
    rtcInitIntersectContext(&ctx);
    const size_t n = queue.rays.size();
    for (size_t a = 0; a < n; a += N) {
        alignas(64) int valid[N];
        RayHitN rh;
        const size_t m = std::min(n - a, size_t(N));
        for (size_t k = 0; k < size_t(N); ++k) {
            valid[k] = k < m ? -1 : 0;
            to_rtc_lane(queue.rays[a + std::min(k, m - 1)], rh, k);
        }
        ++t.calls;
        if (queue.shadow) {
            if constexpr (N == 4) rtcOccluded4(valid, scene, &ctx, reinterpret_cast<RTCRay4*>(&rh.ray));
            if constexpr (N == 8) rtcOccluded8(valid, scene, &ctx, reinterpret_cast<RTCRay8*>(&rh.ray));
            if constexpr (N == 16) rtcOccluded16(valid, scene, &ctx, reinterpret_cast<RTCRay16*>(&rh.ray));
            for (size_t k = 0; k < m; ++k) t.occluded += rh.ray.tfar[k] < 0.f;
        } else {
            if constexpr (N == 4) rtcIntersect4(valid, scene, &ctx, &rh);
            if constexpr (N == 8) rtcIntersect8(valid, scene, &ctx, &rh);
            if constexpr (N == 16) rtcIntersect16(valid, scene, &ctx, &rh);
            for (size_t k = 0; k < m; ++k) t.closest += rh.hit.geomID[k] != RTC_INVALID_GEOMETRY_ID;
        }
    }
}

void replay_stream(RTCScene scene, const ReplayQueue& queue, bool coherent, std::vector<RTCRayHit>& buf,
                   ReplayTiming& t) {
    RTCIntersectContext ctx;
    rtcInitIntersectContext(&ctx);
    ctx.flags = coherent ? RTC_INTERSECT_CONTEXT_FLAG_COHERENT : RTC_INTERSECT_CONTEXT_FLAG_INCOHERENT;
    const size_t n = queue.rays.size();
    buf.resize(n);
    for (size_t k = 0; k < n; ++k) {
        to_rtc(queue.rays[k], buf[k].ray);
        buf[k].hit.geomID = RTC_INVALID_GEOMETRY_ID;
        buf[k].hit.instID[0] = RTC_INVALID_GEOMETRY_ID;
    }
    ++t.calls;
    if (queue.shadow) {
        rtcOccluded1M(scene, &ctx, reinterpret_cast<RTCRay*>(buf.data()), unsigned(n), sizeof(RTCRayHit));
        for (size_t k = 0; k < n; ++k) t.occluded += buf[k].ray.tfar < 0.f;
    } else {
        rtcIntersect1M(scene, &ctx, buf.data(), unsigned(n), sizeof(RTCRayHit));
        for (size_t k = 0; k < n; ++k) t.closest += buf[k].hit.geomID != RTC_INVALID_GEOMETRY_ID;
    }
}

// One ray by bare Embree, as the renderer's Scene::intersect / occluded
// would trace it.
void replay_one(RTCScene scene, const Ray& ray, bool shadow, ReplayTiming& t) {
    RTCIntersectContext ctx;
    rtcInitIntersectContext(&ctx);
    RTCRayHit rh;
    to_rtc(ray, rh.ray);
    ++t.calls;
    if (shadow) {
        rtcOccluded1(scene, &ctx, &rh.ray);
        t.occluded += rh.ray.tfar < 0.f;
    } else {
        rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
        rh.hit.instID[0] = RTC_INVALID_GEOMETRY_ID;
        rtcIntersect1(scene, &ctx, &rh);
        t.closest += rh.hit.geomID != RTC_INVALID_GEOMETRY_ID;
    }
}

}  // namespace

double Scene::replay(const RayLog& log, bool bare, int repeats) const {
    if (!committed_) throw std::logic_error("replay: the scene is not committed");
    double best = kInf;
    for (int r = 0; r < std::max(repeats, 1); ++r) {
        ReplayTiming t;
        auto t0 = std::chrono::steady_clock::now();
        for (size_t i = 0; i < log.rays.size(); ++i) {
            const Ray& ray = log.rays[i];
            if (bare) {
                replay_one(scene_, ray, log.shadow[i] != 0, t);
            } else if (log.shadow[i]) {
                occluded(ray);
            } else {
                Interaction it;
                intersect(ray, it);
            }
        }
        best = std::min(best, std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count());
    }
    return best;
}

ReplayTiming Scene::replay_grouped(const RayLog& log, int width, bool wavefront, bool coherent, int repeats) const {
    if (!committed_) throw std::logic_error("replay_grouped: the scene is not committed");
    if (width != 0 && width != 1 && width != 4 && width != 8 && width != 16)
        throw std::invalid_argument("replay_grouped: width must be 0 (stream), 1, 4, 8 or 16, not " +
                                    std::to_string(width));
    if (wavefront && (log.samples == 0 || log.sample.size() != log.rays.size()))
        throw std::invalid_argument(
            "replay_grouped: the log has no sample marks (only the camera driver's one-ray loop marks them)");
    const std::vector<ReplayQueue> queues = replay_queues(log, wavefront);
    std::vector<RTCRayHit> buf;
    ReplayTiming best;
    best.seconds = kInf;
    for (int r = 0; r < std::max(repeats, 1); ++r) {
        ReplayTiming t;
        auto t0 = std::chrono::steady_clock::now();
        for (const ReplayQueue& q : queues) {
            auto q0 = std::chrono::steady_clock::now();
            switch (width) {
                case 0:
                    replay_stream(scene_, q, coherent, buf, t);
                    break;
                case 1:
                    for (const Ray& ray : q.rays) replay_one(scene_, ray, q.shadow, t);
                    break;
                case 4:
                    replay_packets<4, RTCRayHit4, RTCRay4>(scene_, q, t);
                    break;
                case 8:
                    replay_packets<8, RTCRayHit8, RTCRay8>(scene_, q, t);
                    break;
                default:
                    replay_packets<16, RTCRayHit16, RTCRay16>(scene_, q, t);
                    break;
            }
            const double dt = std::chrono::duration<double>(std::chrono::steady_clock::now() - q0).count();
            (q.shadow ? t.shadow_seconds : t.closest_seconds) += dt;
        }
        t.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
        if (t.seconds < best.seconds) best = t;
    }
    return best;
}

bool Scene::visible(const Interaction& from, const DirectSample& ds) const {
    Ray r = from.spawn(ds.d);
    if (std::isinf(ds.dist)) {
        r.tmax = kInf;
        return !occluded(r);
    }
    // Both ends are pushed off their surfaces (after pbrt-v4's SpawnRayTo):
    // the light point moves towards the shading point's side by its own
    // error bound, and the ray stops just short of it. Without the far offset
    // a shadow ray arriving at a grazing angle crosses the light's own
    // surface before its end (the point's float error, ~1e-7, over cos ~0.1)
    // and is falsely occluded: measured -0.03 % direct light in a closed
    // cube furnace.
    Vec3 to = ds.p;
    if (length_sq(ds.n) > 0.f) {
        float eps_to = ds.eps > 0.f ? ds.eps : hit_epsilon(to, 0.f);
        to = to + ds.n * (dot(ds.n, r.o - to) >= 0.f ? eps_to : -eps_to);
    }
    Vec3 d = to - r.o;
    float dist = length(d);
    if (!(dist > 0.f)) return true;
    r.d = d / dist;
    r.tmax = dist * (1.f - 1e-4f);
    return !occluded(r);
}

Color Scene::transmittance(const Interaction& from, const DirectSample& ds, int medium, uint64_t& rays,
                           Sampler& sampler, bool through_null_lobes) const {
    Ray r;
    if (from.kind == VertexKind::Medium) {
        r.o = from.p;
        r.d = ds.d;
    } else {
        r = from.spawn(ds.d);
    }
    // The far end as in visible(): pushed off the light's surface.
    Vec3 to = ds.p;
    bool infinite = std::isinf(ds.dist);
    if (!infinite && length_sq(ds.n) > 0.f) {
        float eps_to = ds.eps > 0.f ? ds.eps : hit_epsilon(to, 0.f);
        to = to + ds.n * (dot(ds.n, r.o - to) >= 0.f ? eps_to : -eps_to);
    }
    if (!infinite) {
        Vec3 d = to - r.o;
        float dist = length(d);
        if (!(dist > 0.f)) return Color(1.f);
        r.d = d / dist;
    }
    Color tr(1.f);
    // Each step crosses one index-matched surface; a bound keeps a shadow ray
    // caught between coincident surfaces from looping (it is then dropped).
    for (int step = 0; step < 1024; ++step) {
        float remaining = infinite ? kInf : dot(to - r.o, r.d);
        if (!(remaining > 0.f)) return tr;
        r.tmin = 0.f;
        r.tmax = infinite ? kInf : remaining * (1.f - 1e-4f);
        Interaction it;
        ++rays;
        if (!intersect(r, it)) {
            if (medium >= 0) tr *= media[medium]->segment_transmittance(r.o, r.d, remaining, sampler);
            return tr;
        }
        const Bsdf& b = *bsdfs[shapes[it.shape]->bsdf];
        if (b.flags() != kNull) {
            if (!through_null_lobes || !(b.flags() & kNull)) return Color(0.f);
            BsdfContext ctx;
            ctx.set(it);
            tr *= b.null_transmission(ctx, dot(r.d, it.n));
        }
        if (medium >= 0) tr *= media[medium]->segment_transmittance(r.o, r.d, it.t, sampler);
        if (is_black(tr)) return tr;
        medium = medium_after(it, r.d, medium);
        Vec3 d = r.d;
        r = it.spawn(d);
    }
    return Color(0.f);
}

}  // namespace rm
