"""The spec's ``scene``: objects (primitives, meshes, lights, cameras, empties), their materials and the world."""

from __future__ import annotations

from typing import Annotated, Any, Literal, Union

from pydantic import Discriminator, Field, Tag, field_validator, model_validator

from visualenv.files import MAX_IMAGE_PIXELS
from visualenv.spec.fields import BlenderName, Color, Name, StrictModel, Vec3


class Texture(StrictModel):
    """A procedural or image texture that drives the base colour of a material."""

    type: Literal["noise", "voronoi", "checker", "wave", "image"] = Field(description="texture kind")
    scale: float = Field(5.0, gt=0, description="texture coordinate scale (procedural kinds)")
    detail: float = Field(2.0, ge=0, le=15, description="noise detail")
    colors: Annotated[list[Color], Field(min_length=2, max_length=2)] | None = Field(
        None, description="two colours the texture value blends between (procedural kinds)"
    )
    image: Union[str, Annotated[list[str], Field(min_length=1)], None] = Field(
        None,
        description="image file, relative to the spec (type: image); or a list of files, a texture set an actor's 'texture' picks from",
    )

    @model_validator(mode="after")
    def _image_needs_file(self) -> "Texture":
        if self.type == "image" and not self.image:
            raise ValueError("an image texture needs 'image': a file path")
        return self


class Material(StrictModel):
    """A Principled BSDF material."""

    color: Color = Field([0.8, 0.8, 0.8], description="base colour; an alpha below 1 makes the surface see-through")
    roughness: float = Field(0.5, ge=0, le=1)
    metallic: float = Field(0.0, ge=0, le=1)
    emission: Color | None = Field(None, description="emission colour")
    emission_strength: float = Field(1.0, ge=0)
    texture: Texture | None = None


class ObjectBase(StrictModel):
    location: Vec3 = Field([0.0, 0.0, 0.0], description="initial location (m)")
    rotation: Vec3 = Field([0.0, 0.0, 0.0], description="initial Euler XYZ rotation (radians)")
    scale: Union[float, Vec3] = Field(1.0, description="initial scale")
    visible: bool = True
    parent: BlenderName | None = Field(None, description="name of the parent object")


class Craters(StrictModel):
    """Bowl-shaped craters pressed into a terrain: real geometry, so a low sun casts shadows in them.

    Each crater of radius R is a parabolic bowl ``depth * 2R`` deep with a raised
    rim ``rim * 2R`` high whose ejecta fall off as ``(R / r)**3`` outside it (the
    usual profile of a simple crater); craters add up where they overlap. Radii
    are drawn log-uniformly (small craters are the common ones), places uniformly,
    from ``seed``: the same spec always builds the same ground.
    """

    count: int = Field(40, ge=1, le=2000, description="number of craters")
    radius: Annotated[list[Annotated[float, Field(gt=0)]], Field(min_length=2, max_length=2)] = Field(
        [0.5, 5.0], description="[smallest, largest] crater radius (m)"
    )
    depth: float = Field(0.2, ge=0, le=1, description="bowl depth as a fraction of the diameter")
    rim: float = Field(0.04, ge=0, le=1, description="rim height as a fraction of the diameter")
    seed: int = Field(0, ge=0, description="seed of the crater places and sizes")

    @field_validator("radius")
    @classmethod
    def _radius_order(cls, radius: list[float]) -> list[float]:
        if radius[0] > radius[1]:
            raise ValueError("[smallest, largest]: the first must not be greater")
        return radius


class PrimitiveObject(ObjectBase):
    """A mesh primitive built by the compiler."""

    primitive: Literal["cube", "plane", "sphere", "cylinder", "cone", "torus", "disk", "ring", "terrain"]
    size: Union[Annotated[float, Field(gt=0)], Vec3] = Field(
        1.0, description="cube/plane/terrain edge length, or [x, y, z] dimensions"
    )
    radius: float = Field(0.5, gt=0, description="sphere/cylinder/cone/disk/torus radius")
    depth: float = Field(1.0, gt=0, description="cylinder/cone height")
    thickness: float = Field(0.05, gt=0, description="ring/torus tube thickness")
    segments: int = Field(
        32, ge=3, le=512, description="round primitives: segments around; terrain: grid cells along each side"
    )
    craters: Craters | None = Field(None, description="terrain: craters pressed into the ground")
    label: Name | None = Field(
        None, description="segmentation: objects that share a label share an id (default: the object's own name)"
    )
    heightmap: str | None = Field(
        None,
        description="terrain: elevation data, relative to the spec: a grayscale PNG (8 or 16 bit), TIFF or .npy; "
        "size [x, y, z] spans it, the lowest value at 0 and the highest at z",
    )
    origin: Literal["center", "bottom"] = Field("center", description="where the object's origin sits")
    smooth: bool = False
    material: Material | None = None

    @model_validator(mode="after")
    def _heightmap_needs_a_height(self) -> "PrimitiveObject":
        if self.heightmap is not None and self.primitive == "terrain" and not isinstance(self.size, list):
            raise ValueError(
                "a terrain with a heightmap needs size: [x, y, z] (z: the height of the map's highest value)"
            )
        return self


