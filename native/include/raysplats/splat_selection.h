// Selecting Gaussians for clean-up: by opacity or size range, by colour, floaters far from their
// neighbours, inside or outside a crop box; and turning a face selection into the vertex and edge selection Blender
// stores beside it. Every function takes whole arrays (one row per Gaussian, i.e. per face of a splat mesh) and
// returns a mask of one byte per row (1 = selected). Multi-threaded where the work is more than a pass over memory.
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

namespace raysplats {

using SelectionMask = std::vector<std::uint8_t>;

// values[i] in [min_value, max_value] (inclusive; NaN never). E.g. opacities.
SelectionMask select_by_value_range(const float* values, std::size_t count, float min_value, float max_value);

// The largest of scales[3i .. 3i+2] in [min_scale, max_scale] (inclusive): "size" in the units of the scales.
SelectionMask select_by_largest_scale(const float* scales, std::size_t count, float min_scale, float max_scale);

// The display colour of each Gaussian's SH DC term (0.5 + SH_C0 f_dc per channel, clamped to [0, 1]: the colour a
// splat viewer shows head-on without view dependence) within Euclidean RGB distance max_distance of
// target_display_rgb (display sRGB values in [0, 1]). sh_dc: 3 floats per Gaussian.
SelectionMask select_by_color_distance(const float* sh_dc, std::size_t count, const float target_display_rgb[3],
                                       float max_distance);

// Floaters by the statistical outlier test of point clouds (Rusu et al. 2008; Open3D's
// remove_statistical_outlier): d_i is the mean distance of centre i to its k nearest other centres; Gaussian i is a
// floater when d_i > mean(d) + std_ratio * std(d) (population std over all Gaussians). A k-d tree finds the
// neighbours. Fewer than k + 1 Gaussians: nothing is selected. Non-finite positions are never selected and are not
// anyone's neighbour. `mean_neighbor_distances` (optional, `count` floats) receives d (NaN for non-finite centres).
SelectionMask select_floaters(const float* positions, std::size_t count, int k, double std_ratio,
                              float* mean_neighbor_distances = nullptr);

// Centres p (3 floats each) with world_to_box * p (row-major 4x4, affine) inside [box_min, box_max] on all three
// axes (inclusive); `inside` false selects the complement (non-finite centres are outside).
SelectionMask select_in_box(const float* positions, std::size_t count, const double world_to_box[16],
                            const float box_min[3], const float box_max[3], bool inside);

// Blender's selection is stored per vertex, edge and face and must agree: the vertices and edges of the selected
// faces (corner_edges: the edge index of each corner, as Mesh.loops "edge_index"). Vertices and edges of unselected
// faces that are shared with a selected face are selected too, as Blender's own face selection does.
struct MeshElementSelection {
    SelectionMask vertices;
    SelectionMask edges;
};
MeshElementSelection select_face_elements(const std::uint8_t* face_mask, std::size_t face_count,
                                          const std::int32_t* face_corner_start, const std::int32_t* face_corner_count,
                                          const std::int32_t* corner_vertices, const std::int32_t* corner_edges,
                                          std::size_t corner_count, std::size_t vertex_count, std::size_t edge_count);

}  // namespace raysplats
