"""Runs unittest cases and reports them the way every test of the test command does (docs/building.md, "Skips"):
a line per skipped test, "SKIPPED <test id>: <reason>", then "N passed, N failed, N skipped", and an exit code for
ctest: 0 when every test passed or skipped and at least one passed, 1 when one failed or none ran, 77 (ctest's
SKIP_RETURN_CODE of these tests) when every test skipped, so that a file whose tests all skip is a skip, not a pass.

    import unittest_report
    sys.exit(unittest_report.run(suite))      # a suite the caller built
    unittest_report.main()                    # the calling module's tests (what unittest.main() would run)
"""
import sys
import unittest

SKIP_RETURN_CODE = 77


def report(result, stream=sys.stdout):
    """Prints the skips and the counts of a finished unittest result; returns the exit code for ctest."""
    for test, reason in result.skipped:
        print(f"SKIPPED {test.id()}: {reason}", file=stream)
    failed = len(result.failures) + len(result.errors) + len(result.unexpectedSuccesses)
    skipped = len(result.skipped)
    passed = result.testsRun - failed - skipped
    print(f"{passed} passed, {failed} failed, {skipped} skipped", file=stream)
    stream.flush()
    if failed or result.testsRun == 0:
        return 1
    return SKIP_RETURN_CODE if passed == 0 else 0


def run(suite, stream=sys.stdout):
    result = unittest.TextTestRunner(verbosity=2, stream=stream).run(suite)
    return report(result, stream)


def main(module="__main__"):
    """Runs the module's tests (command-line arguments are the module's own, not unittest's) and exits."""
    if isinstance(module, str):
        module = sys.modules[module]
    sys.exit(run(unittest.TestLoader().loadTestsFromModule(module)))
