"""A hand from a URDF, parsed with yourdfpy (a maintained URDF library).

Joints: revolute, continuous, prismatic, fixed (floating and planar refused, naming the
joint); ``mimic`` elements become couplings. Collision geometry: box, cylinder, sphere,
mesh (capsule, a common extension, too). Mesh paths resolve relative to the URDF file;
``package://NAME/rest`` (and xacro's ``$(find NAME)/rest``) resolves to ``rest`` under the
nearest ancestor folder called NAME, or under a folder NAME beside an ancestor, or else
under the URDF's folder or one of its three parents (the layouts of a ROS package and of a
copied description). Only collision meshes are read: a missing one, or a Git LFS pointer in
its place, is an error naming it.
"""

from __future__ import annotations

import io
import re
from pathlib import Path

import numpy as np
import trimesh

from ...errors import HandDescriptionError
from .description import RawHand, RawJoint, RawLink
from .file_search import find_in_tree
from .geometry import LinkGeometry
from .model import Coupling

__all__ = ["read_collision_mesh", "read_urdf", "resolve_mesh_path"]

#: ``$(find NAME)/rest`` (also after ``file://``), as xacro writes a package's folder (left
#: in some published URDFs: LEAP's leap_description).
_FIND = re.compile(r"^(?:file://)?\$\(find ([^)\s]+)\)/(.*)$")
#: The first bytes of a Git LFS pointer file (a clone made without git-lfs holds these).
_LFS_POINTER = b"version https://git-lfs"


def resolve_mesh_path(uri: str, base_dir: Path) -> Path:
    """The file a URDF mesh ``filename`` names (may not exist)."""
    find = _FIND.match(uri)
    if find:  # a xacro / roslaunch substitution left in the file: the package's folder
        uri = f"package://{find.group(1)}/{find.group(2)}"
    if uri.startswith("file://"):
        return Path(uri[len("file://"):])
    if uri.startswith("package://"):
        package, _, rest = uri[len("package://"):].partition("/")
        for folder in (base_dir, *base_dir.parents):
            if folder.name == package and (folder / rest).exists():
                return folder / rest
        for folder in (base_dir, *base_dir.parents):
            if (folder / package / rest).exists():
                return folder / package / rest
        # A description copied out of its package: urdf/ and meshes/ side by side.
        for folder in (base_dir, *list(base_dir.parents)[:3]):
            if (folder / rest).exists():
                return folder / rest
        return base_dir / rest
    path = Path(uri)
    return path if path.is_absolute() else base_dir / path


def read_collision_mesh(path: Path, where: str, max_bytes: int, base_dir: Path | None = None,
                        uri: str | None = None) -> trimesh.Trimesh:
    """A URDF collision mesh file in metres, the URDF's own ``scale`` not applied (the
    simulation reads the meshes MuJoCo cannot decode with it too). A file that is not there
    is an error naming the file's ``uri`` as the URDF writes it (where a ``package://``
    address was looked for); with ``base_dir`` (the description's folder) it names a file
    of the same name beside the description, a folder up, or in their ``meshes/`` folders
    (an exporter that wrote ``filename="/base_link.STL"``, a URDF copied out of its
    package), else anywhere in the tree of the folder above (an Inspire URDF naming
    ``right_base_link.obj`` beside it, the file in ``../collision/``): told, not taken, as
    RViz would not take it."""
    if not path.is_file():
        near = []
        if base_dir is not None:
            folders = (base_dir, base_dir / "meshes", base_dir.parent, base_dir.parent / "meshes")
            near = [folder / path.name for folder in folders if (folder / path.name).is_file()]
            if not near:  # elsewhere in the tree of the description's folder's parent (a collision/ beside urdf/)
                found = find_in_tree(base_dir.parent, (path.name,))
                near = [found] if found is not None else []
        hint = f" (a file of that name is at {near[0]}: is the URDF's path wrong?)" if near else ""
        named = ""
        if uri is not None and uri.startswith("package://") and base_dir is not None:
            package, _, rest = uri[len("package://"):].partition("/")
            named = (f" (the URDF names {uri}: no folder {package!r} at or above {base_dir} holds {rest}, nor does "
                     "the description's folder or the three above it; keep the description inside its package)")
        elif uri is not None and uri != str(path):
            named = f" (the URDF names {uri})"
        raise HandDescriptionError(f"{where}: collision mesh file {path} not found{named}{hint}", field=where)
    if path.stat().st_size > max_bytes:
        raise HandDescriptionError(f"{where}: collision mesh {path.name} is over the size limit "
                                   f"({path.stat().st_size} > {max_bytes} bytes)", field=where)
    with path.open("rb") as f:
        if f.read(len(_LFS_POINTER)) == _LFS_POINTER:  # a clone made without git-lfs
            raise HandDescriptionError(f"{where}: collision mesh {path.name} is a Git LFS pointer, not the mesh "
                                       "(fetch the file: git lfs pull)", field=where)
    try:
        mesh = trimesh.load(str(path), force="mesh", process=True)
    except Exception as exc:  # trimesh raises many types for a bad file
        raise HandDescriptionError(f"{where}: collision mesh {path.name} cannot be read ({type(exc).__name__})",
                                   field=where) from None
    if not isinstance(mesh, trimesh.Trimesh) or len(mesh.faces) == 0:
        raise HandDescriptionError(f"{where}: collision mesh {path.name} has no triangles", field=where)
    if mesh.units not in (None, "meters", "m"):
        # A COLLADA file's <unit meter="0.001"/> (RViz applies it too); STL and OBJ carry none.
        try:
            mesh.convert_units("meters", guess=False)
        except Exception:  # trimesh raises ValueError / KeyError for a unit it cannot read
            raise HandDescriptionError(f"{where}: collision mesh {path.name} is in units {mesh.units!r}, which "
                                       "cannot be converted to metres", field=where) from None
    return mesh


