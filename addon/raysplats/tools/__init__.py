# Operators that change splat objects: selection (select_splats), upkeep (upkeep: SH degree, adjusted colours, joined
# objects), the exact Apply Transform (exact_apply), regions of compact points edited as polygons (region_editing),
# Object > Convert (convert_splats) and the handlers that keep them current (handlers).
