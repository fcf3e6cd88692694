// The estimator registry: each estimator declares, once and in its own file,
// its name (and aliases), a one-line description, its parameters (type,
// default, range, description, Mitsuba 0.6 names), its capabilities and a
// factory. Everything else reads the declaration: the parameters of a scene
// are checked against it here (types, ranges, unknown names) before the
// factory reads them, a declared parameter the factory never reads is an
// error, and Python (radiometer.estimators()) lists it for the loader, the
// command line's help and the tests.
//
// Models: pbrt-v4's PathIntegrator::Create (cpu/integrators.cpp), which
// reads its own parameters with their defaults from a ParameterDictionary
// that then reports the ones nobody read (paramdict.h, ReportUnused), and
// the parameter block at the top of Mitsuba 3's src/integrators/path.cpp
// (name, type, description and default of each parameter, beside the code
// that reads it).
//
// Registration, in the estimator's .cpp:
//
//     [[maybe_unused]] const bool kRegistered = register_estimator([] {
//         EstimatorInfo e;
//         e.name = "whitted";
//         e.doc = "...";
//         e.params = {max_depth_param(), ParamSpec::integer("n", 1, "...").at_least(1)};
//         e.factory = [](ParamReader& p) { return std::make_unique<Whitted>(p); };
//         return e;
//     }());
//
// That runs at static initialisation, so the core is linked as an object
// library (CMakeLists.txt): from a static archive the linker would drop the
// object file of an estimator that nothing else references.
#pragma once
#include <functional>
#include <memory>
#include <stdexcept>
#include <string>
#include <vector>

#include "core/params.h"
#include "render/integrator.h"

namespace rm {

// A bad integrator description (unknown estimator, unknown or unused
// parameter, wrong type, out of range); the message names the estimator
// and the parameter. The bindings raise it as radiometer.SceneError.
class ParamError : public std::invalid_argument {
public:
    ParamError(std::string estimator, std::string parameter, const std::string& message)
        : std::invalid_argument(message), estimator_(std::move(estimator)), parameter_(std::move(parameter)) {}
    const std::string& estimator() const { return estimator_; }
    const std::string& parameter() const { return parameter_; }  // empty: the estimator itself

private:
    std::string estimator_, parameter_;
};

// One declared parameter.
struct ParamSpec {
    std::string name;
    ParamType type = ParamType::Int;
    ParamValue default_value;
    bool has_default = true;
    std::string doc;
    // Numbers: the range [min, max], either end open or absent.
    bool has_min = false, has_max = false, min_open = false, max_open = false;
    double min = 0, max = 0;
    // Values with a meaning of their own ("-1: unbounded"), allowed even
    // outside the range.
    std::vector<std::pair<ParamValue, std::string>> special;
    std::vector<std::string> choices;  // strings: the values allowed (empty: any)
    std::vector<std::string> aliases;  // other names for it (Mitsuba 0.6's camelCase)
    // Accepted (and checked) but without effect: Mitsuba's work-unit sizes.
    bool ignored = false;
    // Given, it sets these parameters (Mitsuba's `direct` shading_samples);
    // it has no value of its own.
    std::vector<std::string> sets;

    static ParamSpec integer(std::string name, int64_t def, std::string doc);
    static ParamSpec real(std::string name, double def, std::string doc);
    static ParamSpec boolean(std::string name, bool def, std::string doc);
    static ParamSpec string(std::string name, std::string def, std::string doc);
    // An integer of Mitsuba's that changes nothing here (ignored) or sets
    // others (setting): no default of its own.
    static ParamSpec mitsuba_ignored(std::string name, std::string doc);
    static ParamSpec setting(std::string name, std::vector<std::string> targets, std::string doc);

    ParamSpec& at_least(double v);
    ParamSpec& greater_than(double v);
    ParamSpec& at_most(double v);
    ParamSpec& less_than(double v);
    ParamSpec& with_special(ParamValue v, std::string meaning);
    ParamSpec& one_of(std::vector<std::string> values);
    ParamSpec& alias(std::string other);
    ParamSpec& described(std::string text);

