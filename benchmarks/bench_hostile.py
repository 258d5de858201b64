"""Benchmark: what each generated hostile case costs a ``baker`` process — exit code, clock
seconds, peak resident MiB, and seconds from a signal to the end — and the worst of each family.

The cases are ``tests/hostile_cases.py``'s (the long set by default), run as
``tests/test_hostile_generated.py`` runs them (forked from a server that imported baker once:
``tests/hostile_runner.py``), without its checks: it prints the figures the docs quote
(docs/robustness.md, "One budget for the whole input").

    python benchmarks/bench_hostile.py [--fast] [--family budgets] [--match WebP]
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import threading
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from tests.hostile_cases import FAMILIES, cases, prepare  # noqa: E402
from tests.hostile_runner import Runner  # noqa: E402

LIMIT_SECONDS = 120.0


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--fast", action="store_true", help="the fast set only")
    parser.add_argument("--family", choices=FAMILIES, help="one family only")
    parser.add_argument("--match", default="", help="cases whose name holds this")
    args = parser.parse_args()
    chosen = [case for case in cases(long=not args.fast)
              if (args.family in (None, case.family)) and args.match in case.name]
    runner = Runner()
    worst: dict[str, tuple[float, float]] = {}
    print(f"{'case':70} {'exit':>4} {'seconds':>8} {'MiB':>6} {'signal→end':>10}")
    try:
        for case in chosen:
            with tempfile.TemporaryDirectory() as folder:
                root = Path(folder)
                _, plan = prepare(case, root, lambda argv: runner.run(argv, root, LIMIT_SECONDS))
                if plan.reader is not None:  # what reads a FIFO the case streams into
                    threading.Thread(target=plan.reader.read_bytes, daemon=True).start()
                result = runner.run(plan.argv, root, LIMIT_SECONDS, plan.signal, plan.after)
            mib = result["kib"] / 1024
            after = result["after_signal"]
            print(f"{case.id[:70]:70} {result['code']:>4} {result['seconds']:>8.2f} {mib:>6.0f} "
                  f"{'' if after is None else f'{after:.2f}':>10}", flush=True)
            seconds, most = worst.get(case.family, (0.0, 0.0))
            worst[case.family] = (max(seconds, result["seconds"]), max(most, mib))
    finally:
        runner.close()
    for family, (seconds, mib) in worst.items():
        print(f"worst of {family}: {seconds:.2f} s, {mib:.0f} MiB")


if __name__ == "__main__":
    main()
