"""An MJCF model loaded once, with every quantity an expression may read named.

Names (identifiers; characters a name cannot hold become ``_``; unnamed elements
are called ``<kind><index>``, e.g. ``actuator0``):

* ``qpos_<joint>`` and ``qvel_<joint>`` for hinge and slide joints; free joints
  by component, ``qpos_<j>_x/_y/_z/_qw/_qx/_qy/_qz`` and
  ``qvel_<j>_x/_y/_z/_wx/_wy/_wz``; ball joints ``qpos_<j>_qw..._qz`` and
  ``qvel_<j>_wx/_wy/_wz``;
* ``body_<b>_x/_y/_z`` (world position) and ``body_<b>_qw/_qx/_qy/_qz`` (world orientation);
  ``body_<b>_xx ... _zz``: its rotation matrix (MuJoCo's ``xmat``, row then column: ``_xz`` is
  the world x of the body's z axis), as dm_control's ``named.data.xmat[b, 'xz']`` reads it;
  ``body_<b>_com_x/_y/_z``: its centre of mass (MuJoCo's ``xipos``), where hopper's reward reads heights;
* ``mocap_<b>_x/_y/_z`` and ``mocap_<b>_qw/_qx/_qy/_qz`` for a mocap body (``<body mocap="true">``): MuJoCo's
  ``mocap_pos`` and ``mocap_quat``, which the spec sets (:data:`SETTABLE`) to move a body that has no joint;
* ``site_<s>_x/_y/_z``; ``sensor_<s>`` (or ``sensor_<s>_<i>`` for a sensor of several values);
* ``ctrl_<actuator>``; ``act_<actuator>`` (``act_<a>_<i>`` for several), MuJoCo's ``act``, the state of an actuator
  with dynamics (a filter's, a muscle's), which dm_control's quadruped observes; ``sim_time``;
* ``geom_<g>_x/_y/_z`` (world position), ``joint_<j>_x/_y/_z`` (a joint's anchor), ``ncon`` (the contact count) and the model's own fields,
  ``model_<field>_<element>[_<column>]``, some of which a reset writes (:mod:`visualenv.physics.model_fields`).

Two elements that come to one name (joints ``left-leg`` and ``left_leg``, a free
joint ``a``'s ``qpos_a_x`` and a hinge ``a_x``; geoms, cameras and lights, which
are also the drawn scene's objects; keyframes) are an error that names both.

Each name maps to (array, flat index) once, here; a reader gathers many names
with one numpy indexing per array (:mod:`visualenv.physics.simulation`).
"""

from __future__ import annotations

import importlib
import re
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from visualenv.compat.mujoco import ctrl_limited, spec_deletes
from visualenv.errors import VisualEnvError
from visualenv.files import MAX_IMAGE_PIXELS, MAX_MODEL_MEMORY_MIB, PACKAGE_PREFIX, FileSizeError, package_file
from visualenv.physics.model_fields import MODEL_FIELDS, model_values
from visualenv.physics.model_size import check_model_size

INSTALL_HINT = "MuJoCo is not installed: physics specs need it: pip install 'visualenv[mujoco]' (or pip install mujoco)"
#: arrays a name can point into (attributes of MjData; ``time`` and ``ncon`` are scalars; ``model.<field>``: MjModel's)
ARRAYS = (
    "qpos",
    "qvel",
    "xpos",
    "xquat",
    "xmat",
    "xipos",
    "xanchor",
    "site_xpos",
    "geom_xpos",
    "sensordata",
    "ctrl",
    "act",
    "time",
    "ncon",
    "mocap_pos",
    "mocap_quat",
    *(f"model.{field}" for field in MODEL_FIELDS),
)
#: the arrays a spec writes: joint values at reset, mocap poses at reset and in ``dynamics.update``
SETTABLE = ("qpos", "qvel", "mocap_pos", "mocap_quat")
#: the arrays of a mocap body's pose, which ``dynamics.update`` also writes (before each MuJoCo step)
MOCAP = ("mocap_pos", "mocap_quat")
_FREE_QPOS = ("x", "y", "z", "qw", "qx", "qy", "qz")
_FREE_QVEL = ("x", "y", "z", "wx", "wy", "wz")
_BALL_QPOS = ("qw", "qx", "qy", "qz")
_BALL_QVEL = ("wx", "wy", "wz")
#: a body's rotation matrix entries, in MuJoCo's xmat order (row: world axis, column: body axis)
_XMAT = ("xx", "xy", "xz", "yx", "yy", "yz", "zx", "zy", "zz")


