"""Sum an ``RF_CPU_LOG``: CPU seconds by kind of process (``robofabric sim``, ``compute``, ...) and by test file.

python tools/cpu_by_test/report.py /tmp/cpu.log
"""

import collections
import sys


def kind(argv: str) -> str:
    if argv == "INPROC":
        return "pytest, in the test's own process"
    parts = argv.split()
    if not parts:
        return "?"
    if (parts[0].endswith("robofabric/cli.py") or parts[0].endswith("/robofabric")) and len(parts) > 1:
        return "robofabric " + parts[1]
    return parts[0].rsplit("/", 2)[-1] if "/" in parts[0] else parts[0]


def main(path: str) -> None:
    rows = [line.rstrip("\n").split("\t") for line in open(path) if line.count("\t") == 3]
    by_kind: collections.Counter = collections.Counter()
    count: collections.Counter = collections.Counter()
    by_file: collections.Counter = collections.Counter()
    for cpu, _wall, test, argv in rows:
        by_kind[kind(argv)] += float(cpu)
        count[kind(argv)] += 1
        by_file[test.split("::")[0]] += float(cpu)
    print(f"{sum(by_kind.values()):.0f} CPU s in {len(rows)} lines")
    print("by kind of process:")
    for k, c in by_kind.most_common(20):
        print(f"  {c:8.1f} s  {count[k]:5d}x  {c / count[k]:6.2f} s each  {k}")
    print("by test file ('-': started outside a test, e.g. by a module's fixture before its first test):")
    for k, c in by_file.most_common(25):
        print(f"  {c:8.1f} s  {k}")


if __name__ == "__main__":
    main(sys.argv[1])
