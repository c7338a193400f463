"""Load a scene XML with this package's plugins and find the sensor rigs it declares.

A scene is loaded in the active Mitsuba variant: the entry point (a command's ``main``, a test
fixture, a notebook's first cell) chooses it with :func:`nidar_mi.backend.set_variant`; this
module never chooses one. Loading runs the material loader pass (:func:`nidar_mi.materials.expand_scene_xml`: ``nidar_material``
BSDFs by name, and the RGB-only twin) and the label pass (:func:`nidar_mi.labels.strip_labels`: the
``label`` / ``instance`` attributes of shapes) before Mitsuba parses the XML. Any failure becomes a
:class:`~nidar_mi.errors.NidarError` with one line naming the file and the cause.
"""

from __future__ import annotations

import os
import re
import warnings
from dataclasses import dataclass, field

from .backend import active_variant
from .errors import NidarError
from .labels import SceneLabels, strip_labels

__all__ = [
    "LoadedScene",
    "load_scene",
    "load_scene_text",
    "read_scene_xml",
    "RGB_EMITTER_MARKERS",
]

#: Substrings of an emitter's description that betray an RGB or float radiance (D65-shaped in the
#: spectral variants, hence empty past 830 nm).
RGB_EMITTER_MARKERS = ("D65Spectrum", "SRGBEmitterSpectrum", "SRGBReflectanceSpectrum")


@dataclass
class LoadedScene:
    """A loaded scene and its sensors, each list sorted by sensor id.

    Attributes:
        path: the XML file.
        scene: the ``mi.Scene``.
        variant: the Mitsuba variant it was loaded in.
        lidars: ``lidar`` sensors.
        cameras: ``perspective`` and ``thinlens`` sensors (other sensor types are not rendered:
            a warning names them).
        rgb_twin: whether materials were replaced by their RGB appearance.
        labels: the semantic class and instance each shape declares
            (:mod:`nidar_mi.labels.scene_labels`).
    """

    path: str
    scene: object
    variant: str
    lidars: list = field(default_factory=list)
    cameras: list = field(default_factory=list)
    rgb_twin: bool = False
    labels: SceneLabels = field(default_factory=SceneLabels)

    @property
    def weather(self):
        """The weather the scene's LiDARs scan in (their ``fog``, ``rain``, ``snow``, or what a
        render set on them), which its cameras render through: a
        :class:`nidar_mi.weather.Weather`, or None when clear.

        Raises:
            NidarError: the LiDARs disagree (the cameras need one weather).
        """
        seen = {s.id(): getattr(s, "weather", None) for s in self.lidars}
        kinds = {w for w in seen.values()}
        if len(kinds) > 1:
            said = ", ".join(f"'{k}' {w.describe() if w else 'clear'}" for k, w in seen.items())
            raise NidarError(
                f"{self.path}: the lidars see different weather ({said}); the cameras need one: "
                "give every lidar the same fog, rain and snow, or set them for all (`weather`)"
            )
        return next(iter(kinds), None)

    def rgb_only_emitters(self) -> list[str]:
        """Ids of emitters whose radiance is RGB/float (nothing meaningful past 830 nm)."""
        out = []
        for e in self.scene.emitters():
            text = str(e)
            if any(m in text for m in RGB_EMITTER_MARKERS):
                out.append(e.id() or type(e).__name__)
        return out


def _expand(xml: str, rgb_twin: bool) -> str:
    try:
        from .materials import expand_scene_xml
    except ImportError:  # material library not installed in this build
        if rgb_twin or "nidar_material" in xml:
            raise NidarError("the material library (nidar_mi.materials) is not available") from None
        return xml
    return expand_scene_xml(xml, rgb_twin=rgb_twin)


