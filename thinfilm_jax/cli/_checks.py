"""Checks of command-line values before any work (``thinfilm-jax``): a bad value is a usage
error (exit status 2, no traceback), found before minutes of computing.

`check_args` looks at the options a sub-command defines, by name; `run_command` runs the
sub-command and turns what can still go wrong with the user's input (an unreadable file, a
value the library rejects, Ctrl-C) into a one-line message that names the options the user
typed, not the library's argument names (`cli_names`).
"""

from __future__ import annotations

import math
import os
import re
import sys
from pathlib import Path

# option name → (lowest, highest, lowest excluded, kind); None: unbounded
NUMERIC = {
    "resolution": (1, None, False, int),
    "terms": (0, None, False, int),
    "quadrature": (2, None, False, int),
    "chunk": (1, None, False, int),
    "devices": (1, None, False, int),
    "alpha": (0.0, 1.0, True, float),
    "eta_film": (1.0, None, False, float),
    "eta_base": (0.0, None, True, float),
    "kappa_base": (0.0, None, False, float),
    "thickness": (0.0, None, False, float),
    "thickness_max": (0.0, None, True, float),
    "exposure": (0.0, None, True, float),
    "eta_outer": (1.0, None, False, float),
    "theta_o": (0.0, 90.0, False, float),
    "sigma": (0.0, None, True, float),
    "smoothness": (0.0, None, True, float),
    "grid": (2, None, False, int),
    "thickness_range": (0.0, None, False, float),
}
#: sub-commands whose --out is a folder
FOLDER_OUT = ("figure7", "render", "fit-map")


def _enable_x64():
    import jax

    jax.config.update("jax_enable_x64", True)


def _devices(args):
    """``--distributed`` joins a multi-host run first (`jax.distributed`); ``--devices`` k is
    then checked against the devices there (ValueError naming it: exit status 1)."""
    from ..core.sharding import batch_mesh, initialize_distributed

    if getattr(args, "distributed", False):
        initialize_distributed()
    batch_mesh(args.devices)
    return args.devices


def _add_device_options(sub) -> None:
    sub.add_argument("--devices", type=int, help="split the work across the first K devices "
                     "(default: every device; CPU: XLA_FLAGS=--xla_force_host_platform_"
                     "device_count=K makes K host devices)", metavar="K")
    sub.add_argument("--distributed", action="store_true",
                     help="several hosts: call jax.distributed.initialize() first (SLURM, "
                          "Open MPI or JAX_COORDINATOR_ADDRESS, JAX_NUM_PROCESSES, "
                          "JAX_PROCESS_ID); process 0 writes the files")


def _flag(name: str) -> str:
    return "--" + name.replace("_", "-")


def check_args(parser, args) -> None:
    """`parser.error` (usage, exit 2) for the first out-of-range option of `args`."""
    command = getattr(args, "command", None)
    subparsers = getattr(parser, "_subparsers", None)
    for action in subparsers._group_actions if subparsers is not None else ():
        choices = getattr(action, "choices", None)
        if isinstance(choices, dict) and command in choices:
            parser = choices[command]  # errors show the sub-command's usage
    for name, (lo, hi, lo_open, kind) in NUMERIC.items():
        vs = getattr(args, name, None)
        if vs is None or command not in FOLDER_OUT:
            continue
        for v in vs if isinstance(vs, list) else (vs,):
            _check_value(parser, name, v, lo, hi, lo_open, kind)
    _check_out(parser, command, args)


def _check_value(parser, name, v, lo, hi, lo_open, kind) -> None:
    if isinstance(v, float) and not math.isfinite(v):
        parser.error(f"argument {_flag(name)}: must be finite, got {v}")
    low_bad = v <= lo if lo_open else v < lo
    if low_bad or (hi is not None and v > hi):
        lb = "(" if lo_open else "["
        rng = f"{lb}{lo}, {'inf)' if hi is None else f'{hi}]'}"
        what = "an integer" if kind is int else "a number"
        parser.error(f"argument {_flag(name)}: must be {what} in {rng}, got {v}")


def _check_out(parser, command, args) -> None:
    out = getattr(args, "out", None)
    if command in FOLDER_OUT and out is not None:
        p = Path(out)
        if p.exists() and not p.is_dir():
            parser.error(f"argument --out: {out} exists and is not a folder")
        for parent in p.absolute().parents:
            if parent.exists():
                if not parent.is_dir():
                    parser.error(f"argument --out: {parent} is not a folder")
                break


#: the library's argument names in messages (``initial.eta_film``: a field of the material
#: the command built) → the option the user gave it as, and that option's argparse
#: destinations (one per sub-command that has it)
CLI_NAMES = {
    "eta_film": ("--eta-film", ("eta_film", "eta_film_index", "film_index")),
    "eta_base": ("--eta-base", ("eta_base", "eta_base_index", "base_index")),
    "eta_outer": ("--eta-outer", ("eta_outer", "eta_outer_index")),
    "kappa_base": ("--kappa-base", ("kappa_base",)),
}
_API_NAME = re.compile(r"\b(?:initial|template|film|material|stack)\.(eta_film|eta_base|"
                       r"eta_outer|kappa_base|eta\[(\d+)\])(?![\w\[])")


def cli_names(message: str, args) -> str:
    """`message` with the library's names of what the command line gave (``initial.eta_film``,
    ``template.eta_base``, ``initial.eta[1]`` of a ``--layers`` stack) replaced by the options
    the user typed (``--eta-film``, ``--eta-base``, ``--layers layer 1``). A name whose option
    was not given (a setting read from a file) is left as it is.

    Example:
        >>> import argparse
        >>> args = argparse.Namespace(eta_film_index="water", eta_base_index="Si")
        >>> cli_names("initial.eta_film (water) ...; initial.eta_base (Si) ...", args)
        '--eta-film (water) ...; --eta-base (Si) ...'
    """
    def given(dests) -> bool:
        return any(getattr(args, d, None) not in (None, False) for d in dests)

    def swap(m: re.Match) -> str:
        if m.group(2) is not None:
            return (f"--layers layer {m.group(2)}" if given(("layers",)) else m.group(0))
        flag, dests = CLI_NAMES[m.group(1)]
        return flag if given(dests) else m.group(0)

    return _API_NAME.sub(swap, message)


def run_command(args) -> int:
    """Run ``args.func(args)``; user-facing failures become one line on stderr.

    Ctrl-C exits with status 130 (outputs are written atomically: nothing partial is left);
    a ValueError/TypeError/OSError (bad input discovered while running, an unwritable path)
    exits with status 1. ``THINFILM_JAX_TRACEBACK=1`` re-raises instead (for debugging).
    """
    prog = f"thinfilm-jax {getattr(args, 'command', '')}".strip()
    try:
        return args.func(args)
    except SystemExit as e:  # a command's own one-line message (`fit`): the same names
        if isinstance(e.code, str):
            raise SystemExit(cli_names(e.code, args)) from None
        raise
    except KeyboardInterrupt:
        if os.environ.get("THINFILM_JAX_TRACEBACK"):
            raise
        print(f"\n{prog}: interrupted; no partial output was written", file=sys.stderr)
        return 130
    except (ValueError, TypeError, OSError) as e:
        if os.environ.get("THINFILM_JAX_TRACEBACK"):
            raise
        msg = str(e).strip().splitlines()[0] if str(e).strip() else type(e).__name__
        print(f"{prog}: error: {cli_names(msg, args)}", file=sys.stderr)
        return 1
