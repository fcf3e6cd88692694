// The scene: shapes in an Embree 3 BVH, their BSDFs and emitters, one sensor,
// and what the scene can physically produce (used to build and trace nothing
// the scene cannot show).
#pragma once
#include <embree3/rtcore.h>

#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include "scene/bsdf.h"
#include "scene/desc.h"
#include "scene/dipole.h"
#include "scene/emitter.h"
#include "scene/light_sampler.h"
#include "scene/medium.h"
#include "scene/records.h"
#include "scene/sensor.h"
#include "scene/shape.h"

namespace rm {

// What light transport the scene can produce; estimators skip the rest.
struct SceneFeatures {
    bool has_delta_bsdf = false;   // some surface is specular (caustic/specular classes possible)
    bool has_smooth_bsdf = false;  // some surface is diffuse or glossy
    bool has_area_emitters = false;
    bool has_delta_emitters = false;
    bool has_environment = false;
    bool has_media = false;   // some shape or the sensor references a medium
    bool has_dipole = false;  // some shape has a dipole BSSRDF (only path/volpath render it)
    // Some BSDF has a kNull lobe beside a smooth one (a mask over a diffuse
    // or glossy BSDF): volpath, which samples null lobes before next event
    // estimation, refuses it.
    bool has_masked_smooth = false;
    // Some normal or bump map has flip_invalid_normals: its frame follows
    // the direction a ray arrives from, which on a light path is the light's
    // side, not the camera's; only camera-path estimators accept it.
    bool has_incident_frame = false;
};

// Every ray a render traces, in order, for the Embree-limit benchmark
// (benchmarks/studies/embree_limit.py): the renderer's rays replayed with
// bare Embree calls give the throughput Embree alone would reach on them.
// One log per process, attached by a test hook around a one-thread render
// (a global, not a thread-local: a thread-local in a shared library costs
// a call per access, and the unattached check must stay one load).
struct RayLog {
    std::vector<Ray> rays;
    std::vector<uint8_t> shadow;   // 1: occlusion query, 0: closest hit
    std::vector<uint32_t> sample;  // which camera sample traced it (ray_log_begin_sample)
    uint32_t samples = 0;
};
void attach_ray_log(RayLog* log);  // nullptr detaches
namespace detail {
extern RayLog* g_ray_log;  // scene.cpp; set by attach_ray_log
}
// One load where it is checked (the camera driver, once a sample).
inline bool ray_log_attached() { return detail::g_ray_log != nullptr; }
// The camera driver calls it before each sample's rays (one-ray camera
// path only), so the wavefront replay can group the rays of many samples
// by their rank within each sample.
void ray_log_begin_sample();

// What a replay of a RayLog measured (Scene::replay_grouped).
struct ReplayTiming {
    double seconds = 0;                              // fastest pass
    double closest_seconds = 0, shadow_seconds = 0;  // its closest-hit and shadow queues
    size_t closest = 0;                              // closest-hit queries that hit something
    size_t occluded = 0;                             // occlusion queries that found a blocker
    size_t calls = 0;                                // Embree calls per pass
};

class Scene {
public:
    Scene();
    ~Scene();
    Scene(const Scene&) = delete;
    Scene& operator=(const Scene&) = delete;

