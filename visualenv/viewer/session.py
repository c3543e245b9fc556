"""The loop behind `visualenv view`: step the env by the page's keys or an agent, show each step, rebuild on an edit.

It runs in the main thread (Blender renders in the thread that built the scene) and talks to the page only through
the :class:`~visualenv.viewer.board.Board`: it reads the page's inputs from its queue and publishes snapshots.

How it steps (docs/viewer.md): an agent or continuous inputs step the env at the chosen speed; discrete actions step
while a key is held (a tap is one step), so an env with no action that does nothing waits for the player. An
episode that ends stays on the page for a second, then the next starts with the next seed. A spec edit that does
not build shows its located error while the last good env goes on; one that builds replaces the env and starts a
new episode with the same seed. An error while stepping pauses the env and shows the error; reset or an edit
goes on.
"""

from __future__ import annotations

import queue
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from visualenv.env.visual_env import VisualEnv
from visualenv.env.wrappers import FrameStack
from visualenv.errors import SpecError, VisualEnvError
from visualenv.spec.loader import load_spec
from visualenv.train.model_files import stacked_like
from visualenv.train.play import with_view
from visualenv.viewer.board import MAX_QUEUED_INPUTS, VIEW, Board, ViewPacer, observation_pictures, plain
from visualenv.viewer.controls import Controls, controls_for
from visualenv.viewer.watch import FileWatcher, named_files

#: seconds an ended episode stays on the page before the next one starts
END_HOLD_S = 1.0
#: seconds between looks at the watched files
WATCH_EVERY_S = 0.5
#: steps per second at the start
DEFAULT_SPEED = 10.0
#: taps, and single steps asked for, that wait for their steps; more are dropped (a flood of keys is not a backlog)
MAX_PENDING_STEPS = 32


@dataclass(frozen=True)
class Agent:
    """A loaded model that picks the actions (SB3's ``predict``), and the file it came from."""

    model: Any
    path: str


@dataclass(frozen=True)
class ViewOptions:
    """The high-resolution view: its render preset ('fast' or 'quality'), longer side in pixels; preset None: no view."""

    preset: str | None = "fast"
    size: int | None = 320


#: the view `visualenv view` shows by default: 'fast' at 320 px (a 'quality' view takes seconds a frame on a CPU)
DEFAULT_VIEW = ViewOptions()


def describe(exc: BaseException) -> str:
    """What the page shows for an error: a SpecError's located lines as they are, another error with its kind."""
    if isinstance(exc, SpecError):
        return str(exc)
    if isinstance(exc, VisualEnvError):
        return f"error: {exc}"
    return f"{type(exc).__name__}: {exc}"


def shown_path(path: str | Path) -> str:
    """A path as the page shows it: relative to the working folder where it lies inside it, else its name alone (the
    page, and so `/state`, needs no more of where the user keeps their files)."""
    try:
        return str(Path(path).resolve().relative_to(Path.cwd()))
    except ValueError:
        return Path(path).name


