"""Error against run time of every evaluation path, and speed against peers (issue 4).

The same code as ``thinfilm-jax bench`` (`thinfilm_jax.bench.run_bench`):

    python benchmarks/run_bench.py                 # full study, ≤ 10 min on 2 CPU cores
    python benchmarks/run_bench.py --quick         # ≤ 1 min smoke version
    python benchmarks/run_bench.py --no-stability  # skip figures/stability_report.md

Writes bench.json, error_vs_runtime.png, error_vs_runtime.md (and stability_report.md)
into --out (default figures/) and prints the markdown tables. Timings depend on the machine
and its load: the JSON records jax.devices(), the CPU count and the load average.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys

import jax


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--out", default="figures", help="output folder (default: figures)")
    p.add_argument("--quick", action="store_true", help="small sizes (smoke test)")
    p.add_argument("--repeats", type=int, help="warm repeats per timing (default 5)")
    p.add_argument("--no-stability", action="store_true", help="skip the stability report")
    args = p.parse_args(argv)
    jax.config.update("jax_enable_x64", True)
    from thinfilm_jax.bench import BenchConfig, run_bench

    cfg = BenchConfig.quick() if args.quick else BenchConfig.full()
    if args.repeats:
        cfg = dataclasses.replace(cfg, repeats=args.repeats)
    if args.no_stability:
        cfg = dataclasses.replace(cfg, stability=False)
    result = run_bench(out=args.out, config=cfg)
    print(f"total {result['seconds_total']:.0f} s; wrote {args.out}/bench.json, "
          "error_vs_runtime.png, error_vs_runtime.md", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
