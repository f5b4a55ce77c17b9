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

# Left to their modules (main names its module; add_parser and add_arguments differ between modules):
# add_arguments, add_parser, main.

#: every module's __all__ (names re-exported by two modules are one object)
__all__ = [
    "RAW_SUFFIXES", "NOTES", "read_text", "read_csv", "read_observations", "check_output",
    "run_fit_cli",  # fit
    "IndexArg",  # fit_map
    "PHOTO_SUFFIXES", "run_photo",  # fit_photo
    "OWN_SCENE_OPTIONS", "build_parser",  # main
]
