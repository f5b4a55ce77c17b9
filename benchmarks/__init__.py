"""Studies and benchmarks: what the library measures about itself, outside the package.

A folder of the repository, beside `thinfilm_jax/` and not in its wheel: run from a clone,
at its root (``pip install -e '.[bench,plots]'``, or ``make setup``), as ``python -m
benchmarks.<module>``. Nothing in `thinfilm_jax` imports it; it imports the library's public
names only (tests/test_layout.py checks). What users run stays in the
library: ``thinfilm-jax figure7`` and ``thinfilm-jax render`` (`thinfilm_jax.render`). One
concern per module; the main ones:

* `bench` — ``python -m benchmarks.bench`` (``make bench``): runs the studies below, writes
  the report and the targets; ``--suite`` runs the other studies (ibl, scaling, improved,
  models, colour_table, materials, photo).
* `error_runtime` — error against run time of every evaluation path and knob.
* `pareto` — the error-vs-run-time table, Pareto front and figure.
* `peers` — `airy_reflectance` against tmm, NumPy and colour-science.
* `specialisation` — the cost saved and the error added by each static specialisation.
* `stability`, `stiff` — every public function at stiff and extreme inputs (asserted by
  tests/benchmarks/test_stability.py).
* `fit_study` — seeded recovery study of the fits (``python -m benchmarks.fit_study``).
* `gpu_check` — ``make gpu-check``: the suite and the GPU table on an accelerator.
* `_timing`, `_common` — timing, materials, error statistics shared by the above.

The full list, one line per module: docs/reference/layout.md.
"""
