"""Several batches as one vector env: :class:`MultiBatchVectorEnv`.

One :class:`~visualenv.env.batch.BatchedVectorEnv` renders with one Blender,
whose render call uses the threads of one process. To fill a machine with many
cores (or a GPU, with several scenes in flight), `K` worker processes each hold
a batch of about n / K envs, confined to their own share of the cores as
per-process envs are (:mod:`visualenv.env.cores`). The parent holds no Blender:
it sends each worker its slice of the actions and concatenates the replies, so
env i of the whole is env i of the concatenated batches, and env i reset with
seed s is ``visualenv.make`` reset with seed s + i.
"""

from __future__ import annotations

import multiprocessing
import pickle
import signal
import traceback
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium.vector import AutoresetMode
from gymnasium.vector.utils import batch_space

from visualenv.compat.glibc import apply_policy
from visualenv.env.batch import BATCH_OPTIONS, make_batched
from visualenv.env.cores import Share, confine, render_threads, worker_cores
from visualenv.errors import StepError, VisualEnvError, WorkerError

_BROKEN = (EOFError, BrokenPipeError, ConnectionResetError, OSError)


def batch_sizes(num_envs: int, workers: int) -> list[int]:
    """Each worker's number of envs: n split into `workers` parts differing by at most one (the first ones larger)."""
    if isinstance(num_envs, bool) or not isinstance(num_envs, (int, np.integer)) or num_envs < 1:
        raise ValueError(f"num_envs must be an integer of at least 1, got {num_envs!r}")
    if isinstance(workers, bool) or not isinstance(workers, (int, np.integer)) or not 1 <= workers <= num_envs:
        raise ValueError(
            f"workers must be an integer from 1 to num_envs ({num_envs}): each worker holds a batch of at least one env, "
            f"got {workers!r}"
        )
    n, k = int(num_envs), int(workers)
    return [n // k + (1 if w < n % k else 0) for w in range(k)]


class MultiBatchVectorEnv(gym.vector.VectorEnv):
    """`num_envs` envs as `workers` batches, one process (and one Blender scene) each, behind one Gymnasium vector env.

    Spaces, ``info`` and autoreset (``NEXT_STEP`` or ``SAME_STEP``) are those of one
    :class:`~visualenv.env.batch.BatchedVectorEnv` of `num_envs` envs; keyword options
    are :func:`~visualenv.env.batch.make_batched`'s. Each worker renders with the threads
    of its share of the cores (``threads`` overrides; ``pin=False`` leaves workers unconfined).
    """

    metadata = {"autoreset_mode": AutoresetMode.NEXT_STEP, "render_modes": ["rgb_array"], "render_fps": 30}

    def __init__(
        self, target: str, num_envs: int, workers: int, *, pin: bool = True, threads: int | None = None, **kwargs: Any
    ) -> None:
        self._closed_workers = True
        self.sizes = batch_sizes(num_envs, workers)
        bounds = np.cumsum([0, *self.sizes])
        #: the envs of each worker's batch: env j of worker w is env start + j of the whole
        self._slices = [slice(int(a), int(b)) for a, b in zip(bounds[:-1], bounds[1:])]
        self.num_envs = int(num_envs)
        self.render_mode = kwargs.get("render_mode")
        if self.render_mode not in (None, *self.metadata["render_modes"]):  # 'human' would open a page in each worker
            raise ValueError(
                f"render_mode must be one of {self.metadata['render_modes']} with workers, got {self.render_mode!r} "
                "(render_mode='human' shows one batch: leave workers out)"
            )
        # a bad spec is reported here, located, before any worker starts
        self._check_spec(str(target), max(self.sizes), kwargs)
        self._pipes: list[Any] = []
        self.processes: list[Any] = []
        self._closed_workers = False  # from here on, close() stops the workers
        context = multiprocessing.get_context("spawn")
        shares = worker_cores(len(self.sizes), pin)
        try:
            for w, (size, share) in enumerate(zip(self.sizes, shares)):
                options = dict(kwargs)
                # its share's threads (state-only: none)
                if options.get("render") is not False and "threads" not in options:
                    options["threads"] = render_threads(share, len(self.sizes), threads)
                parent, child = context.Pipe()
                process = context.Process(
                    target=_worker,
                    args=(child, str(target), size, options, share),
                    daemon=True,
                    name=f"visualenv-batch-{w}",
                )
                process.start()
                child.close()
                self._pipes.append(parent)
                self.processes.append(process)
            replies = self._gather("start")
        except BaseException:
            self.close()
            raise
        first = replies[0]
        self.single_observation_space = first["observation_space"]
        self.single_action_space = first["action_space"]
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        self.action_space = batch_space(self.single_action_space, self.num_envs)
        self.autoreset_mode = first["autoreset_mode"]
        self.metadata = {**self.metadata, "autoreset_mode": self.autoreset_mode}

    @staticmethod
    def _check_spec(target: str, size: int, kwargs: dict[str, Any]) -> None:
        """The spec compiled, and what a batch of `size` envs cannot render refused, as one batch would (located, typed)."""
        from visualenv.compiler.program import compile_spec
        from visualenv.env.registration import resolve
        from visualenv.compiler.render_plan import checked_options
        from visualenv.render.batch_limits import check_batchable
        from visualenv.spec.loader import load_spec

        program = compile_spec(
            load_spec(resolve(target)), kwargs.get("params"), trust_code=bool(kwargs.get("trust_code"))
        )
        program.check_code_consent()  # the workers are given the consent (trust_code) with the other options
        if kwargs.get("render") is not False and program.spec.observation is not None:
            options = checked_options({k: v for k, v in kwargs.items() if k not in BATCH_OPTIONS})
            check_batchable(program.render_plan().with_options(options), size)

    # -- Gymnasium API ------------------------------------------------------------------------------

    def reset(
        self, *, seed: int | list[int | None] | None = None, options: dict[str, Any] | None = None
    ) -> tuple[Any, dict[str, Any]]:
        """Reset every env; env i gets seed ``seed + i`` (or ``seed[i]``)."""
        seeds = (
            list(seed)
            if isinstance(seed, (list, tuple))
            else [None if seed is None else seed + i for i in range(self.num_envs)]
        )
        if len(seeds) != self.num_envs:
            raise ValueError(f"reset got {len(seeds)} seeds for {self.num_envs} envs")
        for pipe, part in zip(self._pipes, self._slices):
            self._send(pipe, ("reset", {"seed": seeds[part], "options": options}))
        replies = self._gather("reset")
        return _concat([r[0] for r in replies]), merge_infos([r[1] for r in replies], self.sizes)

    def step(self, actions: Any) -> tuple[Any, np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        array = np.asarray(actions)
        if array.shape != self.action_space.shape:
            raise ValueError(
                f"actions of shape {array.shape} for {self.num_envs} envs: the action space is {self.action_space}"
            )
        for pipe, part in zip(self._pipes, self._slices):
            self._send(pipe, ("step", array[part]))
        replies = self._gather("step")
        obs, rewards, terminated, truncated, infos = zip(*replies)
        return (
            _concat(list(obs)),
            np.concatenate(rewards),
            np.concatenate(terminated),
            np.concatenate(truncated),
            merge_infos(list(infos), self.sizes),
        )

    def render(self) -> tuple[np.ndarray, ...] | None:  # type: ignore[override]
        """Each env's view (render_mode="rgb_array"), as one batch's ``render()`` gives them."""
        if self.render_mode is None:
            gym.logger.warn("render() called without render_mode; make the batch with render_mode='rgb_array'")
            return None
        for pipe in self._pipes:
            self._send(pipe, ("render", None))
        return tuple(view for views in self._gather("render") for view in views)

    def get_attr(self, name: str) -> tuple[Any, ...]:
        """Each env's attribute (of its state-only lane, as SB3's ``get_attr`` reads a batch's)."""
        for pipe in self._pipes:
            self._send(pipe, ("get_attr", name))
        return tuple(value for values in self._gather("get_attr") for value in values)

    def call(self, name: str, *args: Any, **kwargs: Any) -> tuple[Any, ...]:
        """Each env's lane's method `name` called with the arguments."""
        for pipe in self._pipes:
            self._send(pipe, ("call", (name, args, kwargs)))
        return tuple(value for values in self._gather("call") for value in values)

    @property
    def segmentation_ids(self) -> dict[str, int]:
        """Id of each label in segmentation observations (the same in every env and worker)."""
        self._send(self._pipes[0], ("segmentation_ids", None))
        return dict(self._receive(0, self._pipes[0], "segmentation_ids"))

    def close_extras(self, **kwargs: Any) -> None:
        if getattr(self, "_closed_workers", True):  # closed, or refused before any worker started
            return
        self._closed_workers = True
        for pipe, process in zip(self._pipes, self.processes):
            if process.is_alive():
                try:
                    pipe.send(("close", None))
                except _BROKEN:
                    pass
        for pipe, process in zip(self._pipes, self.processes):
            process.join(timeout=30)
            if process.is_alive():
                process.terminate()
                process.join(timeout=5)
            pipe.close()

    # -- the workers --------------------------------------------------------------------------------

    def _send(self, pipe: Any, message: tuple[str, Any]) -> None:
        try:
            pipe.send(message)
        except _BROKEN:
            raise self._worker_error(message[0]) from None

    def _gather(self, call: str) -> list[Any]:
        """Every worker's reply to `call`, in order; a worker's exception is raised here (after the others replied)."""
        replies, failure = [], None
        for w, pipe in enumerate(self._pipes):
            try:
                replies.append(self._receive(w, pipe, call))
            except WorkerError:
                raise
            except Exception as exc:  # noqa: BLE001 - the first worker's error is raised once all have answered
                failure = failure or exc
        if failure is not None:
            raise failure
        return replies

    def _receive(self, w: int, pipe: Any, call: str) -> Any:
        try:
            ok, value = pipe.recv()
        except _BROKEN:
            raise self._worker_error(call) from None
        if not ok:
            # env j of worker w's batch is env start + j of the whole
            if isinstance(value, StepError) and value.env is not None:
                raise value.in_env(self._slices[w].start + value.env) from None
            raise value
        return value

    def _worker_error(self, call: str) -> WorkerError:
        for process in self.processes:
            process.join(timeout=0.5 if not process.is_alive() else 0)
        dead = [f"#{i} (pid {p.pid}, exit code {p.exitcode})" for i, p in enumerate(self.processes) if not p.is_alive()]
        return WorkerError(
            f"batch worker {', '.join(dead) or 'a worker'} died during {call}(); close the vector env and make a new one"
        )


def _concat(parts: list[Any]) -> Any:
    """The workers' batch observations joined along the env axis (arrays, or dicts of arrays)."""
    if isinstance(parts[0], dict):
        return {key: np.concatenate([p[key] for p in parts]) for key in parts[0]}
    return np.concatenate(parts)


def merge_infos(infos: list[dict[str, Any]], sizes: list[int]) -> dict[str, Any]:
    """The workers' vector infos as one: each key's arrays joined; a worker without the key gets its mask off.

    A key one worker lacks (``error``, ``final_obs``, ...) is filled, as Gymnasium's vector envs fill
    an absent key: zeros of the others' dtype (None for objects), ``_key`` masks False.
    """
    out: dict[str, Any] = {}
    for key in dict.fromkeys(k for info in infos for k in info):
        values = [info.get(key) for info in infos]
        present = next(v for v in values if v is not None)
        if isinstance(present, dict):
            out[key] = merge_infos([v if isinstance(v, dict) else {} for v in values], sizes)
            continue
        present = np.asarray(present)
        parts = []
        for value, size in zip(values, sizes):
            if value is not None:
                parts.append(np.asarray(value))
            elif present.dtype == object:
                parts.append(np.full(size, None, dtype=object))
            else:
                parts.append(np.zeros((size, *present.shape[1:]), dtype=present.dtype))
        out[key] = np.concatenate(parts)
    return out


def _picklable(exc: BaseException) -> BaseException:
    """`exc` if it survives pickling unchanged, else an error of the nearest kind with its message."""
    try:
        copy = pickle.loads(pickle.dumps(exc))
        if type(copy) is type(exc) and str(copy) == str(exc):
            return exc
    except Exception:  # noqa: BLE001 - anything unpicklable is sent as its message
        pass
    kind = VisualEnvError if isinstance(exc, VisualEnvError) else RuntimeError
    return kind(str(exc) if isinstance(exc, VisualEnvError) else f"{type(exc).__name__}: {exc}")


def _worker(pipe: Any, target: str, size: int, options: dict[str, Any], share: Share | None) -> None:
    """A worker: confined to its cores before Blender starts, then serving its batch's calls until told to close."""
    apply_policy()  # a process visualenv started: freed memory kept for the next render call
    if share is not None:
        confine(share)
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C reaches the process group; the parent decides how to stop
    batch: Any = None
    try:
        batch = make_batched(target, size, **options)
        pipe.send(
            (
                True,
                {
                    "observation_space": batch.single_observation_space,
                    "action_space": batch.single_action_space,
                    "autoreset_mode": batch.autoreset_mode,
                },
            )
        )
    except BaseException as exc:  # noqa: BLE001 - reported to the parent
        pipe.send((False, _picklable(exc)))
        return
    try:
        while True:
            try:
                command, data = pipe.recv()
            except _BROKEN:
                return
            if command == "close":
                return
            try:
                pipe.send((True, _serve(batch, command, data)))
            except BaseException as exc:  # noqa: BLE001 - reported to the parent, which raises it
                if isinstance(exc, KeyboardInterrupt):
                    raise
                pipe.send((False, _picklable(exc)))
    except KeyboardInterrupt:
        traceback.print_exc()
    finally:
        batch.close()


def _serve(batch: Any, command: str, data: Any) -> Any:
    if command == "reset":
        return batch.reset(**data)
    if command == "step":
        return batch.step(data)
    if command == "render":
        return batch.render()
    if command == "get_attr":
        return [getattr(lane, data) for lane in batch.lanes]
    if command == "call":
        name, args, kwargs = data
        return [getattr(lane, name)(*args, **kwargs) for lane in batch.lanes]
    if command == "segmentation_ids":
        return batch.segmentation_ids
    raise ValueError(f"unknown batch worker command {command!r}")