def _one_line(err: Exception) -> str:
    lines = [ln.strip() for ln in str(err).strip().splitlines() if ln.strip()]
    text = " ".join(lines) if lines else type(err).__name__
    text = re.sub(r"\[[a-z_]+\.cpp:\d+\]\s*", "", text)  # drop "[parser.cpp:123]"
    text = re.sub(
        r"(?:Error w|W)hile loading string \(line (\d+), col (\d+)\):", r"line \1, col \2:", text
    )
    return text


#: One file of an include chain in Mitsuba's nested messages: its name, line and column.
_LOADING = re.compile(r"(?:Error w|W)hile loading (.+?) \(line (\d+), col (\d+)\):\s*")
_INCLUDING = re.compile(r"while processing <include>:\s*")


def _include_error(path: str, text: str) -> str | None:
    """One short line for an error inside included files (None when no include is involved).

    Mitsuba nests one "Error while loading FILE (line, col): while processing <include>:"
    per level, up to 15 levels: a cycle (a file including itself, directly or not) becomes
    ``scene include cycle: a.xml -> b.xml -> a.xml``, a chain deeper than Mitsuba allows
    ``scene includes nested deeper than 15 levels: a.xml -> ... -> p.xml``, and any other error
    ``in b.xml (included from a.xml), line L, col C: message``.
    """
    marks = list(_LOADING.finditer(text))
    if len(marks) < 2 or not _INCLUDING.match(text, marks[0].end()):
        return None
    top = os.path.dirname(os.path.abspath(path))

    def name(f: str) -> str:
        return os.path.relpath(f, top) if os.path.isabs(f) else f

    chain = [name(path)] + [name(m.group(1)) for m in marks[1:]]
    for j, f in enumerate(chain):
        if f in chain[:j]:
            return "scene include cycle: " + " -> ".join(chain[chain.index(f) : j + 1])
    last = marks[-1]
    message = text[last.end() :].strip()
    if "include recursion depth" in message:
        depth = re.search(r"depth of (\d+)", message)
        levels = depth.group(1) if depth else str(len(chain) - 1)
        return (
            f"scene includes nested deeper than {levels} levels: {chain[0]} -> ... -> {chain[-1]}"
        )
    via = " <- ".join(reversed(chain[:-1]))
    return f"in {chain[-1]} (included from {via}), line {last.group(2)}, col {last.group(3)}: {message}"


#: Mitsuba's words for a mesh plugin that failed: the line of its element, its type, the reason.
_MESH_FAILED = re.compile(
    r"line (\d+), col \d+\): failed to instantiate shape plugin of type \"(ply|obj|serialized)\": (.*)"
)
#: A mesh loader's own parse error (kept: it says what is wrong in the file).
_LOADER_SAID = re.compile(r"(?:^|Error while loading \w+ file )\"[^\"]*\": (.*)")


def _mesh_error(xml: str, text: str) -> str | None:
    """One line of ours for a mesh that did not load (None when no mesh plugin failed): the
    file named by the failing element, and the loader's reason when it gave one."""
    m = _MESH_FAILED.search(text)
    if not m:
        return None
    line, kind, said = int(m.group(1)), m.group(2), re.sub(r"^\[\w+\]\s*", "", m.group(3))
    element = "\n".join(xml.splitlines()[line - 1 : line + 20])
    named = re.search(r'name="filename"\s+value="([^"]*)"', element)
    what = f"the {kind.upper()} mesh {named.group(1)}" if named else f"a {kind.upper()} mesh"
    reason = _LOADER_SAID.search(said)
    why = (
        reason.group(1).rstrip("!. ") if reason else "a corrupt file, or not a mesh of that format"
    )
    return f"cannot load {what}: {why}"


