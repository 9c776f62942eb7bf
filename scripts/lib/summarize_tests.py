#!/usr/bin/env python3
"""The one summary the test command ends with, read from ctest's JUnit report (ctest --output-junit):
    N passed, N failed, N skipped
then a line per skip with its reason, a line per failure, and the tiers scripts/test.sh could not set up.

Counting: a ctest test that passed, failed or skipped (SKIP_RETURN_CODE 77, or GoogleTest's "[  SKIPPED ]" for the
discovered tests) counts once; a test skipped inside a ctest test that passed (a "SKIPPED <name>: <reason>" line,
what scripts/lib/unittest_report.py and run_gtest.py print) counts as one more skip. A ctest test that did not run
because a fixture it needs failed counts as failed.

A skip is expected when its reason starts with "expected: " (this machine lacks the thing by design, e.g. a CPU
family or a Blender version without the feature). Under --strict any other skip, and any tier not set up, makes the
exit code 1.
    summarize_tests.py JUNIT_XML [--tiers FILE] [--strict]
"""
import argparse
import re
import sys
import xml.etree.ElementTree as ET

SKIP_LINE = re.compile(r"^SKIPPED (\S+): (.*)$", re.M)
# A GoogleTest skip in a discovered test's output: "file:line: Skipped", then the message.
GTEST_SKIP = re.compile(r"^\S+:\d+: Skipped\n(.+)$", re.M)
# ctest's reasons for a skip (anything else not run, e.g. a failed fixture, is a failure).
SKIP_MESSAGES = ("SKIP_RETURN_CODE", "SKIP_REGULAR_EXPRESSION_MATCHED")
EXPECTED = "expected: "


def ctest_skip_reasons(output):
    reasons = [reason for _, reason in SKIP_LINE.findall(output)] or GTEST_SKIP.findall(output)
    if not reasons:
        lines = [line.strip() for line in output.splitlines() if line.strip()]
        reasons = [lines[-1] if lines else "(it printed no reason)"]
    return list(dict.fromkeys(reason.strip() for reason in reasons))


def summarize(junit_path, tier_lines=()):
    """Returns (passed, failed names, skips as (name, reason, expected))."""
    passed, failed, skips = 0, [], []
    for case in ET.parse(junit_path).getroot().iter("testcase"):
        name = case.get("name")
        status = case.get("status")
        output_element = case.find("system-out")
        output = output_element.text or "" if output_element is not None else ""
        skipped = case.find("skipped")
        if status == "run":
            passed += 1
            for inner, reason in SKIP_LINE.findall(output):
                skips.append((f"{name} > {inner}", reason.strip(), reason.startswith(EXPECTED)))
        elif status == "fail":
            # A tier that strict mode failed says which (scripts/lib/tier_not_run.sh).
            strict = re.search(r"^FAILED \(strict mode\): (.*)$", output, re.M)
            failed.append(f"{name}: {strict.group(1)}" if strict else name)
        elif status == "disabled":
            # GoogleTest's DISABLED_ tests (gtest_discover_tests marks them) and the DISABLED property: on purpose.
            skips.append((name, "expected: disabled (a DISABLED_ GoogleTest or the DISABLED property)", True))
        elif skipped is not None and skipped.get("message", "").startswith(SKIP_MESSAGES):
            reasons = ctest_skip_reasons(output)
            skips.append((name, "; ".join(reasons), all(r.startswith(EXPECTED) for r in reasons)))
        else:
            message = skipped.get("message") if skipped is not None else status
            failed.append(f"{name} (not run: {message})")
    return passed, failed, skips


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("junit")
    parser.add_argument("--tiers", help="the tiers not set up: a NAME<TAB>WHY line each (scripts/lib/tiers.sh)")
    parser.add_argument("--strict", action="store_true", help="fail on a skip that is not expected")
    args = parser.parse_args(argv)
    tiers = []
    if args.tiers:
        try:
            with open(args.tiers) as f:
                tiers = [line.rstrip("\n").split("\t", 1) for line in dict.fromkeys(f) if line.strip()]
        except FileNotFoundError:
            pass
    passed, failed, skips = summarize(args.junit)
    print(f"{passed} passed, {len(failed)} failed, {len(skips)} skipped")
    for name, reason, _ in skips:
        print(f"  skipped: {name}: {reason}")
    for name in failed:
        print(f"  FAILED: {name}")
    for name, why in ((t + ["?"])[:2] for t in tiers):
        marker = "not run" if why.startswith(EXPECTED) else "NOT RUN, A WHOLE TIER"
        print(f"  {marker}: {name}: {why}")
    unexpected = [s for s in skips if not s[2]]
    unexpected_tiers = [t for t in tiers if not (t + [""])[1].startswith(EXPECTED)]
    if args.strict and (unexpected or unexpected_tiers):
        print(f"strict mode: {len(unexpected)} skip(s) and {len(unexpected_tiers)} tier(s) not expected on this "
              f"machine (only reasons starting with '{EXPECTED}' are allowed)")
        return 1
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
