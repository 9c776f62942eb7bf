// What a glTF file holds besides splats, for an importer that hands the rest to a mesh importer (the add-on's glTF
// import: its splats through read_splat_file, its other meshes through Blender's glTF importer).
#pragma once

#include <cstddef>
#include <string>
#include <vector>

namespace raysplats {

// Its splat (KHR_gaussian_splatting) and other primitives, and the names of the meshes that hold only splat
// primitives. Throws FileFormatError naming the file for one that is not valid glTF.
struct GltfContents {
    std::size_t splat_primitives = 0, other_primitives = 0;
    std::vector<std::string> splat_only_meshes;
};
GltfContents gltf_contents(const std::string& path);

}  // namespace raysplats