def _check_meshes(path: str, xml: str) -> None:
    """Refuse, before Mitsuba reads them, mesh files that are not files or not of their format
    by their first bytes (a PLY header, an OBJ's text): Mitsuba's own words on such files do not
    name them."""
    import xml.etree.ElementTree as ET

    from .io.atomic import file_problem

    try:
        root = ET.fromstring(xml)
    except ET.ParseError:
        return  # Mitsuba reports it
    base = os.path.dirname(os.path.abspath(path))
    for shape in root.iter("shape"):
        kind = shape.get("type")
        named = [e.get("value") for e in shape if e.get("name") == "filename"]
        if kind not in ("ply", "obj") or not named or not named[0] or "$" in named[0]:
            continue
        mesh = os.path.join(base, named[0])
        problem = file_problem(mesh, f"{kind.upper()} mesh file")
        if problem:
            raise NidarError(f"{path}: {named[0]}: {problem}")
        with open(mesh, "rb") as f:
            head = f.read(1 << 16)
        if kind == "ply":
            bad = not head.startswith(b"ply") or b"end_header" not in head
            end = head.find(b"end_header")
            bad = bad or any(c > 127 for c in head[:end])
            why = "not a PLY file (no ASCII 'ply' ... 'end_header' header)"
        else:
            bad = b"\0" in head
            try:
                head.decode("utf-8")
            except UnicodeDecodeError as e:
                bad = bad or e.start < len(head) - 4  # a character cut at the block's end is fine
            why = "not an OBJ file (not text)"
        if bad:
            raise NidarError(f"{path}: {named[0]}: {why}")


def _load_error(path: str, err: Exception, xml: str = "") -> str:
    """Mitsuba's message on a scene that did not load, as one short line."""
    text = re.sub(r"\[[a-z_]+\.cpp:\d+\]\s*", "", " ".join(str(err).split()))
    return _include_error(path, text) or _mesh_error(xml, text) or _one_line(err)


def read_scene_xml(path: str, *, rgb_twin: bool = False) -> tuple[str, SceneLabels]:
    """The XML of a scene file as Mitsuba is given it (materials of the library expanded, the
    shapes' labels taken out) and the labels, without Mitsuba: every check of the file that
    needs no renderer (it is a readable regular file, well-formed XML, known materials, valid
    labels), e.g. for a whole folder of scenes before any is rendered.

    Raises:
        NidarError: one line naming the file.
    """
    from .io.atomic import file_problem

    problem = file_problem(path, "scene file")
    if problem:
        raise NidarError(f"{path}: {problem}")
    try:
        with open(path, encoding="utf-8") as f:
            xml = f.read()
    except (OSError, UnicodeDecodeError) as e:
        raise NidarError(f"{path}: cannot read ({e})") from None
    try:
        xml = _expand(xml, rgb_twin)
        return strip_labels(xml)
    except NidarError as e:
        raise NidarError(f"{path}: {e}") from None
    except Exception as e:
        raise NidarError(f"{path}: {_one_line(e)}") from None


def load_scene(
    path: str,
    *,
    variant: str | None = None,
    rgb_twin: bool = False,
    params: dict[str, str] | None = None,
    labels: bool = True,
) -> LoadedScene:
    """Load a scene file.

    Args:
        path: scene XML.
        variant: the Mitsuba variant the caller expects (None: the active one); it must be
            the active one (set at the entry point by :func:`nidar_mi.backend.set_variant`).
        rgb_twin: load the RGB-only twin (every material replaced by its sRGB appearance).
        params: values for the scene's ``<default name=...>`` parameters (``$name`` in the XML).
        labels: read the shapes' labels. Labelled shapes stay apart, which slows ray casting on
            scenes of thousands of shapes (a generated city: ~7x per scan); False drops the
            labels (every point ``unlabeled``) and lets Mitsuba merge meshes that share a BSDF.

    Raises:
        NidarError: missing/unreadable/malformed file, an invalid plugin parameter (the
            plugin's one-line message, :func:`nidar_mi.plugins.parameter_error`), or no
            spectral variant active (or another than ``variant``).
    """
    xml, declared = read_scene_xml(path, rgb_twin=rgb_twin)
    if not labels:
        declared = SceneLabels()
    variant = active_variant(variant)
    import mitsuba as mi

    from . import plugins

    _check_meshes(path, xml)
    resolver = mi.file_resolver()
    scene_dir = os.path.dirname(os.path.abspath(path))
    resolver.prepend(scene_dir)
    try:
        # Mitsuba merges meshes that share a BSDF into one shape; labelled shapes stay apart.
        optimize = not (declared.classes or declared.instances)
        values = {k: str(v) for k, v in (params or {}).items()}
        scene = mi.load_string(xml, optimize=optimize, **values)
    except Exception as e:
        raise NidarError(
            f"{path}: {plugins.parameter_error(e) or _load_error(path, e, xml)}"
        ) from None

    lidars, cameras = _sensors(path, scene, variant)
    return LoadedScene(
        path=path,
        scene=scene,
        variant=variant,
        lidars=lidars,
        cameras=cameras,
        rgb_twin=rgb_twin,
        labels=declared,
    )


