# Blender access with no splat knowledge: every way Blender versions differ (compat), fast bulk reads of any mesh
# (mesh_read), the size of a mesh's layers (mesh_memory), the one reader of Blender materials (material_reader) and
# how 3D views show an object (viewport_shading).
