"""Scenes: TOML descriptions of a run, validated against a schema before anything is computed.

A scene names its mesh, material, boundary conditions, loads, initial conditions, method, time
stepping, probes and outputs; see ``docs/scenes.md`` and the built-in scenes next to this file.
Unknown keys and bad values raise ``SceneError`` naming the key.
"""

from __future__ import annotations

import copy
import math
import pathlib
import tomllib
from collections.abc import Mapping

import numpy as np

from dolfinx_dem.errors import MissingFileError, SceneError
from dolfinx_dem.material import ElasticMaterial
from dolfinx_dem.scenes.usage import check_fracture, check_method, check_names, check_static, check_used

BUILTIN = pathlib.Path(__file__).parent


def _number(key, v, positive=False, nonnegative=False):
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
        raise SceneError(f"scene key '{key}' must be a finite number, got {v!r}")
    if positive and v <= 0:
        raise SceneError(f"scene key '{key}' must be > 0, got {v!r}")
    if nonnegative and v < 0:
        raise SceneError(f"scene key '{key}' must be >= 0, got {v!r}")
    return float(v)


def _integer(key, v, minimum=1):
    if isinstance(v, bool) or not isinstance(v, int) or v < minimum:
        raise SceneError(f"scene key '{key}' must be an integer >= {minimum}, got {v!r}")
    return v


def _vector(key, v, length=None):
    if not isinstance(v, list) or not v or (length is not None and len(v) != length):
        n = f"{length} " if length else ""
        raise SceneError(f"scene key '{key}' must be a list of {n}numbers, got {v!r}")
    return [_number(f"{key}[{i}]", x) for i, x in enumerate(v)]


def _string(key, v, choices=None):
    if not isinstance(v, str) or (choices is not None and v not in choices):
        allowed = f" (one of {', '.join(choices)})" if choices else ""
        raise SceneError(f"scene key '{key}' must be a string{allowed}, got {v!r}")
    return v


def _field(key, v, d):
    """A constant vector or a list of d expression strings in x, y, z (and t)."""
    if isinstance(v, list) and v and all(isinstance(e, str) for e in v) and len(v) == (d or len(v)):
        allowed = set(_NAMESPACE) | {"t"} | set("xyz"[: d or 3])
        for i, e in enumerate(v):
            try:
                code = compile(e, f"<{key}[{i}]>", "eval")
            except SyntaxError as err:
                raise SceneError(f"scene key '{key}[{i}]' is not a valid expression: {err.msg}") from None
            unknown = set(code.co_names) - allowed
            if unknown:
                raise SceneError(f"scene key '{key}[{i}]' uses unknown names {sorted(unknown)} "
                                 f"(allowed: {', '.join(sorted(allowed))})")
        return v
    return _vector(key, v, d)


MESH_TYPES = ("interval", "rectangle", "box", "disc", "discs", "balls", "file")
METHODS = ("dem-A", "dem-B", "dem-AB", "fem-P1", "fem-P2")
QUADRATURES = ("midpoint", "gauss-legendre-1", "gauss-legendre-2", "gauss-legendre-3", "gauss-legendre-5")