class PhysicsError(VisualEnvError):
    """A model that cannot be found, loaded or used (the message says which and why)."""


def mujoco_module() -> Any:
    """The mujoco package, imported on first use; a clear error saying how to install it when it is missing.

    MuJoCo's own warnings (a deprecated attribute, an unstable step) become Python
    warnings, instead of lines printed and appended to MUJOCO_LOG.TXT in the current
    folder; the env reports an unstable step itself, as a located fault.
    """
    try:
        mujoco = importlib.import_module("mujoco")
    except ImportError:
        raise PhysicsError(INSTALL_HINT) from None
    if mujoco.get_mju_user_warning() is None:
        mujoco.set_mju_user_warning(_warn)
    return mujoco


def _warn(message: str) -> None:
    warnings.warn(f"MuJoCo: {message}", RuntimeWarning, stacklevel=2)


def resolve_model_path(text: str, base_dir: Path) -> Path:
    """The MJCF file a spec names: relative to the spec, absolute, or ``package:pkg.name/path/in/it.xml``.

    The package form reads a file that an installed package ships, found in the
    package's folders on disk without importing it (:func:`visualenv.files.package_file`).
    """
    if text.startswith(PACKAGE_PREFIX):
        try:
            return package_file(text)
        except VisualEnvError as exc:
            raise PhysicsError(str(exc)) from None
    path = Path(text).expanduser()
    return path if path.is_absolute() else base_dir / path


def identifier(text: str) -> str:
    """A MuJoCo name as an expression identifier: other characters become '_', a leading digit gets '_'."""
    out = re.sub(r"\W", "_", text, flags=re.ASCII)
    return "_" + out if out[:1].isdigit() else out


@dataclass(frozen=True)
class NameTables:
    """Every readable name -> (array, flat index), plus the element names by kind (MuJoCo's spelling -> id)."""

    values: dict[str, tuple[str, int]]
    joints: dict[str, int]
    bodies: dict[str, int]
    geoms: dict[str, int]
    sites: dict[str, int]
    actuators: dict[str, int]
    keyframes: dict[str, int]
    #: an element's name as written in expressions (identifier form), by kind and id
    ident: dict[str, list[str]] = field(default_factory=dict)


