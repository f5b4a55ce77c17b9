r"""`method="colour_table"`: Kneiphof & Klein 2022's prefiltered colour table of one material
and map (SPEC §11, `shading.colour_table`): A(θ_o, α) Σ_k C_jk(ω_r, θ_o) P_k(ω_r, α), read
from the `ColourTable` that `prefilter_colour(map, film, alpha)` built (checked against the
film, α and observer here).

Example:
    >>> from thinfilm_jax.core.methods import implementation
    >>> implementation("colour_table").envmap_kind
    'table'
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np

from ...core import _validate as V
from ..colour_table import check_colour_table, colour_table_radiance
from . import ShadingMethod


class ColourTableMethod(ShadingMethod):
    name = "colour_table"
    envmap_kind = "table"

    def envmap_table(self, film, alpha, normal, view, table, observer):
        """The checks of SPEC §11, then `colour_table_radiance`."""
        check_colour_table(table, film, alpha)
        if observer != table.observer:
            raise ValueError(f"the ColourTable holds the bands of observer={table.observer!r}, "
                             f"got observer={observer!r}")
        for name, v in (("normal", normal), ("view", view)):
            if np.shape(v)[-1:] != (3,):
                raise ValueError(f"{name} must have shape (..., 3), got {np.shape(v)}")
            if V.is_concrete(v):
                V.check_finite(name, v)
        shape = V.check_broadcast([("film", np.zeros(film.shape)), ("alpha", alpha),
                                   ("normal", np.zeros(np.shape(normal)[:-1])),
                                   ("view", np.zeros(np.shape(view)[:-1]))])
        nv = [jnp.broadcast_to(jnp.asarray(v), shape + (3,)) for v in (normal, view)]
        return colour_table_radiance(table, *nv)


COLOUR_TABLE = ColourTableMethod()