    int add_bsdf(const BsdfDesc& desc);
    // positions (3N), indices (3M), normals (3N or empty), uvs (2N or empty); world space.
    // group >= 0 (here and in the other add_* of shapes): the shape goes into
    // that shapegroup (add_shapegroup), in the group's space, instead of
    // the scene; the index returned is then its place in the group.
    int add_mesh(const std::string& id, std::vector<float> positions, std::vector<uint32_t> indices,
                 std::vector<float> normals, std::vector<float> uvs, int bsdf, bool flip_normals, int group = -1);
    // to_world: the unit sphere's object-to-world map (Mitsuba's to_world
    // with translate(center) scale(radius) applied), for the texture
    // coordinates; identity: the sphere's frame is the world's.
    int add_sphere(const std::string& id, Vec3 center, float radius, int bsdf, bool flip_normals,
                   const Matrix4& to_world = identity4(), int group = -1);
    int add_disk(const std::string& id, const Matrix4& to_world, int bsdf, bool flip_normals, int group = -1);
    // Mitsuba 3's cylinder: radius and length, placed by `rigid` (Cylinder in shape.h).
    int add_cylinder(const std::string& id, const Matrix4& rigid, double radius, double length, int bsdf,
                     bool flip_normals, int group = -1);
    // Shapegroups (Mitsuba 3's `shapegroup` + `instance`): add_shapegroup
    // opens an empty group and returns its index; shapes join it through
    // their add_* call's `group`. Once an instance of it exists, a group
    // takes no more shapes. add_instance places the
    // group by to_world: each member becomes one Instance in `shapes`, in
    // a run of consecutive indices, and Embree traces the group once, as a
    // child scene under an instance geometry. Returns the first index (-1
    // for an empty group).
    int add_shapegroup(const std::string& id);
    int add_instance(const std::string& id, int group, const Matrix4& to_world);
    // set_shape_media for member `member` of shapegroup `group` (before its first instance).
    void set_member_media(int group, int member, int interior, int exterior);
    // A vertex_* or face_* attribute of mesh `shape` (Mesh::add_attribute):
    // vertices (or triangles) x channels floats.
    // group >= 0: `shape` is a member index of that shapegroup.
    void add_mesh_attribute(int shape, const MeshAttribute& attribute, int group = -1);
    void add_area_emitter(int shape, const EmitterDesc& desc);
    void add_emitter(const EmitterDesc& desc);
    void set_sensor(const SensorDesc& desc);
    // Media: add_medium returns its index; a shape's interior and exterior
    // media (-1: none) make it a medium boundary (Mitsuba 3's
    // `interior` / `exterior` references). The sensor's medium is
    // SensorDesc::medium.
    int add_medium(const MediumDesc& desc);
    void set_shape_media(int shape, int interior, int exterior);
    // A dipole BSSRDF (Mitsuba 0.6's `dipole` subsurface) on a shape: its
    // boundary is a smooth dielectric of the dipole's IORs whose
    // transmitted light comes back out through the dipole profile.
    // Returns its index in `dipoles`.
    int add_dipole(int shape, const DipoleDesc& desc);
    void commit();  // builds the BVH; the scene is read-only afterwards

    // Closest hit in (ray.tmin, ray.tmax); fills `it` (wi = -ray.d).
    bool intersect(const Ray& ray, Interaction& it) const;
    // The closest hits of up to kPacket coherent rays (camera rays of
    // neighbouring pixels) as one Embree packet (rtcIntersect8, Wald et al.
    // 2001's coherent ray tracing): hit[i] and its[i] as intersect() gives
    // them for rays[i], on the same BVH with the same triangle test.
    static constexpr int kPacket = 8;
    void intersect_packet(const Ray* rays, int n, Interaction* its, bool* hit) const;
    // True when anything blocks the open segment (tmin, tmax).
    bool occluded(const Ray& ray) const;
    // The rays of `log` traced again, one thread, `repeats` times; the
    // fastest pass's seconds. bare: rtcIntersect1 / rtcOccluded1 alone (the
    // limit); else through intersect() / occluded() (our ray set-up, range
    // check and hit record).
    double replay(const RayLog& log, bool bare, int repeats) const;
    // The same rays traced by bare Embree in groups: `width` 4, 8 or 16 for
    // rtcIntersectN / rtcOccludedN packets, 0 for the stream call
    // rtcIntersect1M / rtcOccluded1M over each whole queue (`coherent`
    // sets the context's COHERENT flag), 1 for one ray at a time. With
    // `wavefront` the rays are queued as a wavefront renderer would trace
    // them (all samples' k-th closest-hit rays, then their k-th shadow
    // rays, for k = 0, 1, ...), otherwise in the order they were traced.
    ReplayTiming replay_grouped(const RayLog& log, int width, bool wavefront, bool coherent, int repeats) const;
    // Embree's robust mode (RTC_SCENE_FLAG_ROBUST) on or off, for tests and
    // benchmarks; rebuilds the BVH of a committed scene. commit() turns it
    // on for scenes with meshes, off for analytic shapes alone.
    void set_robust(bool on);
    bool robust() const { return robust_; }
    // Shadow ray from `from` to the point p (or to infinity along d).
    bool visible(const Interaction& from, const DirectSample& ds) const;
    // Shadow ray through media (volpath): the transmittance from `from` (a
    // surface point, or a medium point when from.kind == Medium) to the
    // sample `ds`, starting in `medium` and tracking it across medium
    // boundaries; index-matched (null BSDF) surfaces pass light, any other
    // surface blocks it (returns 0), except with `through_null_lobes` a BSDF
    // with a kNull lobe (thindielectric), passed with its null_transmission
    // as Mitsuba 3's volpath passes it. Beer-Lambert exp(-sigma_t d) per
    // segment, exact for homogeneous media (no sampling noise). `rays`
    // counts the intersection queries.
    // Heterogeneous media estimate their segments by ratio tracking with
    // `sampler`'s random numbers.
    Color transmittance(const Interaction& from, const DirectSample& ds, int medium, uint64_t& rays, Sampler& sampler,
                        bool through_null_lobes = false) const;
    // The medium on the side of `it` that direction d points to: its shape's
    // interior or exterior when the shape is a medium boundary, else `current`.
    static int medium_after(const Interaction& it, const Vec3& d, int current) {
        if (it.medium_inside < 0 && it.medium_outside < 0) return current;
        return dot(d, it.n) > 0.f ? it.medium_outside : it.medium_inside;
    }