#: Allowed keys per section; values are validators (key, value, d) -> value.
SCHEMA = {
    "name": lambda k, v, d: _string(k, v),
    "description": lambda k, v, d: _string(k, v),
    "method": lambda k, v, d: _string(k, v, METHODS),
    "mesh": {
        "type": lambda k, v, d: _string(k, v, MESH_TYPES),
        "n": lambda k, v, d: v if isinstance(v, int) and v >= 1 else [
            _integer(f"{k}[{i}]", x) for i, x in enumerate(_list(k, v))],
        "x0": lambda k, v, d: _number(k, v),
        "x1": lambda k, v, d: _number(k, v),
        "p0": lambda k, v, d: _vector(k, v),
        "p1": lambda k, v, d: _vector(k, v),
        "diagonal": lambda k, v, d: _string(k, v, ("right", "left", "crossed", "left_right", "right_left")),
        "centre": lambda k, v, d: _vector(k, v, 2),
        "radius": lambda k, v, d: _number(k, v, positive=True),
        "h": lambda k, v, d: _number(k, v, positive=True),
        "path": lambda k, v, d: _string(k, v),
        "discs": lambda k, v, d: [_vector(f"{k}[{i}]", x, 3) for i, x in enumerate(_list(k, v))],
        "balls": lambda k, v, d: [_vector(f"{k}[{i}]", x, 4) for i, x in enumerate(_list(k, v))],
        "rectangles": lambda k, v, d: [_vector(f"{k}[{i}]", x, 4) for i, x in enumerate(_list(k, v))],
        "boxes": lambda k, v, d: [_vector(f"{k}[{i}]", x, 6) for i, x in enumerate(_list(k, v))],
        "frame": lambda k, v, d: _vector(k, v, 2 * d if d else None),
        "frame_width": lambda k, v, d: _number(k, v, positive=True),
        "cut": lambda k, v, d: [_string(f"{k}[{i}]", x, tuple("xyz"[:d])) for i, x in enumerate(_list(k, v))],
        "refine_point": lambda k, v, d: _vector(k, v, d),
        "refine_h": lambda k, v, d: _number(k, v, positive=True),
        "refine_radius": lambda k, v, d: _number(k, v, positive=True),
    },
    "material": {
        "E": lambda k, v, d: _number(k, v),
        "nu": lambda k, v, d: _number(k, v),
        "rho": lambda k, v, d: _number(k, v),
        "plane": lambda k, v, d: _string(k, v, ("strain", "stress")),
        "eta": lambda k, v, d: _number(k, v),
        "Gc": lambda k, v, d: _number(k, v, positive=True),  # fracture (issue 34): J/m^2
    },
    "materials": [{
        "tag": lambda k, v, d: _integer(k, v, minimum=0),
        "E": lambda k, v, d: _number(k, v),
        "nu": lambda k, v, d: _number(k, v),
        "rho": lambda k, v, d: _number(k, v),
        "plane": lambda k, v, d: _string(k, v, ("strain", "stress")),
        "eta": lambda k, v, d: _number(k, v),
    }],
    "dirichlet": [{
        "boundary": lambda k, v, d: v if isinstance(v, int) and not isinstance(v, bool) else _string(k, v),
        "value": lambda k, v, d: _field(k, v, d),
        "time_dependent": lambda k, v, d: _bool(k, v),
        "components": lambda k, v, d: _components(k, v, d),
        "name": lambda k, v, d: _name(k, v),
    }],
    "tractions": [{
        "boundary": lambda k, v, d: v if isinstance(v, int) and not isinstance(v, bool) else _string(k, v),
        "value": lambda k, v, d: _field(k, v, d),
        "time_dependent": lambda k, v, d: _bool(k, v),
    }],
    "loads": {
        "gravity": lambda k, v, d: _vector(k, v, d),
        "body_force": lambda k, v, d: _vector(k, v, d),
    },
    "initial": {
        "displacement": lambda k, v, d: _field(k, v, d),
        "velocity": lambda k, v, d: _field(k, v, d),
    },
    "time": {
        "end": lambda k, v, d: _number(k, v, positive=True),
        "dt": lambda k, v, d: _number(k, v, positive=True),
        "cfl": lambda k, v, d: _number(k, v, positive=True),
        "stable_step": lambda k, v, d: _string(k, v, ("bound", "eigenvalue")),
        "quadrature": lambda k, v, d: _string(k, v, QUADRATURES),
    },
    "obstacles": [{
        "point": lambda k, v, d: _vector(k, v, d),
        "normal": lambda k, v, d: _vector(k, v, d),
        "boundary": lambda k, v, d: v if isinstance(v, int) and not isinstance(v, bool) else _string(k, v),
        "tolerance": lambda k, v, d: _number(k, v, nonnegative=True),
        "friction": lambda k, v, d: _number(k, v, nonnegative=True),
    }],
    "contact": {
        "boundary": lambda k, v, d: [x if isinstance(x, int) and not isinstance(x, bool) else _string(f"{k}[{i}]", x)
                                     for i, x in enumerate(_list(k, v))],
        "self_contact": lambda k, v, d: _bool(k, v),
        "tolerance": lambda k, v, d: _number(k, v, nonnegative=True),
        "skin": lambda k, v, d: _number(k, v, positive=True),
        "max_penetration": lambda k, v, d: _number(k, v, positive=True),
        "friction": lambda k, v, d: _number(k, v, nonnegative=True),
        "surface": lambda k, v, d: _string(k, v, ("facet", "vertex")),  # contact/surface.py SURFACES
    },
    "prescribed": [{
        "tag": lambda k, v, d: _integer(k, v, minimum=0),
        "velocity": lambda k, v, d: _vector(k, v, d),
        "displacement": lambda k, v, d: _translation(k, v, d),
        "name": lambda k, v, d: _name(k, v),
    }],
    "probes": [{
        "name": lambda k, v, d: _string(k, v),
        "point": lambda k, v, d: _vector(k, v, d),
        "component": lambda k, v, d: _integer(k, v, minimum=0),
    }],
    "statics": {
        "fixed_mean": lambda k, v, d: [_integer(f"{k}[{i}]", x, minimum=0) for i, x in enumerate(_list(k, v))],
        "fixed_rotation": lambda k, v, d: _bool(k, v),
        "rtol": lambda k, v, d: _number(k, v, positive=True),
        "gradient_rtol": lambda k, v, d: _number(k, v, positive=True),
        "time": lambda k, v, d: _number(k, v),
        "tangential_body_force": lambda k, v, d: _vector(k, v, d),
        "increments": lambda k, v, d: _integer(k, v, minimum=1),
    },
    "fracture": {
        "breakable": lambda k, v, d: [_vector(f"{k}[{i}]", x, d) for i, x in enumerate(_list(k, v))],
    },
    "output": {
        "every": lambda k, v, d: _integer(k, v),
        "series_every": lambda k, v, d: _integer(k, v),
        "picture_scale": lambda k, v, d: _number(k, v, positive=True),
        "animation": lambda k, v, d: _bool(k, v),
    },
}

