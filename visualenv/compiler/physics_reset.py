"""The compiler's part for ``physics.reset``: its values, a redraw loop and settling steps, as the first lines of init.

A reset runs in the order every DeepMind Control task's ``initialize_episode`` follows (the
simulation has been reset by MuJoCo, and forwarded, before init runs; docs/physics.md#reset):

1. the model's values the entries read, in one read;
2. ``values`` in order (draws included), then written (``_phys_write_reset``): joint values and
   writable model fields (:mod:`visualenv.physics.model_fields`); the convention's forward follows
   only when there is neither a redraw nor a settle (as dm_control writes ``qpos`` in a task);
3. ``redraw``: at most ``attempts`` tries, each starting from the values step 2 left: its entries,
   written and forwarded (``_phys_write_redraw``), then ``until`` read after that forward; the
   first try that meets it ends the loop, none is a located fault at ``physics.reset.redraw.until``;
4. ``search``: at most ``attempts`` tries, each writing its values (the first: as the steps before
   left them) and forwarding (``_phys_write_search``), then reading ``until``; a try that fails
   computes the next try's values from its own (``step``): a loop on a value, as quadruped's
   reset raises its body until nothing touches;
5. ``settle``: its physics steps and the time set, then a last forward (``_phys_finish_reset``;
   after a redraw or search without a settle, the forward alone, as dm_control's ``after_reset``).

The generated loop is Python's ``for ... else`` over a range bound per env: each statement that
evaluates a spec expression keeps a line (and site) of its own, so a fault inside names it.
"""

from __future__ import annotations

import ast
from typing import Any, Collection, Mapping, Protocol

from visualenv.compiler import physics as phys
from visualenv.errors import did_you_mean
from visualenv.expr import BOOL, NUM, Checked, Type, vec
from visualenv.expr.codegen import FunctionBuilder, Site, const, local, lower, name
from visualenv.physics.model_fields import MODEL_PREFIX, is_writable, written_geoms
from visualenv.spec.fields import Expr
from visualenv.spec.models import Spec

#: keys of reset values that name the model's values (anything else is a temporary)
MODEL_KEYS = ("qpos_", "qvel_", "mocap_", "model_")
#: a redraw's saved values (a try starts from them) are locals with this prefix
BASE_PREFIX = "_base_"


class ResetCompiler(Protocol):
    """What the reset's compilation uses of the spec compiler (:mod:`visualenv.compiler.program`)."""

    spec: Spec
    plan: phys.PhysicsPlan | None
    pnames: dict[str, Type]
    used: set[str]

    def error(self, path: tuple, message: str, *, key: bool = False, column: int | None = None) -> None: ...

    def expr(
        self, path: tuple, text: Any, names: Mapping[str, Type], *, expect: Type | None = None, random: bool = True
    ) -> Checked | None: ...

    def physics_reads(
        self, fb: FunctionBuilder, key: str, at: int, used: set[str], exclude: Collection[str] = ()
    ) -> None: ...


