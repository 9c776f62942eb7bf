# Two kinds of failure, kept apart (pbrt's discipline, STYLE.md). A user's mistake (a bad or missing file, settings
# that cannot work, the native module not built) is reported with its own message, which names the file, setting or
# object. Anything else is a bug in RaySplats: the user is told so in one short line and the full traceback goes to
# the console (stderr), where a bug report can copy it from. Nothing is re-raised into Blender: an operator cancels,
# the render engine stops with an error; Blender keeps running (docs/design.md §2).
import functools
import traceback

from . import native

INTERNAL_ERROR_PREFIX = "RaySplats internal error — please report"


class InternalError(Exception):
    """An add-on invariant broke: a bug in RaySplats, never the user's doing. Raise it where code checks its own
    assumptions; it is reported like any other unexpected exception."""


def user_error_types():
    """The exception types that are the user's mistakes: ValueError (bad settings; the native InvalidArgument is one),
    OSError (files), the native core's Error (FileFormatError and the core's other deliberate errors) and
    NativeModuleMissing."""
    types = (native.NativeModuleMissing, ValueError, OSError)
    if native.is_available():
        types += (native.core().Error,)
    return types


def is_user_error(error):
    return isinstance(error, user_error_types()) and not isinstance(error, InternalError)


def _short(error, limit=200):
    """One line for the status bar: the exception's type and the first line of its message, cut at `limit`."""
    lines = str(error).strip().splitlines()
    text = f"{type(error).__name__}: {lines[0]}" if lines else type(error).__name__
    return text if len(text) <= limit else text[:limit - 1] + "…"


def report_exception(report, error, user_prefix=""):
    """Reports `error` as an ERROR through `report` (Operator.report or RenderEngine.report): a user error as
    user_prefix + its message; anything else as an internal error, with the traceback printed to stderr. Returns the
    message reported."""
    if is_user_error(error):
        message = f"{user_prefix}{error}"
    else:
        traceback.print_exception(type(error), error, error.__traceback__)
        message = f"{INTERNAL_ERROR_PREFIX}: {_short(error)}"
    report({"ERROR"}, message)
    return message


def reports_failures(user_prefix):
    """Decorates an Operator's execute(self, context): any exception it raises is reported (report_exception, user
    errors as user_prefix + message) and the operator returns {'CANCELLED'}."""
    def decorate(execute):
        @functools.wraps(execute)
        def execute_reporting_failures(self, context):
            try:
                return execute(self, context)
            except Exception as error:
                report_exception(self.report, error, user_prefix)
                return {"CANCELLED"}
        return execute_reporting_failures
    return decorate
