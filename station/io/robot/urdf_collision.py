"""The ``<collision>`` elements of a URDF's links (issue 40; docs/collision.md, docs/robot-file.md "URDF"):
each link's boxes, cylinders, spheres and meshes, placed in the station frame the link rides on.

URDF (wiki.ros.org/urdf/XML/link, "<collision>"): a link may hold several ``<collision>`` elements,
each an optional ``<origin xyz rpy>`` (in the link's frame, metres and radians) and one ``<geometry>``:
``<box size="x y z"/>`` (centred), ``<cylinder radius length/>`` (centred, along z), ``<sphere
radius/>`` or ``<mesh filename scale/>``. A mesh's file is ``package://PKG/REL``, ``file:///ABS`` or a
path relative to the URDF; a package is looked for beside the URDF and in each folder above it (a
folder ``PKG``, or a folder above named ``PKG`` itself). trimesh reads the mesh (STL, OBJ, DAE, …).

The links of the chain only (the one :func:`station.io.robot.formats.robot_from_urdf` imports, base
link first); a link fixed to a moving one rides on that one's frame. A link's frame in the station's
frame is the same for every joint value (both are rigid with the link), so it is found once, at the
joints' zero: the URDF's own chain of origins against the station model's frames
(:func:`station.core.kinematics.forward.chain_frames`). A mesh file that is not found is kept as such
(``missing``): the collision check refuses that link (it never skips it); the import and every command
that does not check collisions go on.
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from station.core.kinematics.forward import chain_frames
from station.core.kinematics.transforms import invert, pose_to_matrix
from station.errors import ConfigError
from station.io.robot.formats import _urdf_chain, _urdf_link, robot_from_urdf, urdf_joint_origin, urdf_root

__all__ = ["LinkGeometry", "urdf_link_geometry", "resolve_mesh"]

#: URDF lengths are metres; the station's are millimetres
MM_PER_M = 1000.0


@dataclass(frozen=True)
class LinkGeometry:
    """One ``<collision>`` element: ``kind`` "box" (``size`` its edges [mm]), "cylinder" (radius,
    length [mm], along local z), "sphere" (radius [mm]) or "mesh" (``vertices`` (m, 3) [mm] and
    ``faces`` (k, 3) in its local frame; ``missing``: where the file was named and as what, when
    it was not found, then no vertices); ``local`` (4, 4) [mm] its frame in the station frame ``frame`` (-1: the robot base,
    else the index of the transform it rides after); ``link`` the station's name of that link (the
    base's set-up transform, else the joint transform: "R", "A1", …) and ``urdf_link`` the URDF's."""

    urdf_link: str
    link: str
    frame: int
    kind: str
    size: tuple[float, ...]
    local: np.ndarray
    vertices: np.ndarray | None = None
    faces: np.ndarray | None = None
    missing: str | None = None


def urdf_link_geometry(path: Path) -> tuple[LinkGeometry, ...]:
    """Every ``<collision>`` of the links along the URDF's chain (the one the station imports)."""
    model = robot_from_urdf(path)
    root = urdf_root(path)
    base, joints = _urdf_chain(path, root, None, None)
    links = {str(el.get("name")): el for el in root.findall("link")}
    moving = [t for t, spec in enumerate(model.transforms) if spec.joint is not None]
    F = chain_frames(model, np.zeros((1, model.n_joints)), setup=False)[0]  # (nt, 4, 4) at the joints' zero
    names = [model.transforms[0].name] + [model.transforms[t].name for t in moving]
    out: list[LinkGeometry] = []
    link, world, k = base, np.eye(4), 0  # the URDF link, its frame at zero, the moving joints passed
    while True:
        frame = -1 if k == 0 else moving[k - 1]
        in_station = world if frame < 0 else invert(F[frame]) @ world  # the link's frame in the station's
        out += _collisions(path, links.get(link), link, names[k], frame, in_station)
        if link not in joints:
            break
        j = joints[link]
        world = world @ urdf_joint_origin(path, j)
        k += j.get("type") != "fixed"
        link = _urdf_link(path, j, "child")
    return tuple(out)


def _collisions(path: Path, el: ET.Element | None, urdf_link: str, link: str, frame: int,
                in_station: np.ndarray) -> list[LinkGeometry]:
    """The link's ``<collision>`` elements, each placed by ``in_station`` (the link's frame in the
    station frame it rides on) and its own ``<origin>``."""
    out = []
    for n, col in enumerate([] if el is None else el.findall("collision"), start=1):
        where = f"{path}: link {urdf_link!r}, <collision> {n}"
        geo = col.find("geometry")
        shapes = [] if geo is None else list(geo)
        if len(shapes) != 1:
            raise ConfigError(f"{where} needs one <geometry> with one of <box>, <cylinder>, <sphere>, <mesh> "
                              f"(URDF, link/collision); found {[s.tag for s in shapes] or 'none'}")
        origin = col.find("origin")
        xyz = _numbers(where, "origin xyz", "0 0 0" if origin is None else origin.get("xyz", "0 0 0"), 3)
        rpy = _numbers(where, "origin rpy", "0 0 0" if origin is None else origin.get("rpy", "0 0 0"), 3)
        local = in_station @ pose_to_matrix(np.array([v * MM_PER_M for v in xyz] + rpy))
        out.append(_geometry(path, where, shapes[0], urdf_link, link, frame, local))
    return out


