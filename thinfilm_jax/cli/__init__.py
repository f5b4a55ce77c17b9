"""Layer 9 (above `render`), the command line ``thinfilm-jax`` (`main`), its ``fit`` and
``fit-map`` sub-commands (`fit`, `fit_map`) and the checks of its arguments (`_checks`)."""

from .fit import (
    RAW_SUFFIXES,
    NOTES,
    read_text,
    read_csv,
    read_observations,
    check_output,
    run_fit_cli,
)
from .fit_map import IndexArg
from .fit_photo import PHOTO_SUFFIXES, run_photo
from .main import OWN_SCENE_OPTIONS, build_parser

# Left to their modules (the name means different things in two modules, or names a
# module): add_arguments, add_parser, main.

__all__ = [
    "RAW_SUFFIXES",
    "NOTES",
    "read_text",
    "read_csv",
    "read_observations",
    "check_output",
    "run_fit_cli",
    "IndexArg",
    "PHOTO_SUFFIXES",
    "run_photo",
    "OWN_SCENE_OPTIONS",
    "build_parser",
]
