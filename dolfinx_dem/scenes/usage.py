"""Scene keys checked against each other: each must act or be an error naming it.

The schema (``scenes.SCHEMA``) checks each key's type; these checks say which mesh types read which
``[mesh]`` keys (docs/scenes.md, the "used by" column), that ``plane`` (plane strain or plane
stress) is a 2D hypothesis and ``statics.fixed_rotation`` a 2D constraint, and that a static scene
(one state written) has no use for the output periods, the animation and the dynamic penetration
limit.
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

#: Keys of dynamic scenes that a static scene (a ``statics`` table) has no use for.
DYNAMIC_ONLY = {"output": ("every", "series_every", "animation"), "contact": ("max_penetration",)}


def check_used(scene: Mapping, d: int | None) -> None:
    """A SceneError for a ``[mesh]`` key its type does not read, or a ``plane``,
    ``statics.fixed_rotation`` or ``statics.tangential_body_force`` outside 2D."""
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
        if scene.get("statics", {}).get("fixed_rotation"):
            raise SceneError(f"scene key 'statics.fixed_rotation' holds the rotation of a 2D body; this scene is {d}D")
        if "tangential_body_force" in scene.get("statics", {}):
            raise SceneError(f"scene key 'statics.tangential_body_force': statics with friction is implemented in 2D; "
                             f"this scene is {d}D")


def check_fracture(scene: Mapping, d: int | None) -> None:
    """A SceneError for fracture (``material.Gc``, issue 34) with what it does not support yet:
    contact, prescribed bodies, statics, several materials, 2D and 3D meshes (cracks with tips),
    FEM methods; and for a ``fracture`` table without ``material.Gc``."""
    if "Gc" not in scene.get("material", {}):
        if "fracture" in scene:
            raise SceneError("scene table 'fracture' configures the breaking facets of 'material.Gc', which this "
                             "scene does not give")
        return
    refused = [what for what, present in (
        ("'obstacles'", bool(scene.get("obstacles"))), ("'contact'", "contact" in scene),
        ("'prescribed'", bool(scene.get("prescribed"))), ("'statics'", "statics" in scene),
        (f"a {d}D mesh (2D and 3D cracks have tips: stage S2)", d is not None and d != 1),
        (f"method '{scene.get('method')}'", scene.get("method", "dem-A") not in ("dem-A", "dem-B"))) if present]
    if refused:
        raise SceneError(f"scene key 'material.Gc': fracture (issue 34) is not implemented with {refused[0]} yet "
                         "(dynamic 1D scenes, one process, dem-A or dem-B, no contact)")


def check_names(scene: Mapping) -> None:
    """A SceneError for a time-dependent value without ``time_dependent``, names of the reaction
    columns (Dirichlet conditions and prescribed bodies) that are not unique, or a prescribed body
    without exactly one of velocity and displacement."""
    for section in ("dirichlet", "tractions"):
        for i, bc in enumerate(scene.get(section, [])):
            for k, e in enumerate(bc.get("value", [])):
                if (
                    isinstance(e, str)
                    and "t" in compile(e, "<value>", "eval").co_names
                    and not bc.get("time_dependent")
                ):
                    raise SceneError(
                        f"scene key '{section}[{i}].value[{k}]' ({e!r}) uses t, but "
                        f"'{section}[{i}].time_dependent' is not true: the value would be frozen at "
                        "t = 0 (set time_dependent = true)"
                    )
    names = [bc["name"] for bc in scene.get("dirichlet", []) if "name" in bc]
    if len(set(names)) != len(names):
        raise SceneError(f"scene key 'dirichlet[].name': names must be unique, got {names}")
    for i, body in enumerate(scene.get("prescribed", [])):
        if ("velocity" in body) == ("displacement" in body):
            raise SceneError(f"scene table 'prescribed[{i}]' needs exactly one of 'velocity' and 'displacement'")
    reactions = [
        str(bc.get("name", i)) for i, bc in enumerate(scene.get("dirichlet", []) + scene.get("prescribed", []))
    ]
    if len(set(reactions)) != len(reactions):
        raise SceneError(
            f"scene keys 'dirichlet[].name' and 'prescribed[].name' name the reaction columns and must "
            f"be unique together, got {reactions} (unnamed: the number in the list of both)"
        )


def check_method(scene: Mapping) -> None:
    """A SceneError for a method that cannot run the scene's contact (``method`` set)."""
    if scene["method"] == "dem-AB" and not (scene.get("obstacles") or "contact" in scene):
        raise SceneError("method 'dem-AB' puts scheme B on the contact candidates: this scene has none (use dem-A)")
    if "contact" in scene:
        if scene["method"] == "fem-P2":
            raise SceneError("contact between bodies ('contact' table) needs a DEM method (dem-A, dem-B or dem-AB)")
        if "statics" in scene and scene.get("obstacles"):
            raise SceneError("a static scene takes obstacles or contact between bodies ('contact' table), not both")


def check_static(scene: Mapping) -> None:
    """A SceneError for a key of dynamic scenes in a static scene (``statics`` table)."""
    for section in ("time", "initial"):
        if section in scene:
            raise SceneError(f"a static scene ('statics' table) takes no '{section}' table")
    statics = scene.get("statics", {})
    frictional = [f"obstacles[{k}].friction" for k, obstacle in enumerate(scene.get("obstacles", []))
                  if obstacle.get("friction", 0.0) > 0]
    if scene.get("contact", {}).get("friction", 0.0) > 0:
        frictional.append("contact.friction")
    if frictional and "tangential_body_force" not in statics:
        raise SceneError(f"scene key '{frictional[0]}': friction is path dependent, a static scene with friction "
                         "takes its load path: the normal load, then 'statics.tangential_body_force' in "
                         "'statics.increments' steps (statics/friction.py; or a dynamic scene integrates it)")
    if "tangential_body_force" in statics and not frictional:
        raise SceneError("scene key 'statics.tangential_body_force': the tangential load path is for obstacles or "
                         "contact between bodies with friction > 0; this scene has none")
    if "increments" in statics and "tangential_body_force" not in statics:
        raise SceneError("scene key 'statics.increments': the increments of 'statics.tangential_body_force', "
                         "which this scene does not give")
    for section, keys in DYNAMIC_ONLY.items():
        for key in (k for k in keys if k in scene.get(section, {})):
            raise SceneError(f"scene key '{section}.{key}' applies to dynamic scenes: a static scene computes and "
                             "writes one state")
