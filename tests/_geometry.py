"""Shading geometry for tests: random unit normals with views on their front side.

    from _geometry import front_facing
    n, v = front_facing(np.random.default_rng(0), 32)
"""

from __future__ import annotations

import numpy as np


def front_facing(rng: np.random.Generator, count: int):
    """(normals, views), each (count, 3) unit vectors drawn isotropically, every view turned
    to the normal's side (⟨n, v⟩ ≥ 0). Draws the normals first, then the views."""
    n = rng.normal(size=(count, 3))
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    v = rng.normal(size=(count, 3))
    v /= np.linalg.norm(v, axis=-1, keepdims=True)
    return n, np.where(np.sum(n * v, -1, keepdims=True) < 0, -v, v)