class Session:
    """One spec (or id) on the page: its env, the keys, the agent, the episode, and the files of a live edit."""

    def __init__(
        self,
        path: Path,
        board: Board,
        *,
        agent: Agent | None = None,
        seed: int = 0,
        view: ViewOptions = DEFAULT_VIEW,
        speed: float = DEFAULT_SPEED,
        trust_code: bool = False,
    ) -> None:
        self.path = path
        self.trust_code = trust_code  # the spec's dynamics.python may be imported (docs/security.md)
        self.board = board
        self.agent = agent
        self.view = view
        self.seed = seed
        self.speed = speed
        self.watcher = FileWatcher([path])
        self.env: Any = None  # what steps: the VisualEnv, in the agent's frame stack where it has one
        self.base: VisualEnv | None = None
        self.controls = Controls()
        self.title = path.name
        self.builds = 0
        self.spec_error: str | None = None
        self.run_error: str | None = None
        self.paused = False
        self.episode = 0
        self.held: list[str] = []  # keys down, the latest last
        self.taps: list[str] = []  # discrete keys pressed since the last step: a tap shorter than a step still steps
        self.step_requests = 0
        self.sliders: list[float] = []
        self.obs: Any = None
        self.info: dict[str, Any] = {}
        self.reward: float | None = None
        self.ret = 0.0
        self.last_action: Any = 0
        self.action_text: Any = None
        self.ended_at: float | None = None
        self.next_step_at = 0.0
        self.view_stale = False
        self.pacer = ViewPacer()

    # -- the loop -------------------------------------------------------------------------------------

    def run(self) -> None:
        """Build the env, then step, show and rebuild until interrupted (KeyboardInterrupt reaches the caller)."""
        self.publish()
        self.rebuild()
        next_watch = time.monotonic() + WATCH_EVERY_S
        while True:
            self.take_inputs(max(0.0, self._wake_at(next_watch) - time.monotonic()))
            if time.monotonic() >= next_watch:
                next_watch = time.monotonic() + WATCH_EVERY_S
                if self.watcher.changed():
                    self.rebuild()
            self.advance()
            self.refresh_view()

    def close(self) -> None:
        if self.env is not None:
            self.env.close()
            self.env = self.base = None

    def _wake_at(self, next_watch: float) -> float:
        """When the loop has something to do, unless an input comes first."""
        times = [next_watch]
        if self.env is not None:
            if self.ended_at is not None and not self.paused:
                times.append(self.ended_at + END_HOLD_S)
            elif not self.paused and self._has_action():
                times.append(self.next_step_at)
            if self.step_requests or self._view_due():
                times.append(0.0)
        return min(times)

    # -- inputs ---------------------------------------------------------------------------------------

    def take_inputs(self, timeout: float) -> None:
        """Wait up to `timeout` seconds for the page's first input, then take every one that came.

        Each input costs the loop a few operations, but a reset costs an episode's start: of the resets that came
        together only the last runs, so that a flood of inputs never delays the pause that follows it.
        """
        try:
            first = self.board.inputs.get(timeout=timeout) if timeout > 0 else self.board.inputs.get_nowait()
        except queue.Empty:
            return
        messages = [first]
        while len(messages) < MAX_QUEUED_INPUTS:
            try:
                messages.append(self.board.inputs.get_nowait())
            except queue.Empty:
                break
        last_reset = max((i for i, m in enumerate(messages) if m["type"] == "reset"), default=-1)
        for i, message in enumerate(messages):
            if message["type"] != "reset" or i == last_reset:
                self.take(message)
        self.publish()

    def take(self, message: dict[str, Any]) -> None:
        """One input of the page (checked by the server: the fields are there and of their types)."""
        kind = message["type"]
        now = time.monotonic()
        if kind == "key":
            self._key(message["key"], message["down"], now)
        elif kind == "pause":
            self.paused = not self.paused
            self.taps.clear()
            self.step_requests = 0
            self.next_step_at = now
        elif kind == "step":
            self.paused = True
            self.step_requests = min(self.step_requests + 1, MAX_PENDING_STEPS)
        elif kind == "reset":
            self.step_requests = 0
            if self.env is not None:
                self.reset(self.seed if message["seed"] is None else message["seed"])
        elif kind == "speed":
            self.speed = message["value"]
            self.next_step_at = min(self.next_step_at, now + 1.0 / self.speed)
        elif kind == "slider":
            names = [name for name, _, _ in self.controls.inputs]
            if message["name"] in names:
                i = names.index(message["name"])
                _, low, high = self.controls.inputs[i]
                self.sliders[i] = float(np.clip(message["value"], low, high))

    def _key(self, key: str, down: bool, now: float) -> None:
        if key not in self.controls.keys and key not in self.controls.holds:
            return
        if not down:
            if key in self.held:
                self.held.remove(key)
            return
        if key in self.held:
            return
        if key in self.controls.keys and not self.paused:
            if not any(k in self.controls.keys for k in self.held):
                self.next_step_at = now  # a fresh press steps at once; holding it repeats at the speed
            if len(self.taps) < MAX_PENDING_STEPS:
                self.taps.append(key)
        self.held.append(key)

    def _has_action(self) -> bool:
        """Whether the env has an action to take now: an agent's or the inputs' always, the keys' while one is pressed."""
        if self.agent is not None or not self.controls.discrete:
            return True
        return bool(self.taps) or any(k in self.controls.keys for k in self.held)

    def _action(self, single: bool = False) -> Any:
        """The next step's action, None where no key asks for one (`single`: a step asked for: the last action)."""
        if self.agent is not None:
            return self.agent.model.predict(self.obs, deterministic=True)[0]
        controls = self.controls
        if not controls.discrete:
            values = list(self.sliders)
            for down in self.held:
                if down in controls.holds:
                    index, value = controls.holds[down]
                    values[index] = value
            return np.array(values, dtype=np.float32)
        key: str | None = (
            self.taps.pop(0) if self.taps else next((k for k in reversed(self.held) if k in controls.keys), None)
        )
        if key is None:
            return self.last_action if single else None
        return controls.keys[key]

    # -- stepping -------------------------------------------------------------------------------------

    def advance(self) -> None:
        """Whatever is due: the next episode after an ended one, a step asked for while paused, or the next step."""
        if self.env is None:
            return
        now = time.monotonic()
        if self.ended_at is not None:
            if self.step_requests or (not self.paused and now >= self.ended_at + END_HOLD_S):
                self.step_requests = 0
                self.reset(self.seed + 1)
            return
        if self.paused:
            if self.step_requests:
                self.step_requests -= 1
                self.step(self._run(lambda: self._action(single=True)))
            return
        if now < self.next_step_at or not self._has_action():
            return
        self.next_step_at = now + 1.0 / self.speed
        self.step(self._run(self._action))

    def _run(self, fn: Any) -> Any:
        """`fn()`, or None where it raised (the agent's predict on an observation it cannot take): the error is shown."""
        try:
            return fn()
        except Exception as exc:  # noqa: BLE001 - shown on the page; the viewer goes on
            self._stopped(exc)
            return None

    def step(self, action: Any) -> None:
        if action is None or self.ended_at is not None:
            return
        try:
            obs, reward, terminated, truncated, info = self.env.step(action)
        except Exception as exc:  # noqa: BLE001 - a StepError (on_fault: raise) or anything the env raised: shown, not fatal
            self._stopped(exc)
            return
        self.obs, self.info, self.reward = obs, info, float(reward)
        self.ret += float(reward)
        self.last_action = action
        if self.controls.discrete:
            index = int(np.asarray(action).reshape(-1)[0])
            self.action_text = self.controls.labels.get(index, index)
        else:
            self.action_text = np.round(np.asarray(action, dtype=np.float64).reshape(-1), 3)
        if terminated or truncated:
            self.ended_at = time.monotonic()
        self.publish(pictures=True)

    def reset(self, seed: int) -> None:
        """A new episode with `seed`."""
        self.seed = seed
        try:
            self.obs, self.info = self.env.reset(seed=seed)
        except Exception as exc:  # noqa: BLE001 - shown on the page
            self._stopped(exc)
            return
        self.episode += 1
        self.reward, self.ret, self.action_text = None, 0.0, None
        self.ended_at = None
        self.run_error = None
        self.taps.clear()
        self.next_step_at = time.monotonic()
        self.publish(pictures=True)

    def _stopped(self, exc: BaseException) -> None:
        """An error while stepping: shown, and the env paused until a reset or an edit."""
        self.run_error = describe(exc)
        self.paused = True
        self.ended_at = time.monotonic()
        self.publish()

    # -- live edit -------------------------------------------------------------------------------------

    def rebuild(self) -> None:
        """Load, compile and build the spec again; on success the new env replaces the old, else the error is shown."""
        try:
            built = self._build()
        except Exception as exc:  # noqa: BLE001 - whatever a saved file makes the build raise, the server goes on
            self.spec_error = describe(exc)
            self.publish()
            return
        old = self.env
        self.env, self.base, self.controls, (self.obs, self.info) = built
        self.title = self.base.program.spec.id
        self.builds += 1
        self.spec_error = self.run_error = None
        self.sliders = self._kept_sliders()
        self.held.clear()
        self.taps.clear()
        self.episode += 1
        self.reward, self.ret, self.action_text, self.ended_at = None, 0.0, None, None
        self.next_step_at = time.monotonic()
        if old is not None:
            try:
                old.close()
            except Exception:  # noqa: BLE001, S110 - the old env is gone either way
                pass
        self.publish(pictures=True, rebuilt=True)

    def _build(self) -> tuple[Any, VisualEnv, Controls, tuple[Any, dict[str, Any]]]:
        try:
            loaded = load_spec(self.path)
        except BaseException:
            self.watcher.watch([*self.watcher.paths, self.path])
            raise
        self.watcher.watch(named_files(loaded))
        viewable = self.view.preset is not None and (
            loaded.spec.observation is not None or loaded.spec.render.view.camera is not None
        )
        if viewable:
            loaded = with_view(loaded, preset=self.view.preset, size=self.view.size)
        base = VisualEnv(loaded, render_mode="rgb_array" if viewable else None, trust_code=self.trust_code)
        try:
            env = stacked_like(base, self.agent.model, self.agent.path) if self.agent is not None else base
            controls = controls_for(base.program)
            first = env.reset(seed=self.seed)
        except BaseException:
            base.close()
            raise
        return env, base, controls, first

    def _kept_sliders(self) -> list[float]:
        """The sliders' values where the inputs stayed the same, else each input's start."""
        start = self.controls.slider_start()
        if len(self.sliders) == len(start):
            return [float(np.clip(v, low, high)) for v, (_, low, high) in zip(self.sliders, self.controls.inputs)]
        return start

    # -- the page -------------------------------------------------------------------------------------

    def _view_due(self) -> bool:
        if not (
            self.view_stale and self.board.watched and self.base is not None and self.base.render_mode == "rgb_array"
        ):
            return False
        idle = self.paused or self.ended_at is not None or not self._has_action()
        return idle or self.pacer.due()

    def refresh_view(self) -> None:
        """The high-resolution view of the current state, while a page watches: at once when the env waits, else paced."""
        if not self._view_due():
            return
        assert self.base is not None
        started = time.monotonic()
        try:
            frame = self.base.render()
        except Exception as exc:  # noqa: BLE001 - shown on the page
            self.view_stale = False
            self._stopped(exc)
            return
        self.pacer.took(started)
        self.view_stale = False
        self.board.publish(self.values(), {VIEW: frame}, kind=VIEW)

    def publish(self, *, pictures: bool = False, rebuilt: bool = False) -> None:
        """The values, and with `pictures` the observation this step shows (`rebuilt`: the cameras may have changed)."""
        if not pictures:
            self.board.publish(self.values())
            return
        self.view_stale = True
        shown = self.env.latest if isinstance(self.env, FrameStack) else self.obs
        images: dict[str, Any] = observation_pictures(shown)
        if rebuilt and (self.base is None or self.base.render_mode != "rgb_array"):
            images[VIEW] = None
        self.board.publish(self.values(), images, only=True)

    def values(self) -> dict[str, Any]:
        """What the page's tables, controls and status show."""
        info = self.info or {}
        values: dict[str, Any] = {
            "title": self.title,
            "spec": shown_path(self.path),
            "mode": f"agent: {shown_path(self.agent.path)}" if self.agent else "you play: keys below",
            "step": info.get("steps", 0),
            "episode": self.episode,
            "seed": self.seed,
            "reward": self.reward,
            "return": self.ret,
            "outcome": info.get("outcome"),
            "success": info.get("is_success"),
            "action": self.action_text,
            "state": info.get("state", {}),
            "paused": self.paused,
            "speed": self.speed,
            "status": self._status(),
            "error": self.spec_error or self.run_error,
            "builds": self.builds,
            "controls": self.controls.page(self.sliders),
        }
        return plain(values)

    def _status(self) -> str:
        if self.env is None:
            return "the spec does not build yet" if self.spec_error else "building"
        if self.run_error:
            return "stopped by an error: reset (r) or edit the spec"
        if self.ended_at is not None:
            return f"episode over ({self.info.get('outcome')})" + ("" if self.paused else ": the next one starts")
        if self.paused:
            return "paused"
        if not self._has_action():
            return "waiting for a key"
        return "running"