@dataclass
class PhysicsModel:
    """An MJCF file compiled by MuJoCo, its names tabled once."""

    path: Path
    model: Any  # mujoco.MjModel
    names: NameTables
    #: the model without its textures, which each env's MjModel copies (:func:`without_textures`)
    dynamics: Any

    @property
    def timestep(self) -> float:
        return float(self.model.opt.timestep)

    def actuator_names(self) -> list[str]:
        """Each actuator's identifier, in actuator order (one Box dimension each by default)."""
        return list(self.names.ident["actuator"])

    def ctrl_range(self, actuator: int) -> tuple[float, float]:
        """An actuator's ctrlrange where it is limited (as Gymnasium's action space), else unbounded."""
        m = self.model
        limited = ctrl_limited(m, actuator)
        lo, hi = (float(v) for v in m.actuator_ctrlrange[actuator])
        return (lo, hi) if limited and lo < hi else (float("-inf"), float("inf"))

    def qpos_names(self) -> list[str]:
        """Every qpos name in qpos order."""
        return sorted(
            (n for n, (a, _) in self.names.values.items() if a == "qpos"), key=lambda n: self.names.values[n][1]
        )

    def qvel_names(self) -> list[str]:
        """Every qvel name in qvel order."""
        return sorted(
            (n for n, (a, _) in self.names.values.items() if a == "qvel"), key=lambda n: self.names.values[n][1]
        )

    def mocap_names(self) -> list[str]:
        """Every mocap body's pose names (``mocap_<b>_x ... _qz``), in body order: what ``dynamics.update`` may set."""
        return [n for n, (a, _) in self.names.values.items() if a in MOCAP]

    def listing(self) -> dict[str, list[str]]:
        """The names by kind, for ``visualenv inspect`` and the starter spec."""
        groups: dict[str, list[str]] = {"joint positions": self.qpos_names(), "joint velocities": self.qvel_names()}
        for title, array in (
            ("bodies", "xpos"),
            ("body orientations", "xquat"),
            ("body rotation matrices", "xmat"),
            ("body centres of mass", "xipos"),
            ("sites", "site_xpos"),
            ("joint anchors", "xanchor"),
            ("sensors", "sensordata"),
            ("actuator controls", "ctrl"),
            ("actuator activations", "act"),
        ):
            groups[title] = [n for n, (a, _) in self.names.values.items() if a == array]
        groups["mocap bodies (set in physics.reset.values and dynamics.update)"] = self.mocap_names()
        groups["geom positions"] = [n for n, (a, _) in self.names.values.items() if a == "geom_xpos"]
        groups["model fields (positions, sizes and damping written at reset)"] = [
            n for n, (a, _) in self.names.values.items() if a.startswith("model.")
        ]
        groups["contacts"] = ["ncon"]
        groups["geoms (for contacts)"] = list(self.names.ident["geom"])
        groups["keyframes"] = list(self.names.ident["key"])
        groups["time"] = ["sim_time"]
        return {k: v for k, v in groups.items() if v}


def load_model(
    path: Path, max_memory_mib: int = MAX_MODEL_MEMORY_MIB, max_image_pixels: int = MAX_IMAGE_PIXELS
) -> PhysicsModel:
    """Compile the MJCF at `path` (MuJoCo resolves its includes, meshes and textures); PhysicsError says what is wrong, with MuJoCo's line.

    What compiling it takes is estimated first (:func:`~visualenv.physics.model_size.check_model_size`): a model asking
    for more than `max_memory_mib`, or the machine's available memory, or an image over `max_image_pixels`, is refused
    before MuJoCo allocates it.
    """
    mujoco = mujoco_module()
    if not path.is_file():
        raise PhysicsError(f"no MJCF file {path}")
    try:
        check_model_size(path, max_memory_mib, max_image_pixels)
    except FileSizeError as exc:
        raise PhysicsError(str(exc)) from None
    try:
        model = mujoco.MjModel.from_xml_path(str(path))
    except (ValueError, mujoco.FatalError) as exc:  # FatalError: an allocation the estimate did not foresee
        message = " ".join(str(exc).split())
        raise PhysicsError(f"MuJoCo cannot load {path}: {message}") from None
    return PhysicsModel(path, model, name_tables(model), without_textures(path, model))


def without_textures(path: Path, model: Any) -> Any:
    """`model` compiled again from `path` without its textures: what each env's MjModel copies
    (:class:`~visualenv.physics.simulation.Simulation`).

    Textures only draw, and the renderer reads them from the model once. Kept, every env would hold its own copy of
    them: gigabytes in a batch of DMC envs (results/benchmarks/model-without-textures.md). MuJoCo's MjSpec deletes
    them and compiles the rest: every other array is the same (``tests/physics/test_spec_section.py``). Where this MuJoCo's
    MjSpec cannot (no ``delete``: :func:`~visualenv.compat.mujoco.spec_deletes`), or MuJoCo refuses to compile the
    spec (a ValueError, as MuJoCo's Python calls raise its errors), the model as it is.
    """
    if not model.ntex:
        return model
    mujoco = mujoco_module()
    if not spec_deletes(mujoco):
        return model
    try:
        with warnings.catch_warnings():  # the model's compile has said them (a deprecated attribute, ...)
            warnings.simplefilter("ignore")
            spec = mujoco.MjSpec.from_file(str(path))
            for texture in list(spec.textures):
                spec.delete(texture)
            for material in spec.materials:
                material.textures = [""] * len(material.textures)
            return spec.compile()
    except (ValueError, mujoco.FatalError):
        return model


