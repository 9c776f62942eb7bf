// A 4x4 affine transform as Blender and numpy hold it: row-major, column vectors (p' = M p), translation in
// the last column. `np.array(obj.matrix_world, dtype=np.float32)` has exactly this layout.
#pragma once

#include <array>

namespace raysplats {

struct Matrix4 {
    // m[4 * row + col]
    std::array<float, 16> m{1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1};

    static Matrix4 identity() { return Matrix4{}; }
    static Matrix4 translation(float x, float y, float z);
    static Matrix4 scale(float x, float y, float z);
    // Rotation by `angle` radians about the unit axis (x, y, z), right-handed.
    static Matrix4 rotation(float angle, float x, float y, float z);
    // Camera or light frame at `eye` whose local -Z looks at `target` and whose +Y is as close to `up` as
    // possible (Blender's convention for cameras and lights).
    static Matrix4 look_at(const std::array<float, 3>& eye, const std::array<float, 3>& target,
                           const std::array<float, 3>& up);

    float operator()(int row, int col) const { return m[4 * row + col]; }
    float& operator()(int row, int col) { return m[4 * row + col]; }

    Matrix4 operator*(const Matrix4& b) const;
    std::array<float, 3> transform_point(const std::array<float, 3>& p) const;
    std::array<float, 3> transform_direction(const std::array<float, 3>& d) const;

    bool is_finite() const;
    bool is_identity() const;
    // Throws InvalidArgument naming `what` if the matrix has NaN/Inf, is not affine (last row 0 0 0 1) or its
    // linear part is singular.
    void check_affine(const char* what) const;
};

}  // namespace raysplats
