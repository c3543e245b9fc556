"""The compiler's part that turns a spec's ``actors`` into the ``bind(state, steps)`` function and its targets.

Mixed into the spec compiler (:func:`visualenv.compiler.program.compile_spec`), whose names in scope, errors and
expression checks it uses: ``spec``, ``pnames``, ``used``, ``error``, ``expr``, ``physics_objects``, ``physics_reads``.
"""

from __future__ import annotations

import ast
from typing import Any

from visualenv.expr import BOOL, NUM, Type, vec
from visualenv.expr.codegen import FunctionBuilder, Site, const, local, lower, name, tuple_of
from visualenv.render.base import BindingTarget
from visualenv.compiler import physics as phys
from visualenv.errors import did_you_mean
from visualenv.bindables import BINDABLES, WORLD_ACTOR, WORLD_PROPERTIES, camera_problem, type_problem
from visualenv.spec.models import CameraObject, EmptyObject, LightObject, MeshObject, PrimitiveObject

#: the expression type of each kind of binding value (BINDABLES' ``value``); a colour's size (3 or 4) is checked apart
VALUE_TYPES: dict[str, Type] = {"vector": vec(3), "scale": vec(3), "color": vec(0), "number": NUM, "condition": BOOL}
#: the Blender object type each kind of declared object becomes
OBJECT_TYPES = (
    (PrimitiveObject, "MESH"),
    (MeshObject, "MESH"),
    (LightObject, "LIGHT"),
    (CameraObject, "CAMERA"),
    (EmptyObject, "EMPTY"),
)


def object_type(obj: Any) -> str:
    """The Blender object type (MESH, LIGHT, CAMERA, EMPTY) a declared scene object becomes."""
    return next(t for cls, t in OBJECT_TYPES if isinstance(obj, cls))


