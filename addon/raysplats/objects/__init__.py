# What a splat object is: the one interface every caller asks (splat_object), the polygon mesh schema and recovery
# (polygon_mesh), compact points (compact_points) in Blender's own splat layout (blender_splats), making and removing
# splat objects (creation), their settings (object_settings), EEVEE material (falloff_material), up-axis conventions
# (axes), colour adjustments (color_adjustment) and the modifiers they do not survive (modifier_checks). No operators.
