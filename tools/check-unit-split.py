#!/usr/bin/env python3
"""Checks that the per-module CTest entries of the unit tests (CMakeLists.txt, unit_<group>) run
every doctest test case exactly once. Usage:
  tools/check-unit-split.py <lensopt_tests> <group>=<source-file filter> ...
It lists the binary's test cases (--list-test-cases), then those of each group's filter, and fails
naming each test case that no group runs or that more than one group runs.
"""
import collections
import subprocess
import sys


def test_cases(binary, *arguments):
    out = subprocess.run([binary, "--list-test-cases", "--no-intro", "--force-colors=false",
                          *arguments], check=True, capture_output=True, text=True).stdout
    names = []
    for line in out.splitlines():
        # Doctest frames the list with "[doctest] ..." lines and a row of '='.
        if not line.strip() or line.startswith("[doctest]") or set(line.strip()) == {"="}:
            continue
        names.append(line.strip())
    return names


def main():
    if len(sys.argv) < 3:
        print(__doc__, file=sys.stderr)
        return 2
    binary = sys.argv[1]
    everything = collections.Counter(test_cases(binary))
    runs = collections.Counter()
    groups_of = collections.defaultdict(list)
    for group in sys.argv[2:]:
        name, _, pattern = group.partition("=")
        for case in test_cases(binary, f"--source-file={pattern}"):
            runs[case] += 1
            groups_of[case].append(name)
    errors = []
    for case, count in sorted(everything.items()):
        if runs[case] < count:
            errors.append(f"test case '{case}' is in no unit_<group> entry: add its file's "
                          "pattern to LENSOPT_UNIT_GROUPS in CMakeLists.txt")
        elif runs[case] > count:
            errors.append(f"test case '{case}' runs in more than one entry: "
                          f"unit_{', unit_'.join(groups_of[case])}")
    for error in errors:
        print(f"check-unit-split: {error}", file=sys.stderr)
    if errors:
        return 1
    print(f"check-unit-split: {sum(everything.values())} test cases, each in one of "
          f"{len(sys.argv) - 2} entries")
    return 0


if __name__ == "__main__":
    sys.exit(main())