class MeshObject(ObjectBase):
    """A mesh imported from a file (.obj, .stl, .ply, .glb/.gltf)."""

    mesh: str = Field(description="mesh file, relative to the spec")
    material: Material | None = None
    label: Name | None = Field(
        None, description="segmentation: objects that share a label share an id (default: the object's own name)"
    )


class LightObject(ObjectBase):
    light: Literal["sun", "point", "spot", "area"]
    strength: float = Field(3.0, ge=0, description="sun: irradiance (W/m2); others: power (W)")
    color: Color = [1.0, 1.0, 1.0]
    spot_size: float = Field(0.785, gt=0, le=3.1416, description="spot cone angle (radians)")
    size: float = Field(0.25, ge=0, description="light radius or area size (m)")


class CameraObject(ObjectBase):
    camera: Literal["perspective", "orthographic"]
    lens: float = Field(35.0, gt=0, description="focal length (mm)")
    sensor_width: float = Field(36.0, gt=0, description="sensor width (mm)")
    ortho_scale: float = Field(6.0, gt=0, description="view width for orthographic cameras (m)")
    clip_start: float = Field(0.05, gt=0)
    clip_end: float = Field(200.0, gt=0)
    look_at: Vec3 | None = Field(None, description="point the camera at this location (overrides rotation)")

    @model_validator(mode="after")
    def _clip_order(self) -> "CameraObject":
        if self.clip_end <= self.clip_start:
            raise ValueError("clip_end must be greater than clip_start")
        return self


class EmptyObject(ObjectBase):
    """An empty: a transform other objects can be parented to."""

    empty: Literal[True] = True


def _object_kind(value: Any) -> str | None:
    if isinstance(value, dict):
        for kind in ("primitive", "mesh", "light", "camera", "empty"):
            if kind in value:
                return kind
        return None
    fields = getattr(type(value), "model_fields", {})
    return next((kind for kind in ("primitive", "mesh", "light", "camera", "empty") if kind in fields), None)


SceneObject = Annotated[
    Union[
        Annotated[PrimitiveObject, Tag("primitive")],
        Annotated[MeshObject, Tag("mesh")],
        Annotated[LightObject, Tag("light")],
        Annotated[CameraObject, Tag("camera")],
        Annotated[EmptyObject, Tag("empty")],
    ],
    Discriminator(
        _object_kind,
        custom_error_type="object_kind",
        custom_error_message="an object needs one of 'primitive', 'mesh', 'light', 'camera' or 'empty'",
    ),
]


class World(StrictModel):
    """The background: a colour, or an environment image that lights the scene and shows behind it.

    Bind ``strength``, ``rotation`` or ``color`` (a tint of the image) through an actor named ``World``.
    """

    color: Color | None = Field(
        None,
        description="background colour (default dark grey); with an image, a tint that multiplies it (default white)",
    )
    strength: float = Field(1.0, ge=0)
    image: str | None = Field(
        None,
        description="an environment map (equirectangular: .hdr, .exr, .png, .jpg, any image Blender reads), "
        "relative to the spec: it lights the scene and shows behind it",
    )
    rotation: Union[float, Vec3] = Field(
        0.0, description="turns the image: radians about the vertical axis, or Euler XYZ [x, y, z]"
    )

    def tint(self) -> list[float]:
        """The colour as given, else dark grey (a plain background) or white (an image shown as it is)."""
        if self.color is not None:
            return list(self.color)
        return [1.0, 1.0, 1.0] if self.image is not None else [0.05, 0.05, 0.05]


class Scene(StrictModel):
    """The Blender scene: a .blend file, declared objects, or both."""

    file: str | None = Field(
        None, description="a .blend file made in Blender, relative to the spec; its objects are bound by name"
    )
    file_scene: BlenderName | None = Field(
        None, description="which scene of the .blend to use; needed when the file has more than one"
    )
    objects: dict[BlenderName, SceneObject] = Field(
        default_factory=dict, description="objects to build (added to the file's scene, if any)"
    )
    world: World | None = Field(None, description="background; default: the file's world, or dark grey")
    max_image_pixels: int = Field(
        MAX_IMAGE_PIXELS,
        ge=1,
        description=(
            "the most pixels an image may have (textures, the sky, heightmaps, an MJCF model's textures and height "
            "fields), read from its header before it is (default 8192 x 8192): raise it for a larger image you trust"
        ),
    )

    @model_validator(mode="after")
    def _file_scene_needs_a_file(self) -> "Scene":
        if self.file_scene is not None and self.file is None:
            raise ValueError("file_scene names a scene of the .blend in 'file', and there is no file")
        return self
