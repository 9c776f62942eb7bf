// Named parameters (raysplats/render/parameters.h): the error wording every front end shares.
#include "raysplats/render/parameters.h"

#include <sstream>

namespace raysplats {

void throw_unknown_name(const char* what, const std::string& name, const std::vector<std::string>& known) {
    std::string list;
    for (const std::string& k : known) list += (list.empty() ? "" : ", ") + k;
    throw InvalidArgument(std::string("unknown ") + what + " '" + name + "' (known: " + list + ")");
}

const char* parameter_type_description(ParameterType type) {
    switch (type) {
        case ParameterType::Bool: return "true or false";
        case ParameterType::Integer: return "an integer";
        case ParameterType::Real: return "a number";
        case ParameterType::Name: return "a name";
        case ParameterType::Matrix: return "a 4x4 matrix";
    }
    return "?";
}

namespace {

std::string value_text(const ParameterValue& value) {
    switch (ParameterType(value.index())) {
        case ParameterType::Bool: return std::get<bool>(value) ? "true" : "false";
        case ParameterType::Integer: return std::to_string(std::get<std::int64_t>(value));
        case ParameterType::Real: {
            std::ostringstream s;
            s << std::get<double>(value);
            return s.str();
        }
        case ParameterType::Name: return "'" + std::get<std::string>(value) + "'";
        case ParameterType::Matrix: return "a matrix";
    }
    return "?";
}

}  // namespace

ParameterValue value_of_type(const ParameterValue& value, ParameterType type, const std::string& what) {
    // The variant's alternatives are in the order of ParameterType.
    const auto given = ParameterType(value.index());
    if (given == type) return value;
    if (type == ParameterType::Real && given == ParameterType::Integer) return double(std::get<std::int64_t>(value));
    throw InvalidArgument(what + " must be " + parameter_type_description(type) + " (got " + value_text(value) + ")");
}

namespace parameter_setters {

std::int64_t integer_in_range(const ParameterValue& value, std::int64_t lowest, std::int64_t highest,
                              const std::string& what) {
    const std::int64_t v = std::get<std::int64_t>(value);
    if (v < lowest || v > highest)
        throw InvalidArgument(what + " must be in " + std::to_string(lowest) + " .. " + std::to_string(highest) +
                              " (got " + std::to_string(v) + ")");
    return v;
}

}  // namespace parameter_setters

}  // namespace raysplats
