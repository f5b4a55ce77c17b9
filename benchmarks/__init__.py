"""Studies and benchmarks: what the library measures about itself, outside the core.

Nothing in the core imports this package; ``thinfilm-jax figure7`` and ``python -m benchmarks.bench``
import it lazily. One concern per module:

* `figure7` — Figure 7 of Kneiphof et al. 2019 (``thinfilm-jax figure7``, ``make figure7``).
* `bench` — ``python -m benchmarks.bench``: runs the studies below, writes the report and the targets.
* `error_runtime` — error against run time of every evaluation path and knob.
* `pareto` — the error-vs-run-time table, Pareto front and figure.
* `peers` — `airy_reflectance` against tmm, NumPy and colour-science.
* `specialisation` — the cost saved and the error added by each static specialisation.
* `stability`, `stiff` — every public function at stiff and extreme inputs (asserted by
  tests/benchmarks/test_stability.py).
* `fit_study` — seeded recovery study of the fits (``python -m benchmarks.fit_study``).
* `_timing`, `_common` — timing, materials, error statistics shared by the above.
"""
