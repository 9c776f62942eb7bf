// Named parameters: the one vocabulary by which every front end (the Python bindings' dicts, the JSON tool)
// sets the fields of a core struct such as RenderSettings or Camera. A table lists each parameter's name, the
// type of value it takes and what it sets; a front end turns its own value (a Python object, a JSON value) into a
// ParameterValue of the value's own kind and hands it to the table, which checks it against the parameter. So a
// misspelt name or a value of the wrong type is an error with one wording wherever it comes from:
//   unknown render setting 'sample' (known: width, height, samples, ...)
//   render setting 'samples' must be an integer (got 'many')
// Ranges are not checked here but by the struct's validate(), which names the setting too.
#pragma once

#include <cstdint>
#include <limits>
#include <string>
#include <type_traits>
#include <variant>
#include <vector>

#include "raysplats/errors.h"
#include "raysplats/render/transform.h"

namespace raysplats {

enum class ParameterType { Bool, Integer, Real, Name, Matrix };

// Throws InvalidArgument "unknown <what> 'x' (known: A, B, C)".
[[noreturn]] void throw_unknown_name(const char* what, const std::string& name, const std::vector<std::string>& known);

// A value as a front end hands it over; the alternatives are in the order of ParameterType: Bool -> bool,
// Integer -> std::int64_t, Real -> double, Name -> std::string, Matrix -> Matrix4 (row-major 4x4, as Blender's
// matrix_world).
using ParameterValue = std::variant<bool, std::int64_t, double, std::string, Matrix4>;

// "an integer", "a 4x4 matrix", ...: the wording of type errors.
const char* parameter_type_description(ParameterType type);

// `value` as the alternative `type` holds (an integer becomes a real number); throws InvalidArgument
// "<what> must be <type description> (got <the value>)" for any other mismatch.
ParameterValue value_of_type(const ParameterValue& value, ParameterType type, const std::string& what);

// One value of an enum by its name, e.g. {"STOCHASTIC", Compositing::Stochastic, "..."}.
template <typename Enum>
struct NamedValue {
    const char* name;
    Enum value;
    const char* description;
};

// Every named value of an enum, and what one is called in errors ("camera model", "compositing").
template <typename Enum>
struct NameTable {
    const char* what;
    std::vector<NamedValue<Enum>> values;

    std::vector<std::string> names() const {
        std::vector<std::string> out;
        for (const auto& v : values) out.emplace_back(v.name);
        return out;
    }
    // Throws InvalidArgument "unknown <what> 'x' (known: A, B, C)".
    Enum value_of(const std::string& name) const {
        for (const auto& v : values)
            if (name == v.name) return v.value;
        throw_unknown_name(what, name, names());
    }
};

template <typename Target>
struct Parameter {
    const char* name;
    ParameterType type;
    const char* description;  // what it sets, with its unit
    // Stores the value (of `type`) in the target; throws InvalidArgument for a value the field cannot hold
    // (an unknown name, an integer out of the field's range).
    void (*set)(Target& target, const ParameterValue& value, const std::string& what);
    std::vector<std::string> choices;  // the accepted names of a Name parameter (NameTable::names()), else empty
};

template <typename Target>
class ParameterTable {
public:
    ParameterTable(const char* what, std::vector<Parameter<Target>> parameters)
        : what_(what), parameters_(std::move(parameters)) {}

    // "render setting", "camera parameter": how errors name an entry.
    const char* what() const { return what_; }
    const std::vector<Parameter<Target>>& parameters() const { return parameters_; }

    // The parameter called `name`; throws InvalidArgument "unknown <what> 'name' (known: ...)".
    const Parameter<Target>& find(const std::string& name) const {
        for (const auto& p : parameters_)
            if (name == p.name) return p;
        throw_unknown_name(what_, name, names());
    }
    std::vector<std::string> names() const {
        std::vector<std::string> out;
        for (const auto& p : parameters_) out.emplace_back(p.name);
        return out;
    }

    // Sets parameter `name` of `target`. The value may be of another type than the parameter's only where no
    // information is lost (an integer for a real number); otherwise it is an error naming the parameter.
    void set(Target& target, const std::string& name, const ParameterValue& value) const {
        const Parameter<Target>& p = find(name);
        const std::string what = std::string(what_) + " '" + p.name + "'";
        p.set(target, value_of_type(value, p.type, what), what);
    }

private:
    const char* what_;
    std::vector<Parameter<Target>> parameters_;
};


namespace parameter_setters {

// Setters for a member of the target, chosen by the member's type: Parameter{..., &member<&T::field>}.
std::int64_t integer_in_range(const ParameterValue& value, std::int64_t lowest, std::int64_t highest,
                              const std::string& what);

template <auto Field>
struct FieldOf;
template <typename Target, typename Value, Value Target::*Field>
struct FieldOf<Field> {
    using TargetType = Target;
    using ValueType = Value;
};

template <auto Field>
void member(typename FieldOf<Field>::TargetType& target, const ParameterValue& value, const std::string& what) {
    using V = typename FieldOf<Field>::ValueType;
    if constexpr (std::is_same_v<V, bool>) {
        target.*Field = std::get<bool>(value);
    } else if constexpr (std::is_same_v<V, float>) {
        target.*Field = float(std::get<double>(value));
    } else if constexpr (std::is_same_v<V, Matrix4>) {
        target.*Field = std::get<Matrix4>(value);
    } else {
        static_assert(std::is_integral_v<V>, "no setter for this member type");
        target.*Field = V(integer_in_range(value, std::numeric_limits<V>::min(), std::numeric_limits<V>::max(), what));
    }
}

// A member of enum type, set by the names the table `Names()` lists.
template <auto Field, auto Names>
void named(typename FieldOf<Field>::TargetType& target, const ParameterValue& value, const std::string& what) {
    target.*Field = Names().value_of(std::get<std::string>(value));
}

}  // namespace parameter_setters

}  // namespace raysplats
