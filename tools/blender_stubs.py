"""Just enough of Blender for BlenderProc's BOP writer (`bproc.writer.write_bop`) to run in a plain
Python, with no Blender: tools/make_bop_fixtures.py runs the writer's own code on these.

What write_bop reads of Blender, and what stands in for it here:
  - `bpy.context.scene`: frame_start, frame_end, frame_current, frame_set(frame) (each object takes
    the pose keyed at the frame, or the nearest earlier one, as Blender's constant extrapolation
    does), render.resolution_x/y and pixel_aspect_x/y, and the camera: an object whose `data`
    holds the lens, sensor and shift that BlenderProc's CameraUtility turns into K and back;
  - objects (`bpy.types.Object`): matrix_world (= matrix_basis, as for an object without a
    parent), custom properties by key, keyframe_insert, hide_render, scale, and a mesh whose
    `vertices[i].co` and `polygons[i].vertices` are what MeshObject.mesh_as_trimesh reads;
  - `mathutils` is Blender's own math library (PyPI's standalone `mathutils`, the same C code in
    single precision), less `bvhtree`/`kdtree`, which BlenderProc only names in annotations;
  - `bpy.types` and `bmesh.types`: names in annotations only, each a bare class;
  - `git`: imported by BlenderProc's V-HACD wrapper, which write_bop never calls.
"""

import os
import sys
import types
from types import SimpleNamespace

import mathutils


class TypeNames(types.ModuleType):
    """A module whose every public name is a bare class: BlenderProc names bpy's types in its
    signatures only."""

    def __getattr__(self, name):
        if name.startswith("__"):
            raise AttributeError(name)
        cls = type(name, (), {})
        setattr(self, name, cls)
        return cls


class BlenderObject:
    """A bpy.types.Object as BlenderProc's MeshObject and writers use it."""

    def __init__(self, name, data=None):
        self.name = name
        self.data = data
        self.parent = None
        self.hide_render = False
        self.scale = (1.0, 1.0, 1.0)
        self.matrix_basis = mathutils.Matrix.Identity(4)
        self._properties = {}
        self._keyframes = {}

    @property
    def matrix_world(self):
        return self.matrix_basis.copy()

    @matrix_world.setter
    def matrix_world(self, matrix):
        self.matrix_basis = mathutils.Matrix(matrix)

    def __getitem__(self, key):
        return self._properties[key]

    def __setitem__(self, key, value):
        self._properties[key] = value

    def __contains__(self, key):
        return key in self._properties

    def items(self):
        return self._properties.items()

    def keyframe_insert(self, data_path, frame):
        # Blender keys location and rotation apart; both come back together here.
        self._keyframes[frame] = self.matrix_basis.copy()

    def show_frame(self, frame):
        if self._keyframes:
            earlier = [f for f in self._keyframes if f <= frame]
            key = max(earlier) if earlier else min(self._keyframes)
            self.matrix_basis = self._keyframes[key].copy()


def camera_data():
    """A camera's data block with Blender's defaults (50 mm lens on a 36 × 24 mm sensor)."""
    return SimpleNamespace(lens_unit="MILLIMETERS", lens=50.0, angle=0.0, sensor_fit="AUTO", sensor_width=36.0,
                           sensor_height=24.0, shift_x=0.0, shift_y=0.0, clip_start=0.1, clip_end=1000.0)


class Scene:
    """bpy.context.scene: the frame range, the render size and the active camera."""

    def __init__(self, width, height):
        self.frame_start = self.frame_end = self.frame_current = 0
        self.render = SimpleNamespace(resolution_x=width, resolution_y=height, pixel_aspect_x=1.0, pixel_aspect_y=1.0)
        self.camera = BlenderObject("Camera", camera_data())
        self.objects = [self.camera]

    def frame_set(self, frame):
        self.frame_current = frame
        for obj in self.objects:
            obj.show_frame(frame)


def blender_mesh(vertices, faces):
    """A mesh data block: vertex coordinates and triangles."""
    return SimpleNamespace(vertices=[SimpleNamespace(co=tuple(v)) for v in vertices],
                           polygons=[SimpleNamespace(vertices=tuple(int(i) for i in f)) for f in faces])


def new_scene(width, height):
    """A fresh scene made bpy.context's, as a new BlenderProc run starts with."""
    scene = Scene(width, height)
    sys.modules["bpy"].context.scene = scene
    return scene


def install(bop_toolkit):
    """Puts the stand-ins in sys.modules and bop_toolkit's checkout on the path, so that
    `import blenderproc.api.writer` works and write_bop's setup step finds bop_toolkit_lib there
    instead of pip-installing it from git."""
    # Lets blenderproc be imported from a script that `blenderproc run` did not start.
    os.environ["OUTSIDE_OF_THE_INTERNAL_BLENDER_PYTHON_ENVIRONMENT_BUT_IN_RUN_SCRIPT"] = "1"
    bpy = types.ModuleType("bpy")
    bpy.types = TypeNames("bpy.types")
    # BlenderProc's WriterUtility names `bpy.context.scene.camera` in an annotation at import.
    bpy.context = SimpleNamespace(scene=Scene(1, 1))
    bmesh = types.ModuleType("bmesh")
    bmesh.types = TypeNames("bmesh.types")
    sys.modules.update({"bpy": bpy, "bmesh": bmesh, "git": types.ModuleType("git")})
    for name in ["bvhtree", "kdtree"]:
        module = TypeNames(f"mathutils.{name}")
        sys.modules[module.__name__] = module
        setattr(mathutils, name, module)
    sys.path.insert(0, bop_toolkit)
    from blenderproc.python.utility.SetupUtility import SetupUtility

    # write_bop asks it for bop_toolkit (from git) and PyOpenGL; both are on the path already.
    SetupUtility.setup_pip = staticmethod(lambda *args, **kwargs: None)
