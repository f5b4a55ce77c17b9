"""Layer 9 (above `render`), the command line ``thinfilm-jax`` (`main`), its ``fit`` and
``fit-map`` sub-commands (`fit`, `fit_map`) and the checks of its arguments (`_checks`)."""