#: Required keys of the sections; "mesh" and "material" are required sections, the others optional.
REQUIRED = {"mesh": ("type",), "material": ("E", "nu", "rho"), "contact": ("boundary",)}
#: Required keys of the entries of array-of-tables sections.
REQUIRED_ITEMS = {
    "materials": ("tag", "E", "nu", "rho"),
    "dirichlet": ("boundary",),
    "tractions": ("boundary", "value"),
    "probes": ("name", "point", "component"),
    "prescribed": ("tag",),
    "obstacles": ("point", "normal", "boundary"),
}
#: Facet tags of the generated interval/rectangle/box meshes, by boundary name.
SIDES = {"xmin": 1, "xmax": 2, "ymin": 3, "ymax": 4, "zmin": 5, "zmax": 6, "left": 1, "right": 2, "bottom": 3, "top": 4}


def _list(key, v):
    if not isinstance(v, list):
        raise SceneError(f"scene key '{key}' must be a list, got {v!r}")
    return v


def _components(key, v, d):
    """A nonempty list of distinct displacement components, each in [0, d - 1]."""
    items = [_integer(f"{key}[{i}]", x, minimum=0) for i, x in enumerate(_list(key, v))]
    if not items or len(set(items)) != len(items) or (d is not None and max(items) >= d):
        raise SceneError(
            f"scene key '{key}' must be a nonempty list of distinct components in [0, {(d or 3) - 1}] "
            f"(0 = x, 1 = y, 2 = z), got {v!r}"
        )
    return items


def _translation(key, v, d):
    """d expression strings in t (a rigid translation U(t))."""
    if not (isinstance(v, list) and v and all(isinstance(e, str) for e in v) and len(v) == (d or len(v))):
        raise SceneError(f"scene key '{key}' must be a list of {d or 'd'} expressions in t (strings), got {v!r}")
    for i, e in enumerate(v):
        try:
            names = compile(e, f"<{key}[{i}]>", "eval").co_names
        except SyntaxError as err:
            raise SceneError(f"scene key '{key}[{i}]' is not a valid expression: {err.msg}") from None
        unknown = set(names) - set(_NAMESPACE) - {"t"}
        if unknown:
            raise SceneError(
                f"scene key '{key}[{i}]' uses unknown names {sorted(unknown)} "
                f"(allowed: {', '.join(sorted(set(_NAMESPACE) | {'t'}))})"
            )
    return v


def _name(key, v):
    """A name for series columns: letters, digits and underscores."""
    if not (isinstance(v, str) and v and v.replace("_", "a").isalnum() and v.isascii()):
        raise SceneError(f"scene key '{key}' must be a name of letters, digits and underscores, got {v!r}")
    return v


def _bool(key, v):
    if not isinstance(v, bool):
        raise SceneError(f"scene key '{key}' must be true or false, got {v!r}")
    return v


def dimension(scene: Mapping) -> int:
    """Spatial dimension implied by the mesh section."""
    mesh = scene.get("mesh", {})
    kind = mesh.get("type")
    if kind == "interval":
        return 1
    if kind in ("rectangle", "disc", "discs"):
        return 2
    if kind in ("box", "balls"):
        return 3
    if kind == "file":
        return None  # known once the mesh is read; validate() is called again then
    raise SceneError(f"scene key 'mesh.type' must be one of {', '.join(MESH_TYPES)}, got {kind!r}")


