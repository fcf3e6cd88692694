// A set of named parameter values as a scene gives them (the loader's XML
// or dict, a Python dict): ints, floats, bools and strings, in the order
// given. It carries no meaning; an estimator's declaration
// (render/registry.h) checks the values against their types and ranges.
#pragma once
#include <cstdint>
#include <string>
#include <utility>
#include <variant>
#include <vector>

namespace rm {

enum class ParamType { Bool, Int, Float, String };

// The alternatives are in ParamType's order.
using ParamValue = std::variant<bool, int64_t, double, std::string>;

inline ParamType param_type(const ParamValue& v) { return ParamType(v.index()); }

// "an integer", "a float", ...: for messages.
const char* param_type_phrase(ParamType t);
// "int", "float", "bool", "string": for tables.
const char* param_type_name(ParamType t);
// A value as a scene would write it: 3, 0.05, true, 'power'.
std::string format_param_value(const ParamValue& v);

class ParamSet {
public:
    // Sets `name`, replacing its value if it is already there (keeping its place).
    void set(const std::string& name, ParamValue value) {
        for (auto& [n, v] : items_)
            if (n == name) {
                v = std::move(value);
                return;
            }
        items_.emplace_back(name, std::move(value));
    }
    const ParamValue* find(const std::string& name) const {
        for (const auto& [n, v] : items_)
            if (n == name) return &v;
        return nullptr;
    }
    bool empty() const { return items_.empty(); }
    size_t size() const { return items_.size(); }
    auto begin() const { return items_.begin(); }
    auto end() const { return items_.end(); }

private:
    std::vector<std::pair<std::string, ParamValue>> items_;
};

}  // namespace rm
