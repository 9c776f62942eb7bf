# Where splat objects' settings and tools are shown (panels) and the viewport niceties after an import (solid_view).