def _validate_table(prefix, table, schema, d):
    if not isinstance(table, dict):
        raise SceneError(f"scene key '{prefix}' must be a table")
    out = {}
    for key, value in table.items():
        name = f"{prefix}.{key}" if prefix else key
        if key not in schema:
            raise SceneError(f"scene key '{name}' is unknown (allowed: {', '.join(sorted(schema))})")
        rule = schema[key]
        if isinstance(rule, dict):
            out[key] = _validate_table(name, value, rule, d)
        elif isinstance(rule, list):
            out[key] = [_validate_table(f"{name}[{i}]", v, rule[0], d) for i, v in enumerate(_list(name, value))]
        else:
            out[key] = rule(name, value, d)
    return out


def validate(scene: Mapping, mesh_dimension: int | None = None) -> dict:
    """Check every key and value of a scene; returns a validated deep copy."""
    scene = copy.deepcopy(dict(scene))
    if "mesh" not in scene:
        raise SceneError("scene key 'mesh' is missing")
    d = mesh_dimension or dimension(scene)
    scene = _validate_table("", scene, SCHEMA, d)
    if ("material" in scene) == ("materials" in scene):
        raise SceneError("a scene needs exactly one of 'material' (one material) and 'materials' (one per cell tag)")
    check_used(scene, d)
    check_fracture(scene, d)
    for section, keys in REQUIRED.items():
        if (
            section not in scene
            and section not in ("mesh", "material")
            or section == "material"
            and "materials" in scene
        ):
            continue
        for key in keys:
            if key not in scene.get(section, {}):
                raise SceneError(f"scene key '{section}.{key}' is missing")
    for section, keys in REQUIRED_ITEMS.items():
        for i, item in enumerate(scene.get(section, [])):
            for key in keys:
                if key not in item:
                    raise SceneError(f"scene key '{section}[{i}].{key}' is missing")
    check_names(scene)
    if "statics" in scene:
        check_static(scene)
        if scene.get("method") == "fem-P1":
            raise SceneError("method 'fem-P1' (the explicit FEM peer) is available for dynamic scenes only")
    else:
        _validate_time(scene)
        if scene.get("method") == "fem-P2":
            raise SceneError("method 'fem-P2' is available for static scenes (the Hertz reference) only")
    materials(scene)
    loads = scene.get("loads", {})
    if "gravity" in loads and "body_force" in loads:
        raise SceneError("scene key 'loads': give 'gravity' or 'body_force', not both")
    scene.setdefault("method", "dem-A")
    scene.setdefault("name", "scene")
    check_method(scene)
    return scene


def materials(scene: Mapping) -> ElasticMaterial | dict[int, ElasticMaterial]:
    """The scene's material: an ElasticMaterial (``material``), or {cell tag: ElasticMaterial}
    (``materials``), whose tags must differ and whose entries share ``plane``."""
    if "material" in scene:
        return _material("scene table 'material'", scene["material"])
    out = {}
    for i, m in enumerate(scene["materials"]):
        if m["tag"] in out:
            raise SceneError(
                f"scene key 'materials[{i}].tag': cell tag {m['tag']} already has a material (materials overlap)"
            )
        out[m["tag"]] = _material(f"scene table 'materials[{i}]'", m)
    planes = [m.plane for m in out.values()]
    if len(set(planes)) > 1:
        raise SceneError(
            f"scene key 'materials': all materials must share 'plane' (the body's 2D hypothesis), got {planes}"
        )
    if "gravity" in scene.get("loads", {}):
        raise SceneError(
            "scene key 'loads.gravity' needs one material (rho g is one body force): with 'materials', "
            "give 'loads.body_force'"
        )
    if scene.get("method") == "fem-P2":
        raise SceneError("method 'fem-P2' (the Hertz reference) takes one material, not 'materials'")
    return out


def _material(what, m) -> ElasticMaterial:
    try:
        return ElasticMaterial(E=m["E"], nu=m["nu"], rho=m["rho"], plane=m.get("plane", "strain"), eta=m.get("eta"))
    except ValueError as err:
        raise SceneError(f"{what}: {err}") from None


def _validate_time(scene):
    time = scene.get("time", {})
    if "end" not in time:
        raise SceneError("scene key 'time.end' is missing")
    if ("dt" in time) == ("cfl" in time):
        raise SceneError("scene needs exactly one of 'time.dt' and 'time.cfl'")
    if "stable_step" in time and "cfl" not in time:
        raise SceneError("scene key 'time.stable_step' goes with 'time.cfl'")
    if (
        "dt" in time
        and abs(time["end"] / time["dt"] - round(time["end"] / time["dt"])) > 1e-9 * time["end"] / time["dt"]
    ):
        raise SceneError(f"scene key 'time.end' ({time['end']}) must be a multiple of 'time.dt' ({time['dt']})")


