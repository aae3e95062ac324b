"""Run every benchmark: ``python -m benchmarks`` (or ``make bench``).

Each ``benchmarks/bench_*.py`` defines ``run() -> pandas.DataFrame``; the
tables are printed and written to ``results/benchmarks/<name>.csv``. Timings
are wall-clock medians on this machine; they are reported, never asserted.
"""

import importlib
import pkgutil
import sys
from pathlib import Path

import benchmarks


def main() -> int:
    out = Path("results/benchmarks")
    out.mkdir(parents=True, exist_ok=True)
    names = sorted(m.name for m in pkgutil.iter_modules(benchmarks.__path__) if m.name.startswith("bench_"))
    for name in names:
        table = importlib.import_module(f"benchmarks.{name}").run()
        table.to_csv(out / f"{name}.csv", index=False)
        print(f"\n== {name} ==\n{table.to_string(index=False)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
