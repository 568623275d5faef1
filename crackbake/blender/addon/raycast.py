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


def circle_points(centre, normal, radius: float, segments: int = 48) -> list[tuple]:
    """``segments + 1`` points of the circle of ``radius`` around ``centre`` in the plane
    perpendicular to ``normal`` (closed: the last point is the first), for drawing an impact."""
    import math

    from mathutils import Vector

    n = Vector(normal).normalized()
    helper = Vector((1.0, 0.0, 0.0)) if abs(n.x) < 0.9 else Vector((0.0, 1.0, 0.0))
    u = n.cross(helper).normalized()
    v = n.cross(u)
    c = Vector(centre)
    return [tuple(c + radius * (math.cos(a) * u + math.sin(a) * v))
            for a in (2.0 * math.pi * i / segments for i in range(segments + 1))]


def impact_circles(obj, default_fraction: float = 0.15) -> list[list[tuple]]:
    """World-space circles of the object's impacts on its surface: around the closest surface
    point, in its tangent plane, of the impact's radius (0: ``default_fraction`` of the
    object's bounding-box diagonal, crackbake's default)."""
    from mathutils import Vector

    world = obj.matrix_world
    corners = [Vector(c) for c in obj.bound_box]
    diagonal = (corners[6] - corners[0]).length
    circles = []
    for impact in obj.crackbake.impacts:
        ok, point, normal, _face = obj.closest_point_on_mesh(Vector(impact.location))
        if not ok:
            point, normal = Vector(impact.location), Vector((0.0, 0.0, 1.0))
        radius = impact.radius if impact.radius > 0 else default_fraction * diagonal
        lift = point + normal * 1e-3 * diagonal  # just above the surface, not inside it
        local = circle_points(lift, normal, radius)
        circles.append([tuple(world @ Vector(p)) for p in local])
    return circles