def _geometry(path: Path, where: str, g: ET.Element, urdf_link: str, link: str, frame: int,
              local: np.ndarray) -> LinkGeometry:
    """One ``<geometry>`` child as a :class:`LinkGeometry` (lengths in mm)."""
    def attr(name: str, n: int) -> list[float]:
        text = g.get(name)
        if text is None:
            raise ConfigError(f"{where}: <{g.tag}> has no '{name}' attribute (URDF, link/collision/geometry)")
        vals = _numbers(where, f"{g.tag} {name}", text, n)
        if not all(v > 0 for v in vals):
            raise ConfigError(f"{where}: <{g.tag} {name}=\"{text}\"> must be > 0 [m]")
        return [v * MM_PER_M for v in vals]

    if g.tag == "box":
        return LinkGeometry(urdf_link, link, frame, "box", tuple(attr("size", 3)), local)
    if g.tag == "cylinder":
        return LinkGeometry(urdf_link, link, frame, "cylinder", (attr("radius", 1)[0], attr("length", 1)[0]), local)
    if g.tag == "sphere":
        return LinkGeometry(urdf_link, link, frame, "sphere", (attr("radius", 1)[0],), local)
    if g.tag != "mesh":
        raise ConfigError(f"{where}: <{g.tag}> is not a URDF geometry; use <box>, <cylinder>, <sphere> or <mesh>")
    ref = g.get("filename")
    if not ref:
        raise ConfigError(f"{where}: <mesh> has no 'filename' attribute (URDF, link/collision/geometry)")
    scale = _numbers(where, "mesh scale", g.get("scale", "1 1 1"), 3)
    file = resolve_mesh(path, ref)
    if file is None:
        return LinkGeometry(urdf_link, link, frame, "mesh", (), local, missing=f"{where}: <mesh filename=\"{ref}\">")
    vertices, faces = _read_mesh(where, file)
    return LinkGeometry(urdf_link, link, frame, "mesh", (), local, vertices * np.array(scale) * MM_PER_M, faces)


def resolve_mesh(urdf: Path, ref: str) -> Path | None:
    """The file a ``<mesh filename>`` names, or None where none exists: ``package://PKG/REL`` beside
    the URDF or in a folder above it (``A/PKG/REL``, or ``A/REL`` where ``A`` is named ``PKG``),
    ``file://ABS``, or a path relative to the URDF's folder."""
    here = urdf.resolve().parent
    if ref.startswith("package://"):
        pkg, _, rel = ref[len("package://"):].partition("/")
        candidates = [c for a in (here, *here.parents) for c in ((a / rel) if a.name == pkg else None, a / pkg / rel)
                      if c is not None]
    elif ref.startswith("file://"):
        candidates = [Path(ref[len("file://"):])]
    else:
        candidates = [here / ref]
    return next((c for c in candidates if c.is_file()), None)


def _read_mesh(where: str, file: Path) -> tuple[np.ndarray, np.ndarray]:
    """A mesh file's vertices (m, 3) [file units] and triangles (k, 3), through trimesh (a scene's
    meshes joined in the scene's frame)."""
    import trimesh

    try:
        mesh = trimesh.load(file, force="mesh")
    except Exception as exc:  # trimesh raises many types for files it cannot read
        raise ConfigError(f"{where}: mesh {file} cannot be read ({type(exc).__name__}: {exc}); give an STL, OBJ "
                          f"or DAE file trimesh reads") from None
    vertices = np.asarray(getattr(mesh, "vertices", np.zeros((0, 3))), dtype=float)
    faces = np.asarray(getattr(mesh, "faces", np.zeros((0, 3))), dtype=np.int32)
    if len(faces) == 0 or not np.all(np.isfinite(vertices)):
        raise ConfigError(f"{where}: mesh {file} holds no triangles (or coordinates that are not finite); give "
                          f"the link's collision mesh")
    return vertices, faces


def _numbers(where: str, what: str, text: str, n: int) -> list[float]:
    try:
        vals = [float(v) for v in text.split()]
    except ValueError:
        vals = []
    if len(vals) != n or not all(math.isfinite(v) for v in vals):
        raise ConfigError(f"{where}: <{what}> must be {n} finite numbers, got {text!r}")
    return vals