def load_scene_text(xml: str, name: str = "scene.xml", **kwargs) -> LoadedScene:
    """Load a scene from its XML text (a scene a study builds in memory).

    The text is written to ``name`` in a temporary folder, loaded by :func:`load_scene` and
    the folder removed (the loaded scene keeps nothing of the file), so the scene may name no
    file by a relative path.

    Args:
        xml: the scene XML.
        name: the file name messages give the scene.
        **kwargs: the keyword arguments of :func:`load_scene`.
    """
    import tempfile

    with tempfile.TemporaryDirectory(prefix="nidar_mi_scene-") as tmp:
        path = os.path.join(tmp, name)
        with open(path, "w", encoding="utf-8") as f:
            f.write(xml)
        return load_scene(path, **kwargs)


def _sensors(path: str, scene, variant: str) -> tuple[list, list]:
    """The scene's LiDARs and cameras, each sorted by id; a warning names any other sensor (not
    rendered), a camera with an empty film is refused."""
    from . import plugins
    from .camera import CAMERA_CLASSES

    lidar_cls = plugins.plugin_module("lidar", variant).LidarSensor
    sensors = sorted(scene.sensors(), key=lambda s: s.id())
    lidars = [s for s in sensors if isinstance(s, lidar_cls)]
    cameras = [s for s in sensors if s.class_name() in CAMERA_CLASSES]
    others = [f"'{s.id()}' ({s.class_name()})" for s in sensors if s not in lidars + cameras]
    if others:
        warnings.warn(
            f"{path}: sensor(s) {', '.join(others)} not rendered: only lidar, perspective and "
            "thinlens sensors are",
            RuntimeWarning,
            stacklevel=3,
        )
    _check_poses(path, lidars, cameras)
    for cam in cameras:
        W, H = (int(v) for v in cam.film().crop_size())
        if W < 1 or H < 1:
            raise NidarError(
                f"{path}: camera '{cam.id()}' has a {W}x{H} film (width and height must be >= 1)"
            )
    return lidars, cameras


def _check_poses(path: str, lidars: list, cameras: list) -> None:
    """Refuse a LiDAR whose ``to_world`` is not a rigid, right-handed pose
    (:func:`nidar_mi.geometry.se3.rigid_pose_problem`): a scaled pose would scale every range,
    a mirrored one flip the scan, a NaN one fail only after the work. A camera's pose must be
    finite and rigid too (Mitsuba itself refuses a scaled one); a mirrored camera, which some
    exporters write to flip the image, is left to Mitsuba."""
    import numpy as np

    from .geometry.se3 import POSE_TOLERANCE, rigid_pose_problem

    for kind, sensors in (("lidar", lidars), ("camera", cameras)):
        for sensor in sensors:
            T = np.array(sensor.world_transform().matrix.numpy(), dtype=np.float64).reshape(4, 4)
            problem = rigid_pose_problem(T)
            if problem and not (kind == "camera" and problem.startswith("mirrors")):
                raise NidarError(
                    f"{path}: {kind} '{sensor.id()}': to_world {problem}; a sensor's pose must be "
                    f"a right-handed rotation and a translation (tolerance {POSE_TOLERANCE:g})"
                )
