#!/usr/bin/env python3
"""Runs a GoogleTest binary as one ctest test and reports it as every test of the test command does
(scripts/lib/unittest_report.py): a line per skipped test, "SKIPPED <Suite.Test>: <reason>", then
"N passed, N failed, N skipped". GoogleTest exits 0 whether its tests passed or skipped, so the skips are read from
its XML report (--gtest_output=xml). Exit code: the binary's when it failed, 1 when it ran no test, 77 (ctest's
SKIP_RETURN_CODE) when every test skipped, else 0.
    run_gtest.py BINARY [gtest arguments...]
"""
import os
import re
import subprocess
import sys
import tempfile
import xml.etree.ElementTree as ET

SKIP_RETURN_CODE = 77


def skip_reason(message):
    """GoogleTest's skip message starts with "file:line" and a newline; the reason is what follows."""
    lines = [line for line in message.splitlines() if line.strip()]
    if lines and re.match(r"^\S+:\d+$", lines[0].strip()):
        lines = lines[1:]
    return " ".join(line.strip() for line in lines) or "(no reason given)"


def read_report(path):
    """(passed, failed, [(name, reason) skipped]) from a GoogleTest XML report."""
    passed, failed, skipped = [], [], []
    for case in ET.parse(path).getroot().iter("testcase"):
        name = f"{case.get('classname')}.{case.get('name')}"
        if case.get("status") == "notrun":
            continue  # DISABLED_ tests
        if case.find("failure") is not None:
            failed.append(name)
        elif case.get("result") == "skipped" or case.find("skipped") is not None:
            element = case.find("skipped")
            skipped.append((name, skip_reason(element.get("message", "") if element is not None else "")))
        else:
            passed.append(name)
    return passed, failed, skipped


def main(argv):
    if not argv:
        sys.exit(__doc__)
    with tempfile.TemporaryDirectory() as tmp:
        xml_path = os.path.join(tmp, "report.xml")
        code = subprocess.call(argv + [f"--gtest_output=xml:{xml_path}"])
        if not os.path.exists(xml_path):
            print(f"run_gtest: {argv[0]} wrote no report (exit code {code})")
            return code or 1
        passed, failed, skipped = read_report(xml_path)
    for name, reason in skipped:
        print(f"SKIPPED {name}: {reason}")
    print(f"{len(passed)} passed, {len(failed)} failed, {len(skipped)} skipped")
    if code != 0 or failed:
        return code or 1
    if not passed and not skipped:
        return 1
    return SKIP_RETURN_CODE if not passed else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
