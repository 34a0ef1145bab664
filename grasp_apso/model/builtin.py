"""The paper's four test objects (section 5), built once and cached: sphere, cube,
barrel, fish, with the paper's sizes (metres)."""

from __future__ import annotations

import functools

import numpy as np

from ..errors import ObjectError
from . import shapes
from .objects import GraspObject, from_arrays

__all__ = ["BUILTIN_OBJECTS", "builtin"]

#: Names accepted by :func:`builtin`.
BUILTIN_OBJECTS: tuple[str, ...] = ("sphere", "cube", "barrel", "fish")


_BUILDERS = {
    "sphere": shapes.sphere,
    "cube": shapes.cube,
    "barrel": shapes.barrel,
    "fish": shapes.fish,
}


@functools.lru_cache(maxsize=None)
def _builtin_cached(name: str) -> GraspObject:
    """Build (once) the built-in object ``name``, centre of mass moved to the origin."""
    vertices, faces = _BUILDERS[name]()
    first = from_arrays(vertices, faces, name=name)
    if np.allclose(first.center_of_mass, 0.0, atol=1e-9):
        return first
    return from_arrays(vertices - first.center_of_mass, faces, name=name)


def builtin(name: str) -> GraspObject:
    """One of the paper's test objects, with the paper's sizes (metres).

    ========  ===================================================================
    name      shape
    ========  ===================================================================
    sphere    icosphere (subdivisions 3), diameter 0.05
    cube      box, edge 0.07, faces normal to the object axes
    barrel    along z: length 0.11, diameter 0.03 in the middle and 0.03 / 1.1 at
              the flat ends (a 10 % parabolic bulge), 48 sections
    fish      0.29 (x, head at +x) x 0.06 (y) x 0.07 (z, back up): lofted
              streamlined body, narrow tail stalk, forked tail fin
    ========  ===================================================================

    All are closed, outward-oriented meshes whose centre of mass is at the origin
    (the fish is shifted along x to put it there). Built once and cached; the returned
    objects are shared and immutable.

    Parameters
    ----------
    name : str
        One of :data:`BUILTIN_OBJECTS` (exact, lower case).

    Returns
    -------
    GraspObject

    Raises
    ------
    ObjectError
        ``object_name: unknown built-in object ...`` naming the valid ones.
    """
    if not isinstance(name, str) or name not in _BUILDERS:
        raise ObjectError(
            f"object_name: unknown built-in object {name!r} "
            f"(expected one of: {', '.join(BUILTIN_OBJECTS)})"
        )
    return _builtin_cached(name)