class BindingsCompiler:
    """Checks each actor binding (its object, property, value's type and size) and generates the values a renderer
    sets before each render, flattened in order, with their targets."""

    spec: Any
    pnames: dict[str, Type]
    used: set[str]
    error: Any
    expr: Any
    plan: Any
    physics_objects: Any
    physics_reads: Any

    def build_bindings(self, state_names: list[str]) -> tuple[FunctionBuilder, list[BindingTarget]]:
        """bind(state, steps): the value of every actor property, flattened in order."""
        fb = FunctionBuilder("bind", ["_state", "_steps"])
        fb.unpack([local(n) for n in state_names], "_state")
        fb.assign(local("steps"), name("_steps"))
        # a physics spec's names too: a camera can follow a body
        scope: dict[str, Type] = {
            **self.pnames,
            **{n: NUM for n in state_names},
        }
        scope["steps"] = NUM
        targets: list[BindingTarget] = []
        values: list[ast.expr] = []
        start, before = len(fb.body), set(self.used)
        self.used = set()
        for obj_name, actor in self.spec.actors.items():
            if self.bound_object_known(obj_name):
                for prop in type(actor).model_fields:
                    raw = getattr(actor, prop)
                    if raw is not None:
                        self.bind_property(fb, ("actors", obj_name, prop), raw, scope, targets, values)
        self.bind_written_fields(fb, targets, values)
        self.physics_reads(fb, "bind", start, self.used, set(state_names))
        self.used |= before
        fb.returns(tuple_of(values))
        self.check_cameras()
        return fb, targets

    def bind_written_fields(self, fb: FunctionBuilder, targets: list[BindingTarget], values: list[ast.expr]) -> None:
        """The model fields a reset writes of drawn geoms and sites, drawn: their objects' scale (a size written) and a
        site's location (its position written), bound as an actor's are (:func:`~visualenv.physics.geom_poses.drawn_writes`)."""
        plan = self.plan
        if plan is None or plan.scene is None:
            return
        from visualenv.physics.geom_poses import drawn_writes

        written = plan.written()
        for write in drawn_writes(plan.scene, plan.model, written, set(self.spec.scene.objects))[0]:
            site = Site("physics.reset", f"the {write.prop} of '{write.object}' the reset wrote, drawn")
            for field, divisor in write.values:
                self.used.add(field)
                read = name(local(field))
                var = f"_b{len(values)}"
                fb.assign(var, read if divisor == 1.0 else ast.BinOp(read, ast.Div(), const(divisor)), site)
                values.append(name(var))
            targets.append(BindingTarget(write.object, write.prop, len(write.values)))

    def bound_object_known(self, obj_name: str) -> bool:
        """A bound object must be declared, unless a .blend may hold it (the renderer checks those)."""
        declared = self.spec.scene.objects
        if obj_name == WORLD_ACTOR and obj_name not in declared:
            return True  # the world: the spec's, the file's, or the default one
        model_objects = self.physics_objects()
        if (obj_name in model_objects or obj_name.startswith("body:")) and obj_name not in declared:
            return True  # a geom, light or camera of the MuJoCo model (e.g. a colour drawn at reset: domain randomisation), a body
        if self.spec.scene.file is None and obj_name not in declared:
            known = [*declared, *model_objects]
            self.error(
                ("actors", obj_name),
                f"no object '{obj_name}' in the scene" + did_you_mean(obj_name, known).replace("names:", "objects:"),
                key=True,
            )
            return False
        return True

    def bind_property(
        self,
        fb: FunctionBuilder,
        path: tuple,
        raw: Any,
        scope: dict[str, Type],
        targets: list[BindingTarget],
        values: list[ast.expr],
    ) -> None:
        """One binding: its object's type checked, its values assigned one line each (so a fault names it), its target recorded."""
        _, obj_name, prop = path
        obj = self.spec.scene.objects.get(obj_name)
        if self.plan is not None and (
            why := phys.model_object_problem(self.plan, obj_name, prop, set(self.spec.scene.objects))
        ):
            # MuJoCo poses the model's objects: a pose binding would leave the physics behind
            self.error(path, why, key=True)
            return
        if obj is None and obj_name in self.physics_objects():
            problem = type_problem(prop, obj_name, self.physics_objects()[obj_name])
            if problem:
                self.error(path, problem, key=True)
                return
        problem = type_problem(prop, obj_name, object_type(obj)) if obj is not None else None
        world = obj is None and obj_name == WORLD_ACTOR
        if world and prop not in WORLD_PROPERTIES:
            problem = f"the World actor binds the world's {', '.join(map(repr, WORLD_PROPERTIES))}, not '{prop}'"
        if problem:
            self.error(path, problem, key=True)
            return
        checked_values: list[ast.expr] | tuple[ast.expr, int] | None
        if world and prop == "rotation" and not isinstance(raw, list) and not str(raw).strip().startswith("["):
            checked = self.expr(path, raw, scope, expect=NUM)  # one angle: about the vertical axis
            checked_values = [const(0.0), const(0.0), lower(checked.tree)] if checked else None
        else:
            checked_values = self.binding_values(path, prop, raw, scope)
        if checked_values is None:
            return
        text = "[" + ", ".join(map(str, raw)) + "]" if isinstance(raw, list) else str(raw)
        site = Site(".".join(map(str, path)), text, tuple(sorted(scope)))
        if isinstance(checked_values, tuple):  # a vector computed as a whole: evaluate it once
            whole, size = checked_values
            var = f"_b{len(values)}v"
            fb.assign(var, whole, site)
            checked_values = [ast.Subscript(name(var), const(i), ast.Load()) for i in range(size)]
        for item in checked_values:
            var = f"_b{len(values)}"
            fb.assign(var, item, site)
            values.append(name(var))
        targets.append(BindingTarget(obj_name, prop, len(checked_values)))

    def check_cameras(self) -> None:
        """The observation and view cameras of a scene declared in full (a .blend's are checked when it is loaded)."""
        spec = self.spec
        if spec.observation is None or spec.scene.file is not None:
            return
        types = {n: object_type(o) for n, o in spec.scene.objects.items()}
        # the model's cameras, by their MuJoCo names
        types.update({n: t for n, t in self.physics_objects().items() if n not in types})
        for path, camera in spec.camera_uses():
            problem = camera_problem(camera, types)
            if problem:
                self.error(path, problem)

    def binding_values(
        self, path: tuple, prop: str, raw: Any, scope: dict[str, Type]
    ) -> list[ast.expr] | tuple[ast.expr, int] | None:
        """A binding's value as a list of scalar trees, or (vector tree, size) when it is not a literal."""
        kind = BINDABLES[prop].value
        wanted = VALUE_TYPES[kind]
        if wanted.kind == "vec":
            if isinstance(raw, list):
                if kind == "color" and len(raw) not in (3, 4):
                    self.error(path, "a colour needs 3 (RGB) or 4 (RGBA) values")
                    return None
                out = []
                for i, item in enumerate(raw):
                    checked = self.expr(path + (i,), item, scope, expect=NUM)
                    if checked is None:
                        return None
                    out.append(lower(checked.tree))
                return out
            if kind == "scale" and not (isinstance(raw, str) and raw.strip().startswith("[")):
                checked = self.expr(path, raw, scope, expect=NUM)
                return [lower(checked.tree)] * 3 if checked else None
            checked = self.expr(path, raw, scope)
            if checked is None:
                return None
            size = checked.type.size if checked.type.kind == "vec" else 0
            if (
                checked.type.kind != "vec"
                or (wanted.size and size != wanted.size)
                or (kind == "color" and size not in (3, 4))
            ):
                need = "3 or 4 values" if kind == "color" else f"a vector of {wanted.size}"
                self.error(path, f"'{prop}' needs {need}, got {checked.type}")
                return None
            tree = lower(checked.tree)
            if isinstance(tree, ast.Tuple):
                return list(tree.elts)
            return tree, size  # e.g. a conditional between vectors: the caller evaluates it once
        checked = self.expr(path, raw, scope, expect=wanted)
        if checked is None:
            return None
        return [lower(checked.tree)]