def build_reset(c: ResetCompiler, fb: FunctionBuilder) -> None:
    """The physics reset's statements, appended to init's `fb` (before the state's own inits)."""
    assert c.plan is not None and c.spec.physics is not None
    plan, section = c.plan, c.spec.physics.reset
    table = plan.model.names.values
    # joints, mocap, model fields
    writable = phys.settable(plan.model) | {n for n, (array, _) in table.items() if is_writable(array)}
    scope: dict[str, Type] = dict(c.pnames)
    start, before = len(fb.body), set(c.used)
    c.used = set()
    targets = entries(c, fb, section.values, ("physics", "reset", "values"), scope, writable)
    plan.reset_targets = targets
    plan.finishes = section.redraw is not None or section.search is not None or section.settle is not None
    fb.add(
        phys.call_statement(phys.WRITE_RESET, targets), Site("physics.reset", "the reset values, written to the model")
    )
    until_used: set[str] = set()
    redrawn: list[str] = []
    if section.redraw is not None:
        redrawn, until_used = redraw_loop(c, fb, scope, writable)
    plan.redraw_targets = redrawn
    plan.redraw_attempts = section.redraw.attempts if section.redraw is not None else 0
    searched: list[str] = []
    if section.search is not None:
        searched, search_used = search_loop(c, fb, scope, writable)
        until_used |= search_used
    plan.search_targets = searched
    plan.search_attempts = section.search.attempts if section.search is not None else 0
    plan.settle = (section.settle.steps, section.settle.time) if section.settle is not None else None
    if plan.finishes:
        what = "the settling steps, then the model forwarded" if section.settle is not None else "the model forwarded"
        last = "settle" if section.settle else "search" if section.search else "redraw"
        fb.add(ast.Expr(ast.Call(name(phys.FINISH_RESET), [], [])), Site(f"physics.reset.{last}", what))
    reads = c.used
    c.physics_reads(fb, "reset", start, reads | set(targets) | set(redrawn) | set(searched))
    c.used = before | reads | until_used
    geoms = written_geoms(plan.written(), table)
    plan.posed_geoms = tuple(geoms)
    if plan.scene is not None and geoms:
        from visualenv.physics.geom_poses import with_posed_geoms

        plan.scene = with_posed_geoms(plan.scene, plan.model, geoms)
    if plan.scene is not None:
        from visualenv.physics.geom_poses import drawn_writes

        for written, problem in drawn_writes(plan.scene, plan.model, plan.written())[1]:
            place, keys = (
                (("values",), section.values)
                if written in targets
                else (("redraw", "values"), section.redraw.values)  # type: ignore[union-attr]
                if written in redrawn
                else (("search", "step"), section.search.step)  # type: ignore[union-attr]
            )
            key = next(k for k in keys if written in [p.strip() for p in k.split(",")])
            c.error(("physics", "reset", *place, key), problem, key=True)


def entries(
    c: ResetCompiler,
    fb: FunctionBuilder,
    values: Mapping[str, Any],
    where: tuple,
    scope: dict[str, Type],
    writable: Collection[str],
) -> list[str]:
    """Statements for reset entries (keys: the model's values to write, or temporaries), in order; the model's values they write."""
    targets: list[str] = []
    for key, value in values.items():
        path = (*where, key)
        parts = [p.strip() for p in key.split(",")]
        bad = [p for p in parts if not p.isidentifier()]
        if bad:
            c.error(
                path,
                f"'{bad[0]}' is not a name: a key is a qpos_/qvel_/mocap_ name or a writable model field, several separated "
                "by commas, or a new name",
                key=True,
            )
            continue
        if len(parts) > 1 or parts[0].startswith(MODEL_KEYS) or parts[0] in c.pnames:
            problem = next((why(p, c, writable) for p in parts if p not in writable), None)
            if problem:
                c.error(path, problem, key=True)
                continue
        checked = c.expr(path, value, scope, expect=NUM if len(parts) == 1 else vec(len(parts)))
        if checked is None:
            continue
        site = Site.of(path, checked)
        if len(parts) == 1:
            fb.assign(local(parts[0]), lower(checked.tree), site)
        else:
            fb.assign("_reset_vec", lower(checked.tree), site)
            for i, p in enumerate(parts):
                fb.assign(local(p), ast.Subscript(name("_reset_vec"), const(i), ast.Load()))
        for p in parts:
            scope[p] = NUM
            if p in writable and p not in targets:
                targets.append(p)
    return targets


def why(key: str, c: ResetCompiler, writable: Collection[str]) -> str:
    """Why a reset cannot write `key`: a model value read only, or no such value (with the close names)."""
    assert c.plan is not None
    array = c.plan.model.names.values.get(key, ("", 0))[0]
    if key in c.pnames and array.startswith(MODEL_PREFIX):
        return (
            f"'{key}' is read from the model, not written: a reset writes joint values (qpos_, qvel_), geoms' and "
            "sites' positions and sizes (model_geom_pos_..., model_site_size_...) and damping (model_dof_damping_...)"
        )
    if key in c.pnames:
        return f"'{key}' is computed by MuJoCo from the state: a reset writes joint values (qpos_, qvel_), mocap poses and writable model fields"
    what = (
        "writable model field"
        if key.startswith("model_")
        else "joint value or mocap pose"
        if c.plan.model.mocap_names()
        else "joint value"
    )
    return f"no {what} '{key}' to set" + did_you_mean(key, sorted(writable))


