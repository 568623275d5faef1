"""What the click-to-place operator hits: a ray against the object's evaluated surface."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass
class Hit:
    """A ray's first front-facing hit on the object.

    ``world`` and ``local`` are the point in world and object space, ``normal`` the face's
    world-space unit normal, ``face`` its index in the evaluated mesh."""

    world: tuple
    local: tuple
    normal: tuple
    face: int


def surface_hit(obj, depsgraph, origin, direction, distance: float = 1.0e10) -> Hit | None:
    """The first hit of the world-space ray ``origin + t * direction`` on ``obj`` (modifiers
    applied), or None: a miss, or a hit on a back face (the ray leaves the surface there, so
    the user is looking at the inside)."""
    from mathutils import Vector

    world = obj.matrix_world
    inverse = world.inverted_safe()
    o = inverse @ Vector(origin)
    d = (inverse.to_3x3() @ Vector(direction)).normalized()
    ok, location, normal, face = obj.ray_cast(o, d, distance=distance, depsgraph=depsgraph)
    if not ok:
        return None
    n_world = (inverse.to_3x3().transposed() @ normal).normalized()
    if n_world.dot(Vector(direction)) >= 0.0:
        return None
    return Hit(world=tuple(world @ location), local=tuple(location), normal=tuple(n_world),
               face=int(face))


def object_scale(obj) -> float:
    """One length scale of the object's world matrix (the cube root of its volume change):
    world radius = object radius * this."""
    det = abs(obj.matrix_world.to_3x3().determinant())
    return det ** (1.0 / 3.0) if det > 0 else 1.0
