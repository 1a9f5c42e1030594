"""Is the skin object at its real size?

The skin's radii are physical: millimetres of light transport, given to Cycles and EEVEE in Blender units through
the scene's Unit Scale (metres per Blender unit, :func:`blender_addon.follow.scene_unit_scale`).  A model that is not
the size the scene's units say renders wrong without an error: a character modelled in centimetres in a scene left
in metres is 180 m tall to the renderer, its skin nearly opaque and hard; one a hundred times too small renders like
wax.  (Blender's own Principled BSDF leaves this to the artist's Subsurface Scale.)  :func:`warning` says so in
one line, with what to do: Invert Skin Albedo's report and the panel carry it.
"""

from __future__ import annotations

import bpy
from mathutils import Vector

#: The largest side (metres) of the world-space bounding box of an object carrying skin that is taken as real: from
#: a separate small part (a fingertip or an earlobe is about a centimetre; half of that is left as margin) to a
#: whole character with its arms raised (3 m, above the tallest person measured, 2.72 m: Robert Wadlow, Guinness
#: World Records).  A creature meant to be larger can keep its size: the warning asks only to check.
SMALLEST_M = 0.005
LARGEST_M = 3.0


def extent_m(obj: bpy.types.Object, unit_scale_m: float) -> float:
    """The largest side of ``obj``'s bounding box in world space (its object and parents' transforms applied), in
    metres at ``unit_scale_m`` metres per Blender unit; 0 for an object without one."""
    corners = [obj.matrix_world @ Vector(corner) for corner in obj.bound_box]
    if not corners:
        return 0.0
    return max(max(c[axis] for c in corners) - min(c[axis] for c in corners) for axis in range(3)) * unit_scale_m


def describe(metres: float) -> str:
    """``metres`` for a person to read: metres, centimetres or millimetres, three significant digits."""
    unit, size = ("m", 1.0) if metres >= 1.0 else ("cm", 0.01) if metres >= 0.01 else ("mm", 0.001)
    return f"{metres / size:.3g} {unit}"


def plausible(metres: float) -> bool:
    """Whether an object ``metres`` across (:func:`extent_m`) is taken as skin at its real size: within
    :data:`SMALLEST_M` and :data:`LARGEST_M`, or without an extent (nothing to say)."""
    return metres <= 0.0 or SMALLEST_M <= metres <= LARGEST_M


def look(metres: float) -> str:
    """What skin looks like on an object ``metres`` across outside the real sizes: nearly opaque where larger,
    like wax where smaller."""
    return "nearly opaque and hard" if metres > LARGEST_M else "like wax"


def warning(obj: bpy.types.Object | None, unit_scale_m: float) -> str | None:
    """One line where ``obj`` (the skin object) is larger or smaller than skin is at ``unit_scale_m`` metres per
    Blender unit (:data:`SMALLEST_M`, :data:`LARGEST_M`): how large it is, what the skin will look like and what
    to set; None where it is within them, or there is no object or no extent."""
    if obj is None:
        return None
    size = extent_m(obj, unit_scale_m)
    if plausible(size):
        return None
    return (f"'{obj.name}' is {describe(size)} across at Unit Scale {unit_scale_m:g} m per Blender unit, and skin "
            f"scatters light over millimetres, so it will look {look(size)}; if the model is not that size, set "
            "Scene > Units > Unit Scale to its real size (0.01 for a model in centimetres)")