#: element kinds whose names a spec uses as they are (contacts' geoms, reset.keyframe, cameras) and, for
#: geoms, cameras and lights, as the names of the drawn scene's objects: each group's names must differ
_NAMED_AS_THEY_ARE = (("geom", "camera", "light"), ("key",))
_KIND_WORDS = {"key": "keyframe"}


def _element_names(model: Any, kind: str, count: int) -> tuple[list[str], dict[str, int], list[str]]:
    """Each element's identifier, MuJoCo's name -> id, and each element as an error names it (``joint 'left-leg'``)."""
    mujoco = mujoco_module()
    obj = getattr(mujoco.mjtObj, "mjOBJ_" + kind.upper())
    idents: list[str] = []
    by_name: dict[str, int] = {}
    owners: list[str] = []
    word = _KIND_WORDS.get(kind, kind)
    for i in range(count):
        raw = mujoco.mj_id2name(model, obj, i) or ""
        if raw:
            by_name[raw] = i
        idents.append(identifier(raw) if raw else f"{kind}{i}")
        owners.append(f"{word} '{raw}'" if raw else f"the unnamed {word} {i}")
    return idents, by_name, owners


class _Names:
    """The names being made, each with the element it reads; a name a second element makes is a clash, kept to report."""

    def __init__(self) -> None:
        self.values: dict[str, tuple[str, int]] = {}
        self.owner: dict[str, str] = {}
        self.clashes: dict[tuple[str, str], str] = {}  # (first element, second element) -> the first name they share

    def add(self, name: str, target: tuple[str, int], owner: str) -> None:
        first = self.owner.setdefault(name, owner)
        if first == owner:
            self.values[name] = target
        else:
            self.clashes.setdefault((first, owner), name)


def name_tables(model: Any) -> NameTables:
    """Every readable name of `model`, computed once; PhysicsError naming both when two elements make one name."""
    kinds = {
        "joint": model.njnt,
        "body": model.nbody,
        "geom": model.ngeom,
        "site": model.nsite,
        "sensor": model.nsensor,
        "actuator": model.nu,
        "key": model.nkey,
        "camera": model.ncam,
        "light": model.nlight,
    }
    ident: dict[str, list[str]] = {}
    by_name: dict[str, dict[str, int]] = {}
    owners: dict[str, list[str]] = {}
    for kind, count in kinds.items():
        ident[kind], by_name[kind], owners[kind] = _element_names(model, kind, count)
    names = _Names()
    _joint_values(model, names, ident["joint"], owners["joint"])
    _body_values(names, ident["body"], owners["body"])
    for b, name in enumerate(ident["body"]):
        _mocap_values(names, name, int(model.body_mocapid[b]), owners["body"][b])
    for s, name in enumerate(ident["site"]):
        for i, p in enumerate("xyz"):
            names.add(f"site_{name}_{p}", ("site_xpos", 3 * s + i), owners["site"][s])
    for s, name in enumerate(ident["sensor"]):
        adr, dim = int(model.sensor_adr[s]), int(model.sensor_dim[s])
        for i in range(dim):
            names.add(
                f"sensor_{name}" if dim == 1 else f"sensor_{name}_{i}", ("sensordata", adr + i), owners["sensor"][s]
            )
    for a, name in enumerate(ident["actuator"]):
        names.add(f"ctrl_{name}", ("ctrl", a), owners["actuator"][a])
        adr, count = int(model.actuator_actadr[a]), int(model.actuator_actnum[a])
        for i in range(count if adr >= 0 else 0):
            names.add(f"act_{name}" if count == 1 else f"act_{name}_{i}", ("act", adr + i), owners["actuator"][a])
    names.add("sim_time", ("time", 0), "the simulation time")
    qvel = {n: i for n, (a, i) in names.values.items() if a == "qvel"}
    for name, target, owner in model_values(model, ident, owners, qvel):
        names.add(name, target, owner)
    for group in _NAMED_AS_THEY_ARE:
        seen = _Names()
        for kind in group:
            for i, name in enumerate(ident[kind]):
                seen.add(name, (kind, i), owners[kind][i])
        names.clashes.update(seen.clashes)
    if names.clashes:
        pairs = "; ".join(f"{first} and {second} are both '{name}'" for (first, second), name in names.clashes.items())
        raise PhysicsError(
            f"two elements of the model have one name in visualenv: {pairs}. Rename one of each in the MJCF "
            "(a name keeps its letters, digits and '_'; any other character becomes '_')"
        )
    return NameTables(
        names.values,
        by_name["joint"],
        by_name["body"],
        by_name["geom"],
        by_name["site"],
        by_name["actuator"],
        by_name["key"],
        ident,
    )


