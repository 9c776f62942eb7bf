# Imported at start by every Windows Python that scripts/windows/wine_python.sh runs under Wine (never shipped).
# Python 3.12 and newer ask Windows Management Instrumentation for platform.machine(), platform.uname() and the like
# through the _wmi module, whose query calls propsys.dll's VariantToString: Debian 12's Wine 8.0 does not implement it
# and aborts the process (numpy.testing calls platform.machine() on import). Without _wmi, platform answers from the
# registry and environment as Python 3.11 does, which Wine supports.
import sys

sys.modules["_wmi"] = None
