#!/usr/bin/env python3
"""The test command's reporting, tested on small inputs (ctest scripts.reporting): unittest_report's counts and its
77 when every test skipped, run_gtest's skips read from a GoogleTest XML report, tier_not_run.sh and tiers.sh under
strict mode and not, and summarize_tests.py over the JUnit report of a real ctest run of a small project that uses
cmake/RaySplatsTiers.cmake, so that a skip reaches the summary as a skip with its reason.
    test_reporting.py
"""
import os
import subprocess
import sys
import tempfile
import textwrap
import unittest

LIB = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
ROOT = os.path.dirname(os.path.dirname(LIB))
sys.path.insert(0, LIB)
import summarize_tests  # noqa: E402
import unittest_report  # noqa: E402

UNSTRICT = {"CI": "", "RAYSPLATS_STRICT": "0"}
STRICT = {"CI": "true", "RAYSPLATS_STRICT": ""}


def run(args, env=None, **kwargs):
    full_env = dict(os.environ, **(env or UNSTRICT))
    return subprocess.run(args, env=full_env, capture_output=True, text=True, **kwargs)


def python_tests(tmp, name, body):
    """A test file that reports through unittest_report, as the project's Python test files do."""
    path = os.path.join(tmp, name)
    with open(path, "w") as f:
        f.write(f"import sys, unittest\nsys.path.insert(0, {LIB!r})\nimport unittest_report\n"
                + textwrap.dedent(body) + "\nunittest_report.main()\n")
    return path


class UnittestReport(unittest.TestCase):
    def run_file(self, body):
        with tempfile.TemporaryDirectory() as tmp:
            return run([sys.executable, python_tests(tmp, "test_x.py", body)])

    def test_all_skipped_is_77_with_each_reason(self):
        r = self.run_file("""
            class T(unittest.TestCase):
                def test_a(self): self.skipTest("expected: no such thing here")
                @unittest.skip("tool missing")
                def test_b(self): pass
            """)
        self.assertEqual(r.returncode, 77, r.stdout + r.stderr)
        self.assertIn("SKIPPED __main__.T.test_a: expected: no such thing here", r.stdout)
        self.assertIn("SKIPPED __main__.T.test_b: tool missing", r.stdout)
        self.assertIn("0 passed, 0 failed, 2 skipped", r.stdout)

    def test_a_skip_beside_a_pass_is_counted_not_passed(self):
        r = self.run_file("""
            class T(unittest.TestCase):
                def test_a(self): pass
                def test_b(self): self.skipTest("why")
            """)
        self.assertEqual(r.returncode, 0, r.stdout + r.stderr)
        self.assertIn("1 passed, 0 failed, 1 skipped", r.stdout)

    def test_a_failure_or_no_test_fails(self):
        r = self.run_file("""
            class T(unittest.TestCase):
                def test_a(self): self.fail("no")
                def test_b(self): self.skipTest("why")
            """)
        self.assertEqual(r.returncode, 1)
        self.assertIn("0 passed, 1 failed, 1 skipped", r.stdout)
        self.assertEqual(self.run_file("pass").returncode, 1)


class RunGtest(unittest.TestCase):
    """run_gtest.py over a stand-in binary that writes the XML report GoogleTest would."""
    REPORT = """<?xml version="1.0" encoding="UTF-8"?>
<testsuites><testsuite name="S">
{cases}
</testsuite></testsuites>"""
    PASS = '<testcase name="Passes" status="run" result="completed" classname="S"/>'
    SKIP = ('<testcase name="Skips" status="run" result="skipped" classname="S">'
            '<skipped message="f.cpp:3&#x0A;expected: not this CPU family"/></testcase>')
    FAIL = '<testcase name="Fails" status="run" result="completed" classname="S"><failure message="x"/></testcase>'

    def run_fake(self, cases, code=0):
        with tempfile.TemporaryDirectory() as tmp:
            fake = os.path.join(tmp, "fake_gtest.py")
            with open(fake, "w") as f:
                f.write("import sys\npath = sys.argv[-1].split('xml:', 1)[1]\n"
                        f"open(path, 'w').write({self.REPORT.format(cases=cases)!r})\nsys.exit({code})\n")
            return run([os.path.join(LIB, "run_gtest.py"), sys.executable, fake])

    def test_skips_are_named_and_counted(self):
        r = self.run_fake(self.PASS + self.SKIP)
        self.assertEqual(r.returncode, 0, r.stdout + r.stderr)
        self.assertIn("SKIPPED S.Skips: expected: not this CPU family", r.stdout)
        self.assertIn("1 passed, 0 failed, 1 skipped", r.stdout)

    def test_all_skipped_is_77_and_a_failure_fails(self):
        self.assertEqual(self.run_fake(self.SKIP).returncode, 77)
        self.assertEqual(self.run_fake(self.PASS + self.FAIL, code=1).returncode, 1)
        self.assertEqual(self.run_fake("").returncode, 1)