def _geometry(collision, where: str, base_dir: Path, max_bytes: int) -> LinkGeometry | None:
    geom = collision.geometry
    origin = np.eye(4) if collision.origin is None else np.asarray(collision.origin, float)
    if geom.box is not None:
        return LinkGeometry("box", tuple(np.asarray(geom.box.size, float) / 2.0), origin, None, where)
    if geom.cylinder is not None:
        return LinkGeometry("cylinder", (geom.cylinder.radius, geom.cylinder.length / 2.0), origin, None, where)
    if geom.sphere is not None:
        return LinkGeometry("sphere", (geom.sphere.radius,), origin, None, where)
    capsule = getattr(geom, "capsule", None)
    if capsule is not None:
        return LinkGeometry("capsule", (capsule.radius, capsule.length / 2.0), origin, None, where)
    if geom.mesh is not None:
        path = resolve_mesh_path(geom.mesh.filename, base_dir)
        mesh = read_collision_mesh(path, where, max_bytes, base_dir, geom.mesh.filename).copy()
        scale = geom.mesh.scale
        if scale is not None:
            mesh.apply_scale(np.broadcast_to(np.asarray(scale, float), (3,)))
        return LinkGeometry("mesh", (), origin, mesh, f"{where} ({path.name})")
    return None


#: What to do with a hand described in xacro (the macros most ROS hand packages ship).
XACRO_HINT = ("expand it first (ROS's xacro: `xacro FILE.urdf.xacro > hand.urdf`; a file of macros only "
              "needs a top-level file that calls them) and give the URDF")


def _refuse_gazebo_loops(text: str, links: set[str], label: str) -> None:
    """Refuse a URDF that closes kinematic loops with joints only Gazebo reads
    (``<gazebo><joint>`` between two of its links: a linkage exported so, as Inspire's
    tactile hand is, whose URDF tree alone leaves 30 joints moving freely; Inspire's hands
    have 6 actuators). The tree without its loops moves links the hand cannot move; planned
    with it, none of 30 grasps held."""
    from lxml import etree  # yourdfpy's parser

    parser = etree.XMLParser(resolve_entities=False, no_network=True)  # a file from outside
    try:
        root = etree.fromstring(text.encode("utf-8"), parser)
    except etree.XMLSyntaxError:
        return  # yourdfpy has read it; nothing more to learn here
    loops = []
    for joint in root.iterfind("gazebo/joint"):
        parent, child = joint.findtext("parent", "").strip(), joint.findtext("child", "").strip()
        if parent in links and child in links:
            loops.append(f"{joint.get('name', '?')} ({parent} - {child})")
    if loops:
        more = f" and {len(loops) - 2} more" if len(loops) > 2 else ""
        raise HandDescriptionError(
            f"hand_description: {label} closes kinematic loops with joints only Gazebo reads (<gazebo><joint>: "
            f"{', '.join(loops[:2])}{more}): a URDF tree cannot express them and without them its linkage joints "
            "move freely; give a description whose passive joints follow their actuators as <mimic> joints "
            "(an MJCF's joint equalities also do)", field="hand_description")


