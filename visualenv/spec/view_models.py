"""The spec's ``observation``, ``render`` and ``distractions``: cameras, the sensor model, render settings."""

from __future__ import annotations

from typing import Annotated, Literal, Optional, Union

from pydantic import Field, field_validator, model_validator

from visualenv.spec.fields import BlenderName, Name, Resolution, StrictModel


class Sensor(StrictModel):
    """A camera sensor's imperfections, applied in numpy to each observation after readback.

    With v a pixel as a fraction of full scale (its byte / 255): ``v *= 1 - vignetting * r**2``
    (r: distance from the centre, 1 at the corners), then photon noise of std
    ``shot_noise * sqrt(v)`` and read noise of std ``read_noise``, then ``v *= gain``,
    clipped to 0..1, ``v **= gamma``, rounded to a byte. Noise is drawn from the env's
    seeded generator: the same seed gives the same frames.
    """

    read_noise: float = Field(0.0, ge=0, le=1, description="std of Gaussian noise, as a fraction of full scale")
    shot_noise: float = Field(
        0.0, ge=0, le=1, description="photon noise: std shot_noise * sqrt(v) at intensity v (fraction of full scale)"
    )
    gain: float = Field(1.0, gt=0, le=100, description="exposure: intensities multiplied by this")
    gamma: float = Field(1.0, gt=0, le=10, description="response curve v ** gamma (below 1 brightens the shadows)")
    vignetting: float = Field(
        0.0,
        ge=0,
        le=1,
        description="darkening at the corners: the fraction of light lost there (falls off as r squared)",
    )


def _sensor_on_light(color: str, sensor: "Sensor | None") -> None:
    if sensor is not None and color not in ("rgb", "grayscale"):
        raise ValueError(f"a sensor model acts on light: it needs color 'rgb' or 'grayscale', not '{color}'")


#: what an observation camera gives: light (rgb, grayscale), distance (depth) or object ids (segmentation)
ColorMode = Literal["rgb", "grayscale", "depth", "segmentation"]


class CameraView(StrictModel):
    camera: BlenderName = Field(description="a camera in the scene")
    resolution: Resolution = Field([100, 100], description="[width, height]")
    color: ColorMode = "grayscale"
    depth_range: Annotated[list[Annotated[float, Field(ge=0)]], Field(min_length=2, max_length=2)] = Field(
        [0.0, 20.0], description="depth observations: distances mapped to 0..255"
    )
    sensor: Sensor | None = Field(
        None, description="camera imperfections (noise, gain, gamma, vignetting) on this camera's frames"
    )

    @model_validator(mode="after")
    def _sensor_needs_light(self) -> "CameraView":
        _sensor_on_light(self.color, self.sensor)
        return self

    @field_validator("resolution")
    @classmethod
    def _pixels(cls, value: list[int]) -> list[int]:
        if value[0] * value[1] > 16_777_216:
            raise ValueError("resolution is too large (at most 16 megapixels)")
        return value


class Observation(StrictModel):
    """What the agent sees: one camera (a Box) or several (a Dict)."""

    camera: BlenderName | None = Field(None, description="the single observation camera")
    resolution: Resolution = Field([100, 100], description="[width, height]")
    color: ColorMode = "grayscale"
    depth_range: Annotated[list[Annotated[float, Field(ge=0)]], Field(min_length=2, max_length=2)] = [0.0, 20.0]
    sensor: Sensor | None = Field(
        None, description="camera imperfections (noise, gain, gamma, vignetting) on the single camera's frames"
    )
    cameras: Annotated[dict[Name, CameraView], Field(min_length=1)] | None = Field(
        None, description="several cameras: a Dict observation keyed by these names"
    )

    @field_validator("resolution")
    @classmethod
    def _pixels(cls, value: list[int]) -> list[int]:
        return CameraView._pixels(value)

    @model_validator(mode="after")
    def _one_or_many(self) -> "Observation":
        if (self.camera is None) == (self.cameras is None):
            raise ValueError("give either 'camera' (one camera) or 'cameras' (several)")
        if self.cameras is not None and self.sensor is not None:
            raise ValueError("with several 'cameras', give each camera its own 'sensor'")
        _sensor_on_light(self.color, self.sensor)
        return self

    def views(self) -> dict[str, CameraView]:
        """Every observation camera by key (the single camera's key is its name)."""
        if self.cameras is not None:
            return dict(self.cameras)
        assert self.camera is not None
        return {
            self.camera: CameraView(
                camera=self.camera,
                resolution=self.resolution,
                color=self.color,
                depth_range=self.depth_range,
                sensor=self.sensor,
            )
        }


class ViewSettings(StrictModel):
    """The human view returned by ``env.render()`` (render_mode='rgb_array')."""

    camera: BlenderName | None = Field(None, description="default: the (first) observation camera")
    resolution: Resolution = [400, 400]
    preset: Literal["fast", "quality"] = "quality"

    @field_validator("resolution")
    @classmethod
    def _pixels(cls, value: list[int]) -> list[int]:
        return CameraView._pixels(value)