class Tiers(unittest.TestCase):
    def test_tier_not_run_fails_under_strict_mode_and_skips_otherwise(self):
        script = os.path.join(LIB, "tier_not_run.sh")
        strict = run([script, "x.tier", "no such tool"], env=STRICT)
        self.assertEqual(strict.returncode, 1)
        self.assertIn("x.tier", strict.stdout)
        self.assertEqual(run([script, "x.tier", "no such tool"]).returncode, 77)
        self.assertEqual(run([script, "x.tier", "no such tool"], env={"CI": "", "RAYSPLATS_STRICT": "1"}).returncode, 1)
        self.assertEqual(run([script, "x.tier", "expected: not this CPU"], env=STRICT).returncode, 77)

    def test_tier_unavailable_fails_under_strict_mode_and_records_otherwise(self):
        with tempfile.TemporaryDirectory() as tmp:
            tiers = os.path.join(tmp, "tiers.txt")
            command = f"source {LIB}/tiers.sh; tier_unavailable 'Blender 9.9' 'not on PyPI' || exit 1; echo went on"
            strict = run(["bash", "-c", command], env=dict(STRICT, RAYSPLATS_TIERS_FILE=tiers))
            self.assertEqual(strict.returncode, 1)
            self.assertIn("Blender 9.9", strict.stderr)
            loose = run(["bash", "-c", command], env=dict(UNSTRICT, RAYSPLATS_TIERS_FILE=tiers))
            self.assertEqual(loose.returncode, 0)
            self.assertIn("went on", loose.stdout)
            with open(tiers) as f:
                self.assertEqual(f.read(), "Blender 9.9\tnot on PyPI\n")


class SummaryOfARealCtestRun(unittest.TestCase):
    """A small CMake project with a passing test that skips one test inside, a file whose tests all skip, an expected
    and an unexpected missing tier, and a failure; its ctest JUnit report summarised."""

    @classmethod
    def setUpClass(cls):
        cls.tmp = tempfile.TemporaryDirectory()
        tmp = cls.tmp.name
        python_tests(tmp, "test_mixed.py", """
            class T(unittest.TestCase):
                def test_a(self): pass
                def test_b(self): self.skipTest("expected: inner reason")
            """)
        python_tests(tmp, "test_all_skip.py", """
            class T(unittest.TestCase):
                def test_a(self): self.skipTest("no validator")
            """)
        python_tests(tmp, "test_fails.py", """
            class T(unittest.TestCase):
                def test_a(self): self.fail("broken")
            """)
        with open(os.path.join(tmp, "CMakeLists.txt"), "w") as f:
            f.write(textwrap.dedent(f"""\
                cmake_minimum_required(VERSION 3.18)
                project(reporting NONE)
                enable_testing()
                set(PROJECT_SOURCE_DIR {ROOT})
                include({ROOT}/cmake/RaySplatsTiers.cmake)
                foreach(name mixed all_skip fails)
                  add_test(NAME t.${{name}} COMMAND {sys.executable} {tmp}/test_${{name}}.py)
                  raysplats_skips_with_77(t.${{name}})
                endforeach()
                raysplats_tier_not_run(t.no_avx512 "expected: this CPU has no avx512")
                raysplats_tier_not_run(t.no_node "node not found")
                """))
        build = os.path.join(tmp, "build")
        configure = run(["cmake", "-S", tmp, "-B", build])
        assert configure.returncode == 0, configure.stdout + configure.stderr
        cls.junit = os.path.join(build, "results.xml")
        cls.ctest = {}
        for name, env in (("loose", UNSTRICT), ("strict", STRICT)):
            cls.ctest[name] = run(["ctest", "--output-junit", cls.junit + name], env=env, cwd=build)

    @classmethod
    def tearDownClass(cls):
        cls.tmp.cleanup()

    def summary(self, mode, *extra):
        return run([os.path.join(LIB, "summarize_tests.py"), self.junit + mode, *extra])

    def test_counts_and_reasons(self):
        r = self.summary("loose")
        lines = r.stdout.splitlines()
        self.assertEqual(lines[0], "1 passed, 1 failed, 4 skipped", r.stdout)
        self.assertIn("  skipped: t.mixed > __main__.T.test_b: expected: inner reason", lines)
        self.assertIn("  skipped: t.all_skip: no validator", lines)
        self.assertIn("  skipped: t.no_avx512: expected: this CPU has no avx512", lines)
        self.assertIn("  skipped: t.no_node: node not found", lines)
        self.assertIn("  FAILED: t.fails", lines)
        self.assertEqual(r.returncode, 1)

    def test_strict_mode_fails_the_missing_tier_and_the_unexpected_skip(self):
        r = self.summary("strict", "--strict")
        self.assertTrue(r.stdout.startswith("1 passed, 2 failed, 3 skipped"), r.stdout)
        self.assertIn("  FAILED: t.no_node: tier 't.no_node' was not set up: node not found", r.stdout.splitlines())
        self.assertIn("strict mode: 1 skip(s)", r.stdout)
        self.assertEqual(r.returncode, 1)

    def test_only_expected_skips_pass_strict_mode(self):
        passed, failed, skips = summarize_tests.summarize(self.junit + "strict")
        self.assertEqual([s[0] for s in skips if s[2]], ["t.mixed > __main__.T.test_b", "t.no_avx512"])


if __name__ == "__main__":
    unittest_report.main()
