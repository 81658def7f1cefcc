#!/usr/bin/python3
"""Counts test cases in catkin's JUnit result files and prints `N passed, N failed`.

catkin_test_results counts a rostest twice (the launch wrapper and the test node's own report);
here each test case is counted once: gtest-*.xml and rosunit-*.xml hold the cases, and a
rostest-*.xml counts only when it reports a failure of its own (a node that crashed or timed out
before writing a report). A result file that cannot be parsed counts as one failure.
Usage: summarize_test_results.py RESULTS_DIR [--list-failures]
"""
import glob
import os
import sys
import xml.etree.ElementTree as ET


def cases(path):
    root = ET.parse(path).getroot()
    for case in root.iter("testcase"):
        failed = case.find("failure") is not None or case.find("error") is not None
        skipped = case.find("skipped") is not None or case.get("status") == "notrun"
        yield case.get("classname", ""), case.get("name", ""), failed, skipped


def main():
    if len(sys.argv) < 2:
        sys.exit(__doc__)
    results = sys.argv[1]
    passed, failed, failures = 0, 0, []
    for path in sorted(glob.glob(os.path.join(results, "**", "*.xml"), recursive=True)):
        name = os.path.basename(path)
        try:
            found = list(cases(path))
        except ET.ParseError as err:
            failed += 1
            failures.append(f"{name}: unreadable result file ({err})")
            continue
        wrapper = name.startswith("rostest-")
        for classname, case, bad, skipped in found:
            if skipped:
                continue
            if bad:
                failed += 1
                failures.append(f"{name}: {classname}.{case}")
            elif not wrapper:
                passed += 1
    if "--list-failures" in sys.argv:
        for line in failures:
            print("FAILED:", line)
    print(f"{passed} passed, {failed} failed")


if __name__ == "__main__":
    main()