def _mocap_values(names: _Names, body: str, mocap: int, owner: str) -> None:
    """A mocap body's ``mocap_<b>_x/_y/_z`` and ``mocap_<b>_qw/_qx/_qy/_qz`` (the pose the spec sets); none for other bodies."""
    if mocap < 0:
        return
    for i, p in enumerate("xyz"):
        names.add(f"mocap_{body}_{p}", ("mocap_pos", 3 * mocap + i), owner)
    for i, p in enumerate(("qw", "qx", "qy", "qz")):
        names.add(f"mocap_{body}_{p}", ("mocap_quat", 4 * mocap + i), owner)


def _joint_values(model: Any, names: _Names, idents: list[str], owners: list[str]) -> None:
    """``qpos_<j>``/``qvel_<j>`` of hinge and slide joints; free and ball joints by component."""
    mujoco = mujoco_module()
    free, ball = int(mujoco.mjtJoint.mjJNT_FREE), int(mujoco.mjtJoint.mjJNT_BALL)
    for j, name in enumerate(idents):
        qadr, vadr, jtype = int(model.jnt_qposadr[j]), int(model.jnt_dofadr[j]), int(model.jnt_type[j])
        if jtype not in (free, ball):
            names.add(f"qpos_{name}", ("qpos", qadr), owners[j])
            names.add(f"qvel_{name}", ("qvel", vadr), owners[j])
            continue
        qparts, vparts = (_FREE_QPOS, _FREE_QVEL) if jtype == free else (_BALL_QPOS, _BALL_QVEL)
        for i, p in enumerate(qparts):
            names.add(f"qpos_{name}_{p}", ("qpos", qadr + i), owners[j])
        for i, p in enumerate(vparts):
            names.add(f"qvel_{name}_{p}", ("qvel", vadr + i), owners[j])


def _body_values(names: _Names, idents: list[str], owners: list[str]) -> None:
    """``body_<b>_x/_y/_z`` (xpos), ``_qw..._qz`` (xquat), ``_xx..._zz`` (xmat) and ``_com_x/_y/_z`` (xipos) of every
    body but the world."""
    for b, name in enumerate(idents):
        if b == 0:
            continue  # the world body never moves
        for i, p in enumerate("xyz"):
            names.add(f"body_{name}_{p}", ("xpos", 3 * b + i), owners[b])
        for i, p in enumerate(("qw", "qx", "qy", "qz")):
            names.add(f"body_{name}_{p}", ("xquat", 4 * b + i), owners[b])
        for i, p in enumerate(_XMAT):
            names.add(f"body_{name}_{p}", ("xmat", 9 * b + i), owners[b])
        for i, p in enumerate("xyz"):
            names.add(f"body_{name}_com_{p}", ("xipos", 3 * b + i), owners[b])