    // The values allowed, as a scene's author reads them: "-1 (unbounded)
    // or >= 1", "(0, 1)", "0..16 (0: none)", "'power', 'balance' or
    // 'uniform'"; empty when any value of the type goes.
    std::string range_text() const;
    // Empty when `v` (already of this type) is allowed, else why not.
    std::string check(const ParamValue& v) const;
};

// The parameters several estimators share, declared once.
ParamSpec max_depth_param();
// Emitter selection (scene/light_sampler.h), shared by every estimator:
// register_estimator adds it to each declaration and make_integrator reads
// it into Integrator::light_sampler, so an estimator's own code never does.
ParamSpec light_sampler_param();
ParamSpec rr_depth_param();
ParamSpec hide_emitters_param();
// The truncation probe of the estimators that estimate what max_depth cuts off.
ParamSpec truncation_probe_param();
// volpath's equiangular distance sampling (volpath.cpp).
ParamSpec equiangular_param();
ParamSpec strategy_images_param();
// The MIS heuristic of the bidirectional estimators (bdpt, vcm, bpm) and
// the power heuristic's exponent.
ParamSpec mis_param();
ParamSpec mis_beta_param();

struct EstimatorInfo;

// The view of its parameters an estimator's factory gets: each get_* reads
// one declared parameter (the scene's value, or the declared default) and
// marks it read. A declared parameter no get_* reads is an error
// (report_unused), so a declaration cannot promise what the code ignores.
class ParamReader {
public:
    ParamReader(const EstimatorInfo& info, std::string name, const ParamSet& values)
        : info_(info), name_(std::move(name)), values_(values) {}
    int get_int(const std::string& param);
    float get_float(const std::string& param);
    bool get_bool(const std::string& param);
    std::string get_string(const std::string& param);
    // A check of the factory's own (several parameters together) failed:
    // throws ParamError naming `param`; `message` follows "integrator 'X': ".
    [[noreturn]] void fail(const std::string& param, const std::string& message) const;
    // The name the scene used (an alias stays an alias: "volpath").
    const std::string& name() const { return name_; }
    // Throws ParamError for the first parameter in `values` that no get_* read.
    void report_unused() const;

private:
    const ParamValue& get(const std::string& param, ParamType type);
    const EstimatorInfo& info_;
    std::string name_;
    const ParamSet& values_;
    std::vector<std::string> read_;
};

using EstimatorFactory = std::function<std::unique_ptr<Integrator>(ParamReader&)>;

struct EstimatorInfo {
    std::string name;
    std::vector<std::string> aliases;  // other names of the same estimator ("volpath" for "path")
    std::string doc;                   // one line
    Capabilities caps;
    std::vector<ParamSpec> params;
    EstimatorFactory factory;

    // The parameter called `name` (or one of its aliases), or null.
    const ParamSpec* param(const std::string& name) const;
};

// Adds an estimator; called from a static initialiser in the estimator's
// file (above). A malformed declaration or a name taken twice is reported
// by the first use of the registry (std::logic_error), not at load time.
bool register_estimator(EstimatorInfo info);
// Every registered estimator, by name.
std::vector<const EstimatorInfo*> registered_estimators();
// The estimator called `name` (or one of its aliases), or null.
const EstimatorInfo* find_estimator(const std::string& name);
// Names the scene format knows whose estimators have not arrived yet.
std::vector<std::string> planned_estimators();

// `given` checked against the declaration (aliases to names, types,
// ranges, unknown names: ParamError) and completed: every parameter with a
// value, in declaration order; the ignored ones dropped.
ParamSet resolve_params(const EstimatorInfo& info, const std::string& name, const ParamSet& given);

// Resolves `desc` and runs its estimator's factory (which may refuse
// combinations of values) without rendering: the resolved parameters.
ParamSet resolve_integrator(const IntegratorDesc& desc);

}  // namespace rm
