#include "render/registry.h"

#include <algorithm>
#include <climits>
#include <cmath>
#include <cstdio>
#include <cstdlib>

namespace rm {

namespace {

// Range ends as a reader writes them: 0, 1, 0.05, 1024.
std::string bound_text(double v) {
    char buf[40];
    for (int prec = 1; prec <= 17; ++prec) {
        std::snprintf(buf, sizeof buf, "%.*g", prec, v);
        if (std::strtod(buf, nullptr) == v) break;
    }
    return buf;
}

std::string join(const std::vector<std::string>& parts, const std::string& sep, const std::string& last_sep) {
    std::string s;
    for (size_t i = 0; i < parts.size(); ++i) {
        if (i > 0) s += i + 1 == parts.size() ? last_sep : sep;
        s += parts[i];
    }
    return s;
}

double as_double(const ParamValue& v) {
    return param_type(v) == ParamType::Int ? double(std::get<int64_t>(v)) : std::get<double>(v);
}

bool same_value(const ParamValue& a, const ParamValue& b) {
    if (param_type(a) == param_type(b)) return a == b;
    bool numbers = param_type(a) != ParamType::Bool && param_type(a) != ParamType::String &&
                   param_type(b) != ParamType::Bool && param_type(b) != ParamType::String;
    return numbers && as_double(a) == as_double(b);
}

std::string prefix(const std::string& estimator) { return "integrator '" + estimator + "': "; }

}  // namespace

// ---- ParamSpec --------------------------------------------------------------

namespace {

ParamSpec declared(std::string name, ParamValue def, std::string doc) {
    ParamSpec s;
    s.name = std::move(name);
    s.type = param_type(def);
    s.default_value = std::move(def);
    s.doc = std::move(doc);
    return s;
}

}  // namespace

ParamSpec ParamSpec::integer(std::string name, int64_t def, std::string doc) {
    return declared(std::move(name), def, std::move(doc));
}
ParamSpec ParamSpec::real(std::string name, double def, std::string doc) {
    return declared(std::move(name), def, std::move(doc));
}
ParamSpec ParamSpec::boolean(std::string name, bool def, std::string doc) {
    return declared(std::move(name), def, std::move(doc));
}
ParamSpec ParamSpec::string(std::string name, std::string def, std::string doc) {
    return declared(std::move(name), std::move(def), std::move(doc));
}

ParamSpec ParamSpec::mitsuba_ignored(std::string name, std::string doc) {
    ParamSpec s = integer(std::move(name), 0, std::move(doc));
    s.has_default = false;
    s.ignored = true;
    return s;
}

ParamSpec ParamSpec::setting(std::string name, std::vector<std::string> targets, std::string doc) {
    ParamSpec s = integer(std::move(name), 0, std::move(doc));
    s.has_default = false;
    s.sets = std::move(targets);
    return s;
}

ParamSpec& ParamSpec::at_least(double v) {
    has_min = true, min_open = false, min = v;
    return *this;
}
ParamSpec& ParamSpec::greater_than(double v) {
    has_min = true, min_open = true, min = v;
    return *this;
}
ParamSpec& ParamSpec::at_most(double v) {
    has_max = true, max_open = false, max = v;
    return *this;
}
ParamSpec& ParamSpec::less_than(double v) {
    has_max = true, max_open = true, max = v;
    return *this;
}
ParamSpec& ParamSpec::with_special(ParamValue v, std::string meaning) {
    special.emplace_back(std::move(v), std::move(meaning));
    return *this;
}
ParamSpec& ParamSpec::one_of(std::vector<std::string> values) {
    choices = std::move(values);
    return *this;
}
ParamSpec& ParamSpec::alias(std::string other) {
    aliases.push_back(std::move(other));
    return *this;
}
ParamSpec& ParamSpec::described(std::string text) {
    doc = std::move(text);
    return *this;
}

namespace {

bool in_interval(const ParamSpec& s, double x) {
    if (s.has_min && (s.min_open ? !(x > s.min) : !(x >= s.min))) return false;
    if (s.has_max && (s.max_open ? !(x < s.max) : !(x <= s.max))) return false;
    return true;
}

std::string interval_text(const ParamSpec& s) {
    if (s.has_min && s.has_max) {
        if (s.type == ParamType::Int && !s.min_open && !s.max_open) return bound_text(s.min) + ".." + bound_text(s.max);
        return std::string(s.min_open ? "(" : "[") + bound_text(s.min) + ", " + bound_text(s.max) +
               (s.max_open ? ")" : "]");
    }
    if (s.has_min) return (s.min_open ? "> " : ">= ") + bound_text(s.min);
    if (s.has_max) return (s.max_open ? "< " : "<= ") + bound_text(s.max);
    return "";
}

}  // namespace

std::string ParamSpec::range_text() const {
    if (!choices.empty()) {
        std::vector<std::string> q;
        for (const std::string& c : choices) q.push_back("'" + c + "'");
        return join(q, ", ", " or ");
    }
    std::string interval = interval_text(*this);
    std::vector<std::string> outside, inside;
    for (const auto& [v, meaning] : special) {
        std::string vt = param_type(v) == ParamType::String ? format_param_value(v) : bound_text(as_double(v));
        if (!interval.empty() && in_interval(*this, as_double(v)))
            inside.push_back(vt + ": " + meaning);
        else
            outside.push_back(vt + " (" + meaning + ")");
    }
    if (interval.empty()) return join(outside, ", ", " or ");
    std::string s = join(outside, ", ", " or ");
    if (!s.empty()) s += " or ";
    s += interval;
    if (!inside.empty()) s += " (" + join(inside, "; ", "; ") + ")";
    return s;
}

std::string ParamSpec::check(const ParamValue& v) const {
    if (type == ParamType::Bool) return "";
    if (type == ParamType::String) {
        const std::string& s = std::get<std::string>(v);
        if (choices.empty() || std::find(choices.begin(), choices.end(), s) != choices.end()) return "";
        return "must be " + range_text();
    }
    double x = as_double(v);
    if (type == ParamType::Float && !std::isfinite(x)) return "must be a finite number";
    if (type == ParamType::Int && (x < double(INT_MIN) || x > double(INT_MAX))) return "must be a 32-bit integer";
    for (const auto& sp : special)
        if (same_value(sp.first, v)) return "";
    // Floats reach the estimator in single precision: that value must be in range too.
    bool ok = in_interval(*this, x) && (type != ParamType::Float || in_interval(*this, double(float(x))));
    if (ok) return "";
    std::string r = range_text();
    if (r[0] == '(' || r[0] == '[') return "must lie in " + r;
    if (r.find("..") != std::string::npos) return "must be in " + r;
    return "must be " + r;
}

ParamSpec light_sampler_param() {
    return ParamSpec::string("light_sampler", "uniform",
                             "emitter selection: 'uniform' (each emitter alike), 'power' (in proportion to its "
                             "power), 'tree' (a light tree seen from the shading point; light paths start by power)")
        .one_of({"uniform", "power", "tree"});
}

ParamSpec max_depth_param() {
    return ParamSpec::integer("max_depth", -1, "longest path in segments")
        .at_least(1)
        .with_special(int64_t(-1), "unbounded");
}

ParamSpec rr_depth_param() {
    return ParamSpec::integer("rr_depth", 5, "path depth from which Russian roulette may stop a path").at_least(1);
}

ParamSpec hide_emitters_param() {
    return ParamSpec::boolean("hide_emitters", false, "directly visible emitters appear black");
}

ParamSpec truncation_probe_param() {
    return ParamSpec::real("truncation_probe", 0.0625,
                           "fraction of the paths stopped by max_depth that go on past it (Russian roulette, weight "
                           "1 / fraction) to estimate the light max_depth cuts off, in res.error_budget; the image "
                           "is unchanged; 0: off")
        .at_least(0.0)
        .at_most(1.0);
}

ParamSpec equiangular_param() {
    return ParamSpec::boolean("equiangular", false,
                              "in homogeneous media, also sample scattering distances equiangularly towards a light "
                              "point (Kulla and Fajardo 2012), combined with free flight by MIS: single scattering "
                              "near point and spot lights; grid media keep free flight alone");
}

ParamSpec mis_param() {
    return ParamSpec::string("mis", "power", "MIS weights: the power or balance heuristic, or uniform weights")
        .one_of({"power", "balance", "uniform"});
}

ParamSpec mis_beta_param() {
    return ParamSpec::real("beta", 2.0, "the power heuristic's exponent (Veach 1997, eq. 9.13)").greater_than(0);
}

ParamSpec strategy_images_param() {
    return ParamSpec::integer("strategy_images", 0,
                              "keep one image per strategy (s, t) of path depth s + t - 1 up to this "
                              "(RenderResult.strategies)")
        .at_least(0)
        .at_most(16)
        .with_special(int64_t(0), "none");
}

// ---- ParamReader ------------------------------------------------------------

const ParamValue& ParamReader::get(const std::string& param, ParamType type) {
    const ParamSpec* s = info_.param(param);
    const ParamValue* v = values_.find(param);
    if (!s || s->name != param || s->type != type || !v)
        throw std::logic_error("estimator '" + info_.name + "' reads parameter '" + param + "' as " +
                               param_type_name(type) + ", which its declaration does not give");
    if (std::find(read_.begin(), read_.end(), param) == read_.end()) read_.push_back(param);
    return *v;
}

int ParamReader::get_int(const std::string& param) { return int(std::get<int64_t>(get(param, ParamType::Int))); }
float ParamReader::get_float(const std::string& param) { return float(std::get<double>(get(param, ParamType::Float))); }
bool ParamReader::get_bool(const std::string& param) { return std::get<bool>(get(param, ParamType::Bool)); }
std::string ParamReader::get_string(const std::string& param) {
    return std::get<std::string>(get(param, ParamType::String));
}

void ParamReader::fail(const std::string& param, const std::string& message) const {
    throw ParamError(name_, param, prefix(name_) + message);
}

void ParamReader::report_unused() const {
    for (const auto& [n, v] : values_)
        if (std::find(read_.begin(), read_.end(), n) == read_.end())
            throw ParamError(
                name_, n,
                prefix(name_) + "parameter '" + n + "' is not used (declared, but the estimator never reads it)");
}

// ---- The registry -----------------------------------------------------------

const ParamSpec* EstimatorInfo::param(const std::string& n) const {
    for (const ParamSpec& s : params) {
        if (s.name == n) return &s;
        if (std::find(s.aliases.begin(), s.aliases.end(), n) != s.aliases.end()) return &s;
    }
    return nullptr;
}

namespace {

struct Registry {
    std::vector<std::unique_ptr<EstimatorInfo>> entries;
    std::vector<std::string> errors;  // malformed declarations, reported on first use
};

// A function-local static: estimators register from static initialisers of
// other files, in no defined order.
Registry& registry() {
    static Registry r;
    return r;
}

// What is wrong with a declaration, or "".
std::string declaration_error(const EstimatorInfo& e, const Registry& r) {
    if (e.name.empty()) return "an estimator without a name";
    if (!e.factory) return "no factory";
    std::vector<std::string> names = e.aliases;
    names.push_back(e.name);
    for (const std::string& n : names)
        for (const auto& other : r.entries)
            if (other->name == n || std::find(other->aliases.begin(), other->aliases.end(), n) != other->aliases.end())
                return "name '" + n + "' taken by estimator '" + other->name + "'";
    std::vector<std::string> pnames;
    for (const ParamSpec& s : e.params) {
        pnames.push_back(s.name);
        pnames.insert(pnames.end(), s.aliases.begin(), s.aliases.end());
        if (s.has_default && (param_type(s.default_value) != s.type || !s.check(s.default_value).empty()))
            return "parameter '" + s.name + "': its default does not fit its declaration";
        for (const auto& sp : s.special)
            if (param_type(sp.first) != s.type) return "parameter '" + s.name + "': a special value of another type";
        for (const std::string& t : s.sets) {
            const ParamSpec* ts = e.param(t);
            if (!ts || ts->type != s.type || !ts->sets.empty() || ts->ignored)
                return "parameter '" + s.name + "' sets '" + t + "', which is not a parameter of the same type";
        }
    }
    std::vector<std::string> sorted = pnames;
    std::sort(sorted.begin(), sorted.end());
    auto dup = std::adjacent_find(sorted.begin(), sorted.end());
    if (dup != sorted.end()) return "parameter name '" + *dup + "' declared twice";
    return "";
}

const Registry& checked_registry() {
    const Registry& r = registry();
    if (!r.errors.empty()) throw std::logic_error("estimator registry: " + join(r.errors, "; ", "; "));
    return r;
}

std::vector<std::string> known_names() {
    std::vector<std::string> names;
    for (const auto& e : checked_registry().entries) {
        names.push_back(e->name);
        names.insert(names.end(), e->aliases.begin(), e->aliases.end());
    }
    std::sort(names.begin(), names.end());
    return names;
}

// The estimator `name` names, or ParamError (unknown, or planned).
const EstimatorInfo& lookup(const std::string& name) {
    if (const EstimatorInfo* e = find_estimator(name)) return *e;
    std::vector<std::string> planned = planned_estimators();
    if (std::find(planned.begin(), planned.end(), name) != planned.end())
        throw ParamError(name, "", prefix(name) + "estimator '" + name + "' is not implemented yet");
    throw ParamError(name, "",
                     "integrator: unknown estimator '" + name + "' (known: " + join(known_names(), ", ", ", ") + ")");
}

// `v` as a value of `type`: an integer is also a number; nothing else converts.
bool convert(const ParamValue& v, ParamType type, ParamValue& out) {
    if (param_type(v) == type) {
        out = v;
        return true;
    }
    if (type == ParamType::Float && param_type(v) == ParamType::Int) {
        out = double(std::get<int64_t>(v));
        return true;
    }
    return false;
}

}  // namespace

bool register_estimator(EstimatorInfo info) {
    Registry& r = registry();
    // Every estimator selects its emitters by light_sampler, read by build().
    if (!info.param("light_sampler")) info.params.push_back(light_sampler_param());
    std::string err = declaration_error(info, r);
    if (!err.empty()) {
        r.errors.push_back("estimator '" + info.name + "': " + err);
        return false;
    }
    r.entries.push_back(std::make_unique<EstimatorInfo>(std::move(info)));
    return true;
}

std::vector<const EstimatorInfo*> registered_estimators() {
    std::vector<const EstimatorInfo*> out;
    for (const auto& e : checked_registry().entries) out.push_back(e.get());
    std::sort(out.begin(), out.end(), [](const EstimatorInfo* a, const EstimatorInfo* b) { return a->name < b->name; });
    return out;
}

const EstimatorInfo* find_estimator(const std::string& name) {
    for (const auto& e : checked_registry().entries)
        if (e->name == name || std::find(e->aliases.begin(), e->aliases.end(), name) != e->aliases.end())
            return e.get();
    return nullptr;
}

std::vector<std::string> planned_estimators() {
    // Named by the scene format (DESIGN section 3), arriving with later work.
    static const char* const kPlanned[] = {"vcm", "pssmlt", "vpl", "irrcache", "radiosity"};
    std::vector<std::string> out;
    for (const char* n : kPlanned)
        if (!find_estimator(n)) out.push_back(n);
    return out;
}

ParamSet resolve_params(const EstimatorInfo& info, const std::string& name, const ParamSet& given) {
    const std::string pre = prefix(name);
    ParamSet checked;  // by declared name
    std::vector<const ParamSpec*> setters;
    for (const auto& [k, v] : given) {
        const ParamSpec* s = info.param(k);
        if (!s) {
            std::vector<std::string> known;
            for (const ParamSpec& p : info.params) known.push_back(p.name);
            std::sort(known.begin(), known.end());
            throw ParamError(
                name, k,
                pre + "unknown parameter '" + k + "' for '" + name + "' (known: " + join(known, ", ", ", ") + ")");
        }
        if (s->name != k && given.find(s->name))
            throw ParamError(name, k,
                             pre + "parameter '" + k + "' given together with its alias '" + s->name + "'; give one");
        ParamValue val;
        if (!convert(v, s->type, val))
            throw ParamError(
                name, k,
                pre + "parameter '" + k + "' expects " + param_type_phrase(s->type) + ", got " + format_param_value(v));
        std::string why = s->check(val);
        if (!why.empty())
            throw ParamError(name, k, pre + "parameter '" + k + "' " + why + ", got " + format_param_value(v));
        if (!s->sets.empty()) setters.push_back(s);
        checked.set(s->name, std::move(val));
    }
    ParamSet out;
    for (const ParamSpec& s : info.params) {
        if (s.ignored || !s.sets.empty()) continue;
        if (const ParamValue* v = checked.find(s.name))
            out.set(s.name, *v);
        else
            out.set(s.name, s.default_value);
    }
    for (const ParamSpec* s : setters) {
        const ParamValue& v = *checked.find(s->name);
        for (const std::string& t : s->sets) {
            if (checked.find(t))
                throw ParamError(name, s->name,
                                 pre + "parameter '" + s->name + "' sets " + join(s->sets, ", ", " and ") +
                                     "; give either it or them");
            std::string why = info.param(t)->check(v);
            if (!why.empty())
                throw ParamError(name, s->name,
                                 pre + "parameter '" + s->name + "' sets '" + t + "', which " + why + ", got " +
                                     format_param_value(v));
            out.set(t, v);
        }
    }
    return out;
}

namespace {

std::unique_ptr<Integrator> build(const IntegratorDesc& desc, ParamSet& resolved) {
    const EstimatorInfo& info = lookup(desc.type);
    resolved = resolve_params(info, desc.type, desc.params);
    ParamReader reader(info, desc.type, resolved);
    std::unique_ptr<Integrator> r = info.factory(reader);
    LightSamplerKind lights = parse_light_sampler(reader.get_string("light_sampler"));
    reader.report_unused();
    r->light_sampler = lights;
    r->type = desc.type;
    r->caps = info.caps;
    return r;
}

}  // namespace

ParamSet resolve_integrator(const IntegratorDesc& desc) {
    ParamSet resolved;
    build(desc, resolved);
    return resolved;
}

std::unique_ptr<Integrator> make_integrator(const IntegratorDesc& desc, const EffectMask& mask) {
    ParamSet resolved;
    std::unique_ptr<Integrator> r = build(desc, resolved);
    r->mask = mask;
    return r;
}

}  // namespace rm