def builtin_names() -> list[str]:
    return sorted(p.stem for p in BUILTIN.glob("*.toml"))


def load(name_or_path: str, overrides: Mapping[str, object] | None = None) -> dict:
    """Read a built-in scene by name or a TOML file, apply dotted-key overrides, validate."""
    path = pathlib.Path(name_or_path)
    if not path.suffix:
        if name_or_path not in builtin_names():
            raise SceneError(f"unknown scene {name_or_path!r}; built-in scenes: {', '.join(builtin_names())}")
        path = BUILTIN / f"{name_or_path}.toml"
    if not path.is_file():
        raise MissingFileError(f"scene file {path} does not exist")
    with open(path, "rb") as f:
        try:
            scene = tomllib.load(f)
        except tomllib.TOMLDecodeError as err:
            raise SceneError(f"scene file {path} is not valid TOML: {err}") from None
    if "mesh" in scene and scene["mesh"].get("type") == "file":
        p = pathlib.Path(scene["mesh"].get("path", ""))
        if not p.is_absolute():
            scene["mesh"]["path"] = str((path.parent / p).resolve())
    return override(scene, overrides)


def override(scene: Mapping, overrides: Mapping[str, object] | None = None) -> dict:
    """A validated copy of ``scene`` with the dotted-key ``overrides`` applied."""
    scene = copy.deepcopy(dict(scene))
    for key, value in (overrides or {}).items():
        set_key(scene, key, value)
    return validate(scene)


def set_key(scene: dict, dotted: str, value):
    """Set ``a.b.c = value`` in a nested scene dict (creating tables as needed)."""
    parts = dotted.split(".")
    table = scene
    for p in parts[:-1]:
        table = table.setdefault(p, {})
        if not isinstance(table, dict):
            raise SceneError(f"scene key '{dotted}': '{p}' is not a table")
    table[parts[-1]] = value


def parse_override(text: str) -> tuple[str, object]:
    """``key=value`` with a TOML value (``mesh.n=[40, 4]``, ``time.end=2.0``); bare words are strings."""
    if "=" not in text:
        raise SceneError(f"override {text!r} must look like key=value")
    key, raw = text.split("=", 1)
    key = key.strip()
    try:
        value = tomllib.loads(f"v = {raw.strip()}")["v"]
    except tomllib.TOMLDecodeError:
        value = raw.strip()
    return key, value


_NAMESPACE = {name: getattr(np, name) for name in ("sin", "cos", "tan", "exp", "sqrt", "abs", "tanh", "pi", "where")}


def evaluate_condition(expression: str, x: np.ndarray, key: str) -> np.ndarray:
    """A boolean expression in x, y, z (e.g. "y <= 0.2") at points x (d, n)."""
    d = x.shape[0]
    names = dict(_NAMESPACE, **{c: x[i] for i, c in enumerate("xyz"[:d])})
    try:
        code = compile(expression, f"<{key}>", "eval")
    except SyntaxError as err:
        raise SceneError(f"scene key '{key}' is not a valid condition: {err.msg}") from None
    unknown = set(code.co_names) - set(names)
    if unknown:
        raise SceneError(f"scene key '{key}' uses unknown names {sorted(unknown)}")
    return eval(code, {"__builtins__": {}}, names)  # noqa: S307


def evaluate_field(spec, x: np.ndarray, t: float = 0.0, key: str = "field") -> np.ndarray:
    """Evaluate a scene field (constant vector or expressions in x, y, z, t) at points x (d, n).
    A value that is not finite (NaN, inf) is a ``SceneError`` naming the scene ``key``, the
    expression, the time and a point."""
    d, n = x.shape
    if all(isinstance(e, str) for e in spec):
        names = dict(_NAMESPACE, t=t, **{c: x[i] for i, c in enumerate("xyz"[:d])})
        out = np.empty((d, n))
        for i, e in enumerate(spec):
            with np.errstate(all="ignore"):  # reported below, with the key
                out[i] = np.broadcast_to(eval(e, {"__builtins__": {}}, names), (n,))  # noqa: S307
            bad = ~np.isfinite(out[i])
            if bad.any():
                k = int(np.argmax(bad))
                raise SceneError(
                    f"scene key '{key}[{i}]' ({e!r}) is not finite at t = {t:.9g}: {out[i, k]} at "
                    f"x = {x[:, k].tolist()}"
                )
        return out
    return np.repeat(np.asarray(spec, dtype=float)[:, None], n, axis=1)
