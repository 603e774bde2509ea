"""Visual PointMaze (issue 21): OGBench's point maze seen through a 64x64 chase camera.

OGBench's ``MazeEnv(ob_type='pixels')`` repaints the floor as a colour gradient of position,
greys the walls, drops the goal marker and the torso light, and renders 64x64 RGB with
``mujoco.Renderer``. Its stock ``point.xml`` has no ``back`` camera, so without one OGBench shows
a fixed top-down view of the whole maze. The authors add a chase camera to the point's body
(docs/reference.md §14): pos (0, -2.5, 5), xyaxes (1 0 0 0 2 1), mode ``trackcom``, a view
that follows the robot, so the task is partially observable. We add the same camera through
``MjSpec`` to the model OGBench builds (offline; nothing is downloaded) and render from it.

A frame is a pure function of (maze, x, y, render settings): the point's qpos is set, its
velocity zeroed, kinematics recomputed and the scene drawn. One model, one ``MjData`` and one
``mujoco.Renderer`` (one GL context) serve every frame of a :class:`FrameRenderer`.

Dynamics, tasks and the start/goal protocol are the point maze's (``families/maze/pointmaze.py``): the
visual env is a :class:`~fmctd_dist.families.maze.pointmaze.PointMaze` that can also draw what it sees.
"""

from __future__ import annotations

import os
import threading

import numpy as np

from fmctd_dist.families.maze.pointmaze import PointMaze
from fmctd_dist.errors import DeviceError
from fmctd_dist.registry import require_family

os.environ.setdefault("MUJOCO_GL", "egl")  # headless; read when mujoco is first imported
# Mesa's llvmpipe spawns one raster thread per core; on a busy 2-core machine one thread rendered
# ~4x faster (docs/results.md section 13). Read when the first GL context is made.
os.environ.setdefault("LP_NUM_THREADS", "1")

VISUAL_FAMILY = "visual-pointmaze"
IMAGE_SIZE = 64  # OGBench's visual envs: 64x64x3 uint8
CAMERA = "back"  # the authors' chase camera, added to the point's body
CAMERA_POS = (0.0, -2.5, 5.0)  # relative to the torso body at qpos = 0
CAMERA_XYAXES = (1.0, 0.0, 0.0, 0.0, 2.0, 1.0)  # x right; y forward-up: looks along +y, tilted down
REFERENCE_SHADOWSIZE = 4096  # MuJoCo's default shadow map: what OGBench's own renderer draws
GL_FIX = ("headless rendering needs an EGL driver: set MUJOCO_GL=egl before Python starts (our modules set it "
          "when it is unset) and install Mesa's EGL and DRI libraries (Debian: apt-get install libegl1 "
          "libegl-mesa0 libgl1-mesa-dri; this project's machine image has them)")


def point_env_name(name: str) -> str:
    """``visual-pointmaze-medium`` -> ``pointmaze-medium`` (the maze, tasks and data it shares)."""
    return require_family(name, (VISUAL_FAMILY,), "the visual maze renderer").removeprefix("visual-")


def _gl_error(e: BaseException) -> DeviceError:
    backend = os.environ.get("MUJOCO_GL", "<unset>")
    return DeviceError(f"MuJoCo could not open a GL context (MUJOCO_GL={backend}): {type(e).__name__}: {e}. "
                       f"{GL_FIX}")


class FrameRenderer:
    """Renders the visual maze at given point positions, reusing one model, MjData and GL context.

    ``camera="back"``: the chase camera (the paper's partially observed task); ``camera=None``:
    OGBench's fixed top-down view of the whole maze. A GL context belongs to the thread that made
    it: render from that thread (``render_states`` keeps one renderer per thread).
    """

    def __init__(self, name: str, camera: str | None = CAMERA, shadowsize: int = REFERENCE_SHADOWSIZE,
                 size: int = IMAGE_SIZE):
        self.name = name
        self.point_name = point_env_name(name)
        if camera not in (CAMERA, None):
            raise ValueError(f"camera={camera!r}: use {CAMERA!r} (chase) or None (top-down)")
        if isinstance(shadowsize, bool) or not isinstance(shadowsize, int) or shadowsize < 0:
            raise ValueError(f"shadowsize={shadowsize!r} must be a non-negative int (4096 = MuJoCo's default)")
        self.camera, self.shadowsize, self.size = camera, shadowsize, size
        try:
            import mujoco  # deferred: importing it loads the GL backend MUJOCO_GL names
        except Exception as e:  # e.g. MUJOCO_GL=osmesa without libOSMesa: PyOpenGL fails inside the import
            raise _gl_error(e) from None
        self._mj = mujoco
        _check_gl(size)
        self.model, top_down = _build_model(self.point_name, size)
        self.model.vis.quality.shadowsize = shadowsize
        self.data = mujoco.MjData(self.model)
        self.view = CAMERA if camera else top_down
        try:
            self.renderer = mujoco.Renderer(self.model, height=size, width=size)
        except Exception as e:  # ImportError (no libEGL), mujoco.FatalError, RuntimeError: all mean no GL
            raise _gl_error(e) from None

    def render(self, xy: np.ndarray) -> np.ndarray:
        """xy [N, 2] world positions -> uint8 [N, size, size, 3] frames (velocity 0, kinematics only)."""
        xy = np.asarray(xy, dtype=np.float64)
        if xy.ndim != 2 or xy.shape[1] != 2:
            raise ValueError(f"xy has shape {xy.shape}; expected [N, 2] positions")
        if not np.isfinite(xy).all():
            raise ValueError("xy holds NaN or inf; positions must be finite")
        out = np.empty((len(xy), self.size, self.size, 3), dtype=np.uint8)
        for i, p in enumerate(xy):
            self.data.qpos[:2] = p
            self.data.qvel[:] = 0.0
            self._mj.mj_forward(self.model, self.data)
            self.renderer.update_scene(self.data, camera=self.view)
            self.renderer.render(out=out[i])
        return out

    def close(self) -> None:
        self.renderer.close()


