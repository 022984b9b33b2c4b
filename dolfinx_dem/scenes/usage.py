"""Scene keys that only some scenes use: each must act or be an error naming it (issue 32.7).

The schema (``scenes.SCHEMA``) checks each key's type; these checks say which mesh types read which
``[mesh]`` keys (docs/scenes.md, the "used by" column), and that ``plane`` (plane strain or plane
stress) is a 2D hypothesis.
"""

from __future__ import annotations

from collections.abc import Mapping

from dolfinx_dem.errors import SceneError

_GMSH_BODIES = ("h", "frame", "frame_width", "cut", "refine_point", "refine_h", "refine_radius")
#: The ``[mesh]`` keys each mesh type reads.
MESH_KEYS = {
    "interval": ("x0", "x1", "n"),
    "rectangle": ("p0", "p1", "n", "diagonal"),
    "box": ("p0", "p1", "n"),
    "disc": ("centre", "radius", "h"),
    "discs": ("discs", "rectangles", *_GMSH_BODIES),
    "balls": ("balls", "boxes", *_GMSH_BODIES),
    "file": ("path",),
}


def check_used(scene: Mapping, d: int | None) -> None:
    """A SceneError for a ``[mesh]`` key its type does not read, or a ``plane`` outside 2D."""
    mesh = scene["mesh"]
    used = MESH_KEYS.get(mesh.get("type"), ())
    unused = [k for k in mesh if k != "type" and k not in used]
    if unused:
        raise SceneError(f"scene key 'mesh.{unused[0]}' is not read by a '{mesh['type']}' mesh, whose keys are "
                         f"{', '.join(used)} (to change the mesh type, give the whole table: "
                         "--set 'mesh={type=...}')")
    if d is not None and d != 2:
        tables = [("material", scene["material"])] if "material" in scene else [
            (f"materials[{i}]", m) for i, m in enumerate(scene.get("materials", []))]
        for name, table in tables:
            if "plane" in table:
                raise SceneError(f"scene key '{name}.plane' (plane strain or plane stress) is a 2D hypothesis; "
                                 f"this scene is {d}D")
