# The colour adjustments stored on a Gaussian object (properties.py: exposure, brightness, saturation, hue,
# temperature) and where they apply. They are one affine map of the display colour, applied exactly to the SH by the
# core (native/include/raysplats/color_adjustment.h) wherever Gaussians are recovered (polygon_mesh.recover_from_arrays:
# the render, the viewport and every export), and to the corner colour attribute that Solid and Material Preview
# show (upkeep.refresh_corner_colors). The stored SH stay as imported, so adjusting is never lossy.
from .. import native

ADJUSTMENT_NAMES = ("exposure", "brightness", "saturation", "hue", "temperature")
IDENTITY = {"exposure": 0.0, "brightness": 0.0, "saturation": 1.0, "hue": 0.0, "temperature": 0.0}


def adjustment_of(settings):
    """The object's adjustments as the core's keyword arguments (settings: Object.raysplats; None: no adjustment)."""
    return {name: float(getattr(settings, name, IDENTITY[name])) for name in ADJUSTMENT_NAMES}


def adjustment_key(settings):
    """A hashable value that changes whenever the object's adjustments do (the viewport's sync key)."""
    return tuple(adjustment_of(settings).values())


def is_identity(settings):
    return adjustment_of(settings) == IDENTITY


def adjust_cloud_colors(cloud, settings):
    """Applies the object's adjustments to a recovered cloud's SH in place (nothing to do without any)."""
    if not is_identity(settings) and len(cloud["sh"]):
        native.core().apply_color_adjustment(cloud["sh"], **adjustment_of(settings))
    return cloud