def load_llvm_users_first() -> None:
    """Import torch's compiler stack (which loads triton, when installed) before the first GL context.

    Mesa's EGL (llvmpipe) loads its own LLVM; triton, imported later in the same process (torch does so the
    first time it builds an optimizer or compiles), then segfaults on the clash. Measured on this image:
    render a frame, then ``torch.optim.AdamW(...)`` -> SIGSEGV in ``triton/knobs.py``; in the other order
    both work. ~2 s, once per process.
    """
    try:
        import torch._dynamo  # noqa: F401  (imports triton if it is installed)
    except ImportError:
        pass


def _check_gl(size: int) -> None:
    """Open and free one GL context, so a missing backend is one DeviceError before any env is built."""
    import mujoco

    load_llvm_users_first()
    try:
        ctx = mujoco.GLContext(size, size)  # None when MUJOCO_GL's backend failed to import
        ctx.make_current()
        ctx.free()
    except Exception as e:  # ImportError, AttributeError / TypeError from a half-loaded backend, FatalError
        raise _gl_error(e) from None


def _build_model(point_name: str, size: int):
    """(MjModel with the ``back`` camera and OGBench's pixel-mode floor, OGBench's top-down MjvCamera)."""
    import mujoco
    import ogbench

    try:
        env = ogbench.make_env_and_datasets(f"{point_name}-navigate-v0", env_only=True, ob_type="pixels",
                                            width=size, height=size, render_mode="rgb_array")
    except Exception as e:  # pixel mode opens a renderer in OGBench's constructor
        if "GL" in f"{type(e).__name__}{e}" or isinstance(e, (ImportError, mujoco.FatalError)):
            raise _gl_error(e) from None
        raise
    u = env.unwrapped
    spec = mujoco.MjSpec.from_file(u.fullpath)
    if spec.camera(CAMERA) is None:  # the authors' OGBench fork has it in point.xml already
        cam = spec.body("torso").add_camera(name=CAMERA, pos=list(CAMERA_POS),
                                            mode=mujoco.mjtCamLight.mjCAMLIGHT_TRACKCOM)
        cam.alt.type = mujoco.mjtOrientation.mjORIENTATION_XYAXES
        cam.alt.xyaxes = list(CAMERA_XYAXES)
    model = spec.compile()
    # OGBench repaints the floor texture after compiling (gradient of position); copy its pixels.
    assert model.tex_data.shape == u.model.tex_data.shape
    model.tex_data[:] = u.model.tex_data
    top_down = u.custom_camera
    u.custom_renderer.close()
    env.close()
    return model, top_down


_RENDERERS: dict[tuple, FrameRenderer] = {}


def render_states(maze: str, xy: np.ndarray, *, camera: str | None = CAMERA,
                  shadowsize: int = REFERENCE_SHADOWSIZE) -> np.ndarray:
    """Frames of the visual maze ``maze`` with the point at ``xy`` [N, 2] -> uint8 [N, 64, 64, 3].

    A pure function of its arguments (same inputs, same bytes); the renderer behind it is made
    once per (maze, camera, shadowsize, thread) and reused.
    """
    key = (maze, camera, shadowsize, threading.get_ident())
    if key not in _RENDERERS:
        _RENDERERS[key] = FrameRenderer(maze, camera=camera, shadowsize=shadowsize)
    return _RENDERERS[key].render(xy)


class VisualPointMaze(PointMaze):
    """A PointMaze (same dynamics, tasks, start/goal protocol and success) that also draws its view.

    ``reset``/``step`` return positions as the point maze does; ``image()`` is the 64x64 frame
    the robot sees now and ``goal_image()`` the frame at the goal (OGBench's ``render_goal``).
    """

    def __init__(self, name: str, protocol: str = "fixed", shadowsize: int = REFERENCE_SHADOWSIZE):
        super().__init__(point_env_name(name), protocol)
        self.visual_name = name
        self.frames = FrameRenderer(name, shadowsize=shadowsize)

    def image(self) -> np.ndarray:
        """uint8 [64, 64, 3]: the chase camera's view at the point's current position."""
        return self.frames.render(self.position()[None])[0]

    def goal_image(self) -> np.ndarray:
        return self.frames.render(self.goal[None])[0]

    def close(self) -> None:
        self.frames.close()
        super().close()