def redraw_loop(
    c: ResetCompiler, fb: FunctionBuilder, scope: dict[str, Type], writable: Collection[str]
) -> tuple[list[str], set[str]]:
    """``for _try in tries: <restore>; <entries>; write and forward; read; if until: break`` ``else: fail``; its targets and until's names."""
    assert c.plan is not None and c.spec.physics is not None and c.spec.physics.reset.redraw is not None
    redraw = c.spec.physics.reset.redraw
    where = ("physics", "reset", "redraw")
    mark = len(fb.body)
    targets = entries(c, fb, redraw.values, (*where, "values"), scope, writable)
    body, fail_stmt, until_used = _one_try(c, fb, mark, "redraw", targets, redraw.until, scope)
    restore = [ast.Assign([ast.Name(local(t), ast.Store())], name(BASE_PREFIX + t)) for t in targets]
    for t in targets:  # each try starts from the values physics.reset.values left
        fb.add(ast.Assign([ast.Name(BASE_PREFIX + t, ast.Store())], name(local(t))))
    loop = ast.For(ast.Name("_try", ast.Store()), name(phys.REDRAW_TRIES), [*restore, *body], [fail_stmt])
    fb.body.append(loop)
    return targets, until_used


def _one_try(
    c: ResetCompiler, fb: FunctionBuilder, mark: int, kind: str, targets: list[str], until: Expr, scope: dict[str, Type]
) -> tuple[list[ast.stmt], ast.stmt, set[str]]:
    """A try's statements from `mark` on (write `targets` and forward, read, `until` or break), taken out of the body,
    with the ``else`` that fails apart; and until's names. `kind` is ``redraw`` or ``search``."""
    write, failed, done = {
        "redraw": (phys.WRITE_REDRAW, phys.REDRAW_FAILED, "redrawn"),
        "search": (phys.WRITE_SEARCH, phys.SEARCH_FAILED, "searched"),
    }[kind]
    fb.add(
        phys.call_statement(write, targets), Site(f"physics.reset.{kind}", f"the {done} values, written to the model")
    )
    until_used = _until_or_fail(c, fb, kind, until, scope, failed)
    body, fail_stmt = fb.body[mark:-1], fb.body[-1]
    del fb.body[mark:]
    return body, fail_stmt, until_used


def search_loop(
    c: ResetCompiler, fb: FunctionBuilder, scope: dict[str, Type], writable: Collection[str]
) -> tuple[list[str], set[str]]:
    """``for _try in tries: write and forward; read; if until: break; <step>`` ``else: fail``; its targets and until's names.

    Each try writes what the one before left (the first: what the reset's values and redraw left, or the model's own),
    and a try that fails steps them: a loop on a value (dm_control's ``_find_non_contacting_height``: z += 0.01)."""
    assert c.plan is not None and c.spec.physics is not None and c.spec.physics.reset.search is not None
    search = c.spec.physics.reset.search
    where = ("physics", "reset", "search")
    mark = len(fb.body)
    targets = entries(c, fb, search.step, (*where, "step"), scope, writable)
    step = fb.body[mark:]
    del fb.body[mark:]
    body, fail_stmt, until_used = _one_try(c, fb, mark, "search", targets, search.until, scope)
    fb.body.append(ast.For(ast.Name("_try", ast.Store()), name(phys.SEARCH_TRIES), [*body, *step], [fail_stmt]))
    return targets, until_used


def _until_or_fail(
    c: ResetCompiler, fb: FunctionBuilder, step: str, until: Expr, scope: dict[str, Type], failed: str
) -> set[str]:
    """A reset loop's test, written once for redraw and search: the model's names `until` reads, then ``if until:
    break``, then the call to `failed` (the loop's last statement: it moves to the loop's ``else``); until's names."""
    outer, c.used = c.used, set()
    at = len(fb.body)
    checked = c.expr(("physics", "reset", step, "until"), until, scope, expect=BOOL)
    until_used = c.used
    c.physics_reads(fb, step, at, until_used)
    c.used = outer
    until_site = Site(
        f"physics.reset.{step}.until", checked.text if checked else "", tuple(sorted(checked.names)) if checked else ()
    )
    fb.add(ast.If(lower(checked.tree) if checked else const(True), [ast.Break()], []), until_site)
    fb.add(ast.Expr(ast.Call(name(failed), [], [])), until_site)
    return until_used
