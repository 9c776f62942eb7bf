# Runs one test module inside Blender:
#   blender -b -noaudio --factory-startup --python-exit-code 1 --python run_blender_test.py -- \
#       test_x.py --addon-dir addon --data-dir ../shared/data --tmp-dir /tmp/x
# Registers the add-on from the source tree and runs the module's unittest cases, reported by
# scripts/lib/unittest_report.py: each skip with its reason and the counts. Blender's exit code is 1 when a test
# failed (or none ran) and 77, a skip for ctest, when every test skipped.
import argparse
import importlib.util
import os
import sys
import unittest

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "scripts", "lib"))
import unittest_report  # noqa: E402


def main():
    argv = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else []
    parser = argparse.ArgumentParser()
    parser.add_argument("script")
    parser.add_argument("--addon-dir", required=True)
    parser.add_argument("--data-dir", required=True)
    parser.add_argument("--tmp-dir", required=True)
    parser.add_argument("-k", dest="pattern", default=None, help="run only tests whose name contains this")
    parser.add_argument("--known-failure", action="append", default=[], metavar="TEST_METHOD",
                        help="a test known to fail on this Blender: run as unittest.expectedFailure, so the run "
                             "still fails if it starts passing (then remove it from blender_tests/CMakeLists.txt)")
    args = parser.parse_args(argv)

    os.makedirs(args.tmp_dir, exist_ok=True)
    os.environ["RAYSPLATS_DATA_DIR"] = os.path.abspath(args.data_dir)
    os.environ["RAYSPLATS_TMP_DIR"] = os.path.abspath(args.tmp_dir)
    sys.path.insert(0, os.path.abspath(args.addon_dir))
    sys.path.insert(0, os.path.dirname(os.path.abspath(args.script)))
    import raysplats
    raysplats.register()

    spec = importlib.util.spec_from_file_location("blender_test_module", args.script)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    loader = unittest.TestLoader()
    if args.pattern:
        loader.testNamePatterns = [f"*{args.pattern}*"]
    suite = loader.loadTestsFromModule(module)
    for name in args.known_failure:
        cases = [case for case in vars(module).values() if isinstance(case, type) and hasattr(case, name)]
        if not cases:
            raise SystemExit(f"--known-failure {name}: no such test in {args.script}")
        for case in cases:
            setattr(case, name, unittest.expectedFailure(getattr(case, name)))
    try:
        code = unittest_report.run(suite)
    finally:
        # Blender-as-a-module (PyPI bpy) crashes at interpreter exit while add-on classes are still
        # registered, as Blender itself would unregister them on quit; do it here.
        raysplats.unregister()
    if code:
        raise SystemExit(code)


main()