    // Emitter selection (scene/light_sampler.h): the sampler of `kind`
    // over this scene's emitters, built on first use (committed scenes).
    const LightSampler& light_sampler(LightSamplerKind kind) const;
    // The one the render in progress uses (LightSamplerUse); uniform
    // outside renders. Every light sample and light path selects here.
    const LightSampler& lights() const { return *active_lights_; }

    std::vector<std::unique_ptr<Shape>> shapes;
    std::vector<std::unique_ptr<Bsdf>> bsdfs;
    std::vector<std::unique_ptr<Emitter>> emitters;
    std::vector<const Emitter*> environment;  // emitters hit by escaping rays
    std::vector<std::unique_ptr<Medium>> media;
    std::vector<std::unique_ptr<Dipole>> dipoles;
    std::unique_ptr<Sensor> sensor;
    SensorDesc sensor_desc;
    SceneFeatures features;
    Vec3 bbox_lo{kInf}, bbox_hi{-kInf};
    bool committed() const { return committed_; }
    // Sphere around the scene's bounding box (unit sphere at the origin for
    // an empty scene): where infinite emitters start their light paths.
    void bounding_sphere(Vec3& center, float& radius) const {
        if (is_finite(bbox_lo) && is_finite(bbox_hi)) {
            center = (bbox_lo + bbox_hi) * 0.5f;
            radius = 0.5f * length(bbox_hi - bbox_lo);
        } else {
            center = Vec3(0.f);
            radius = 1.f;
        }
    }

private:
    friend class LightSamplerUse;
    mutable std::mutex lights_mutex_;
    mutable std::unique_ptr<LightSampler> lights_[3];
    mutable const LightSampler* active_lights_ = nullptr;
    mutable int lights_users_ = 0;
    // The Interaction of a closest hit (intersect, intersect_packet).
    void fill_hit(const Ray& ray, const RTCHit& hit, float t, Interaction& it) const;
    int add_shape(std::unique_ptr<Shape> s, int bsdf, bool flip_normals, int group);
    // A shapegroup: its members (in the group's space) and its Embree scene,
    // committed when its first instance is made.
    struct ShapeGroup {
        std::string id;
        std::vector<std::unique_ptr<Shape>> members;
        RTCScene scene = nullptr;
    };
    std::vector<ShapeGroup> groups_;
    // Member `member` of shapegroup `group`, checked (indices, not yet
    // instanced) for a change before its instances are made; `who` names
    // the caller in the error.
    Shape* editable_member(int group, int member, const char* who);
    RTCDevice device_ = nullptr;
    RTCScene scene_ = nullptr;
    bool committed_ = false;
    bool robust_ = true;
    int sensor_shape_ = -1;
};

// Makes `kind` the scene's selection for its lifetime (one render): the
// sampler every estimator's light samples and light paths use. Renders of
// one scene at the same time must agree on it (std::invalid_argument
// otherwise, naming both).
class LightSamplerUse {
public:
    LightSamplerUse(const Scene& scene, LightSamplerKind kind);
    ~LightSamplerUse();
    LightSamplerUse(const LightSamplerUse&) = delete;
    LightSamplerUse& operator=(const LightSamplerUse&) = delete;

private:
    const Scene& scene_;
};

}  // namespace rm