def read_urdf(text: str, base_dir: Path, max_mesh_bytes: int, label: str = "URDF") -> RawHand:
    """The RawHand of a URDF document (``base_dir``: where relative mesh paths start)."""
    import yourdfpy  # a pinned dependency; imported here to keep package import light

    # Unexpanded macros: a URDF reader would take what it can and miss the rest. (Comments
    # left out: xacro's own output may quote a macro call in one, as the Robotiq's does.)
    if "<xacro:" in re.sub(r"<!--.*?-->", "", text, flags=re.S):
        raise HandDescriptionError(f"hand_description: {label} holds xacro elements (<xacro:...>), not a plain "
                                   f"URDF: {XACRO_HINT}", field="hand_description")

    try:
        # Bytes: lxml refuses a str that carries an encoding declaration (<?xml ... encoding=?>).
        robot = yourdfpy.URDF.load(io.BytesIO(text.encode("utf-8")), build_scene_graph=False,
                                   build_collision_scene_graph=False, load_meshes=False,
                                   load_collision_meshes=False)
    except Exception as exc:  # lxml / yourdfpy errors: the message may quote the file
        raise HandDescriptionError(f"hand_description: {label} is not a valid URDF ({type(exc).__name__})",
                                   field="hand_description") from None
    desc = robot.robot
    joints_by_child = {}
    for joint in desc.joints:
        if joint.child in joints_by_child:
            raise HandDescriptionError(f"link {joint.child!r}: child of two joints", field=joint.child)
        joints_by_child[joint.child] = joint
    link_names = [link.name for link in desc.links]
    for joint in desc.joints:
        for end in (joint.parent, joint.child):
            if end not in link_names:
                raise HandDescriptionError(f"joint {joint.name!r}: link {end!r} is not defined", field=joint.name)
    _refuse_gazebo_loops(text, set(link_names), label)
    tops = [name for name in link_names if name not in joints_by_child]
    if len(tops) != 1:
        raise HandDescriptionError(f"hand_description: a URDF needs one root link, found {len(tops)} "
                                   f"({', '.join(tops[:4])})", field="hand_description")
    children: dict[str, list] = {}
    for joint in desc.joints:
        children.setdefault(joint.parent, []).append(joint)
    by_name = {link.name: link for link in desc.links}
    raw = RawHand(name=desc.name or "hand", links=[])
    order = [(tops[0], None)]
    seen = set()
    while order:
        name, joint = order.pop()
        if name in seen:
            raise HandDescriptionError(f"link {name!r}: the joints form a loop", field=name)
        seen.add(name)
        link = by_name[name]
        geoms = []
        for k, collision in enumerate(link.collisions):
            where = f"link {name} collision {collision.name or k}"
            g = _geometry(collision, where, base_dir, max_mesh_bytes)
            if g is None:
                raise HandDescriptionError(f"{where}: geometry kind not supported", field=name)
            geoms.append(g)
        origin = np.eye(4) if joint is None or joint.origin is None else np.asarray(joint.origin, float)
        moving = []
        if joint is not None and joint.type != "fixed":
            if joint.type not in ("revolute", "continuous", "prismatic"):
                raise HandDescriptionError(f"joint {joint.name!r}: type {joint.type} is not supported "
                                           "(revolute, continuous, prismatic, fixed)", field=joint.name)
            axis = np.array([1.0, 0.0, 0.0]) if joint.axis is None else np.asarray(joint.axis, float)
            lim = joint.limit
            lower = None if lim is None or lim.lower is None else float(lim.lower)
            upper = None if lim is None or lim.upper is None else float(lim.upper)
            if joint.type == "continuous":
                lower = upper = None
            moving.append(RawJoint(joint.name, joint.type, axis, lower=lower, upper=upper,
                                   source=f"{joint.type} joint without <limit>"))
            if joint.mimic is not None:
                raw.couplings.append(Coupling(joint.name, joint.mimic.joint,
                                              float(1.0 if joint.mimic.multiplier is None else joint.mimic.multiplier),
                                              float(0.0 if joint.mimic.offset is None else joint.mimic.offset),
                                              f"joint {joint.name} mimic", own_effort=True))
        raw.links.append(RawLink(name, None if joint is None else joint.parent, origin, moving, geoms))
        for child_joint in reversed(children.get(name, [])):  # depth first, file order
            order.append((child_joint.child, child_joint))
    if len(seen) != len(link_names):
        raise HandDescriptionError("hand_description: some links are not connected to the root link",
                                   field="hand_description")
    raw.notes.extend(_inertia_notes(desc.links))
    return raw


def _inertia_notes(links) -> list[str]:
    """A note per link whose ``<inertia>`` is no physical inertia (:func:`unphysical_inertia`):
    MuJoCo refuses to compile such a link, so the simulation keeps its moments and drops its
    products of inertia (:mod:`grasp_apso.simulation.any_hand_model`). Wonik's Allegro Hand
    V5 URDF gives six finger links an ``ixy`` about 1000 times too large (eigenvalues down
    to -0.0057 kg m^2). The planner itself reads no inertia."""
    notes = []
    for link in links:
        inertial = link.inertial
        if inertial is None or inertial.inertia is None:
            continue
        matrix = np.asarray(inertial.inertia, float)
        if matrix.shape != (3, 3):
            continue
        if unphysical_inertia(matrix):
            eig = np.linalg.eigvalsh(0.5 * (matrix + matrix.T)) if np.all(np.isfinite(matrix)) else None
            told = "not finite" if eig is None else f"eigenvalues {', '.join(f'{e:.3g}' for e in eig)} kg m^2"
            notes.append(f"link {link.name}: its <inertia> is no physical inertia ({told}); MuJoCo refuses "
                         "such a link, so the simulation keeps its moments and drops its products of inertia "
                         "(check the file's off-diagonal terms)")
    return notes


def unphysical_inertia(matrix: np.ndarray) -> bool:
    """Whether a link's inertia (3, 3) kg m^2 is no physical inertia: not finite, or a
    principal moment negative beyond rounding (zeros, a frame link's, are floored by the
    simulation as they are)."""
    matrix = np.asarray(matrix, float)
    if not np.all(np.isfinite(matrix)):
        return True
    eig = np.linalg.eigvalsh(0.5 * (matrix + matrix.T))
    return bool(eig[0] < -1e-6 * abs(eig[-1]))
