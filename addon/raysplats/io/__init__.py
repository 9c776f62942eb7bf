# Files in and out: the format vocabulary from the core (format_table), the import policy (import_policy), File >
# Import (import_splats) with a glTF file's meshes (gltf_mesh_import), File > Export > Gaussian Splats
# (export_splats), File > Export > RaySplats Mesh (export_mesh) and the exporters' "Limit to" (export_scope).
