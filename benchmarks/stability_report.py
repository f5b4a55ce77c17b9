"""Write figures/stability_report.md: every public function at stiff and extreme inputs.

    python benchmarks/stability_report.py [--out figures/stability_report.md]

The checks are `thinfilm_jax.bench.STABILITY_FUNCTIONS` (value and gradient, float32 and
float64); tests/test_stability.py asserts the same results.
"""

from __future__ import annotations

import argparse
import sys

import jax


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--out", default="figures/stability_report.md", help="markdown path")
    args = p.parse_args(argv)
    jax.config.update("jax_enable_x64", True)
    from thinfilm_jax.bench import write_stability_report

    summary = write_stability_report(args.out, verbose=True)
    print(f"{summary['n_checks']} checks, {summary['n_problems']} problems; wrote {args.out}")
    return 1 if summary["n_problems"] else 0


if __name__ == "__main__":
    sys.exit(main())