class RenderSettings(StrictModel):
    """The spec's ``render`` section: engine, quality preset, device and threads of every render, and the human view."""

    engine: Literal["cycles", "workbench", "eevee"] = "cycles"
    preset: Literal["fast", "quality"] = Field(
        "fast", description="fast: 1 sample, no bounces (training); quality: previews"
    )
    samples: int | None = Field(None, ge=1, le=4096, description="overrides the preset's samples")
    bounces: int | None = Field(None, ge=0, le=128, description="overrides the preset's light bounces")
    device: Literal["cpu", "gpu", "auto"] = Field(
        "cpu", description="Cycles device; gpu falls back to cpu with a message"
    )
    threads: int = Field(0, ge=0, le=256, description="render threads, 0: all cores")
    noise: Literal["independent", "shared"] = Field(
        "independent",
        description="Cycles' sampling noise: independent per pixel (Cycles' default), or shared by every pixel "
        "(scrambling distance 0: a pixel's value does not depend on where it lies in the image; batched envs render so)",
    )
    view: ViewSettings = Field(default_factory=ViewSettings)


#: ``difficulty: [low, high]``: each episode's difficulty drawn uniformly between the two
DifficultyRange = Annotated[list[Annotated[float, Field(ge=0.0, le=1.0)]], Field(min_length=2, max_length=2)]


class VideoBackground(StrictModel):
    """``distractions.background`` as the Distracting Control Suite's: DAVIS 2017's videos from the user's copy."""

    videos: str = Field(
        min_length=1,
        description=(
            "the folder of DAVIS 2017's videos (DAVIS/JPEGImages/480p: a folder of .jpg frames per video); "
            "relative to the spec's folder (to the working directory in make()'s option), ~ and $VARIABLES expanded"
        ),
    )
    split: Literal["train", "val", "all"] = Field(
        "train",
        description="the suite's 60 training videos or its 30 validation ones, or 'all': every clip in the folder (a "
        "folder of frames each, in name order), not DAVIS's; a level plays the first 4 (up to 0.1), 8 (up to 0.2) or all",
    )


class Distractions(StrictModel):
    """The ``distractions`` section: what the observation shows changed per episode (or drifting every step), the
    state and rewards untouched; the Distracting Control Suite's kinds at its scale (docs/distractions.md)."""

    difficulty: Union[Annotated[float, Field(ge=0.0, le=1.0)], DifficultyRange] = Field(
        description=(
            "the scale of every change: camera orbit and roll up to difficulty x pi/2, its distance times 1 - "
            "difficulty/2 to 1 + 1.5 x difficulty, colours shifted by up to difficulty per channel (the Distracting "
            "Control Suite's ranges and its levels 0.1, 0.2, 0.3); [low, high]: drawn uniformly per episode"
        ),
    )
    camera: bool = Field(True, description="the observation cameras orbit, roll and zoom about the point they look at")
    colors: bool = Field(True, description="every material's colour and the sky's shift")
    background: Union[bool, VideoBackground] = Field(
        True,
        description=(
            "true: a moving pattern of two random colours over the sky, seen by the camera only (visualenv's own); "
            "{videos: DIR, split: train|val|all}: the suite's DAVIS 2017 videos, fully opaque in place of the sky"
        ),
    )
    dynamic: bool = Field(
        False, description="false: drawn at reset and kept for the episode; true: drifting every step as well"
    )
    upper_hemisphere: Optional[bool] = Field(
        None,
        description=(
            "the orbiting camera stays at or above the horizontal plane through the point it orbits, and not past "
            "overhead (the Distracting Control Suite's limit_to_upper_quadrant); default: so, unless the camera "
            "looks straight down (as DeepMind Control's reacher's, which the suite does not limit)"
        ),
    )
    floor_alpha: Optional[Union[Annotated[float, Field(ge=0.0, le=1.0)], Literal["dcs"]]] = Field(
        None,
        description=(
            "the opacity of a MuJoCo model's floor (the geoms of its material 'grid'), the sky and background seen "
            "through the rest (the suite's ground_plane_alpha); 'dcs': the suite's by the model file's name "
            "(reacher 0, walker and cheetah 1, else 0.3); default: opaque. At 1 sample a partial opacity shows as "
            "per-pixel noise of the right average: raise render.samples for a smooth blend"
        ),
    )

    @field_validator("difficulty")
    @classmethod
    def _range_in_order(cls, value: float | list[float]) -> float | list[float]:
        if isinstance(value, list) and value[0] > value[1]:
            raise ValueError(f"expected [low, high] with low <= high, got {value}")
        return value

    @property
    def largest(self) -> float:
        """The largest difficulty an episode may draw (0: no distraction)."""
        return max(self.difficulty) if isinstance(self.difficulty, list) else self.difficulty
