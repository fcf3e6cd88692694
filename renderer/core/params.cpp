#include "core/params.h"

#include <cmath>
#include <cstdio>
#include <cstdlib>

namespace rm {

const char* param_type_phrase(ParamType t) {
    switch (t) {
        case ParamType::Bool:
            return "a boolean";
        case ParamType::Int:
            return "an integer";
        case ParamType::Float:
            return "a number";
        case ParamType::String:
            return "a string";
    }
    return "?";
}

const char* param_type_name(ParamType t) {
    switch (t) {
        case ParamType::Bool:
            return "bool";
        case ParamType::Int:
            return "int";
        case ParamType::Float:
            return "float";
        case ParamType::String:
            return "string";
    }
    return "?";
}

namespace {

// The shortest decimal that reads back as `v` (as Python's repr), with a
// decimal point so that it reads as a float.
std::string format_double(double v) {
    if (std::isnan(v)) return "nan";
    if (std::isinf(v)) return v > 0 ? "inf" : "-inf";
    char buf[40];
    for (int prec = 1; prec <= 17; ++prec) {
        std::snprintf(buf, sizeof buf, "%.*g", prec, v);
        if (std::strtod(buf, nullptr) == v) break;
    }
    std::string s(buf);
    if (s.find_first_of(".e") == std::string::npos) s += ".0";
    return s;
}

}  // namespace

std::string format_param_value(const ParamValue& v) {
    switch (param_type(v)) {
        case ParamType::Bool:
            return std::get<bool>(v) ? "true" : "false";
        case ParamType::Int:
            return std::to_string(std::get<int64_t>(v));
        case ParamType::Float:
            return format_double(std::get<double>(v));
        case ParamType::String:
            return "'" + std::get<std::string>(v) + "'";
    }
    return "?";
}

}  // namespace rm
