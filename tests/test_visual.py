"""Visual PointMaze (issue 21): rendering, the chase camera, config guards and the frames store."""

from __future__ import annotations

import hashlib
import os
import shutil
import subprocess
import sys
import xml.etree.ElementTree as ET

import numpy as np
import pytest

from conftest import TINY_DATA
from fmctd_dist.config import REPO_ROOT, load_config
from fmctd_dist.families.maze.data import load_dataset
from fmctd_dist.families.visual.env import (CAMERA, CAMERA_POS, CAMERA_XYAXES, FrameRenderer, VisualPointMaze,
                                              point_env_name, render_states)
from fmctd_dist.errors import ConfigError, DatasetError, DeviceError

MEDIUM = "visual-pointmaze-medium"
OPEN = np.array([[8.0, 8.0], [12.0, 8.0]])  # medium: cells (3, 3) and (3, 4), both free


@pytest.fixture(scope="module")
def chase():
    r = FrameRenderer(MEDIUM)
    yield r
    r.close()


def test_frames_shape_dtype_and_determinism(chase):
    xy = np.array([[0.0, 0.0], [4.0, 0.0], [20.0, 20.0]])
    a = chase.render(xy)
    assert a.shape == (3, 64, 64, 3) and a.dtype == np.uint8
    assert np.array_equal(a, chase.render(xy))
    assert np.array_equal(a, render_states(MEDIUM, xy))  # the pure function, its own renderer
    assert np.array_equal(chase.render(xy[1:2])[0], a[1])  # a frame does not depend on the batch


def test_image_changes_with_position(chase):
    a, b = chase.render(np.array([[0.0, 0.0], [20.0, 20.0]])).astype(int)
    assert np.abs(a - b).mean() > 20


def test_chase_camera_follows_the_robot(chase):
    """Camera pose vs body pose through MuJoCo data: a fixed offset and a fixed orientation."""
    offsets = []
    for p in np.array([[0.0, 0.0], [8.0, 8.0], [20.0, 4.0]]):
        chase.render(p[None])
        torso = chase.model.body("torso").id
        offsets.append(chase.data.cam_xpos[0] - chase.data.subtree_com[torso])
        x, y = np.array(CAMERA_XYAXES[:3]), np.array(CAMERA_XYAXES[3:])
        z = np.cross(x, y)
        want = np.stack([x, y / np.linalg.norm(y), z / np.linalg.norm(z)], axis=1)  # columns: camera axes
        np.testing.assert_allclose(chase.data.cam_xmat[0].reshape(3, 3), want, atol=1e-9)
    np.testing.assert_allclose(offsets, [np.array(CAMERA_POS) - [0, 0, 0.7]] * 3, atol=1e-9)


def test_chase_view_keeps_its_layout_as_the_floor_colour_changes(chase):
    """One cell along open floor: the ball stays where it is in the frame; the floor under it changes colour."""
    a, b = chase.render(OPEN).astype(int)
    ball = (slice(20, 36), slice(26, 38))  # the ball stays in the frame's centre
    assert np.abs(a[ball] - b[ball]).mean() < 2
    floor = (slice(44, 52), slice(8, 56))  # the floor just in front of the ball
    shift = a[floor].mean((0, 1)) - b[floor].mean((0, 1))
    assert np.abs(shift).max() > 10  # one cell = 4 units of a 192-level gradient over the 32-unit floor
    assert np.abs(a[floor] - b[floor] - shift).mean() < 3  # a uniform colour change, not a new layout


def test_chase_frames_equal_the_authors_xml_route(tmp_path, monkeypatch, chase):
    """OGBench's own pixel env with the camera written into point.xml renders our bytes exactly."""
    import ogbench.locomaze.point as point
    from ogbench.locomaze.maze import make_maze_env

    ref = FrameRenderer(MEDIUM)  # ours, built from stock point.xml; the reference shadow map, as OGBench draws
    tree = ET.parse(point.PointEnv.xml_file)
    ET.SubElement(tree.find('.//body[@name="torso"]'), "camera", name=CAMERA, pos="0 -2.5 5",
                  xyaxes="1 0 0 0 2 1", mode="trackcom")
    xml = tmp_path / "point_back.xml"
    tree.write(xml)
    monkeypatch.setattr(point.PointEnv, "xml_file", str(xml))
    env = make_maze_env("point", "maze", maze_type="medium", ob_type="pixels", width=64, height=64,
                        render_mode="rgb_array", camera_name=CAMERA)
    env.reset(seed=0)
    env.set_xy(OPEN[0])
    env.data.qvel[:] = 0
    import mujoco

    mujoco.mj_forward(env.model, env.data)
    assert np.array_equal(env.render(), ref.render(OPEN[:1])[0])
    env.close()


def test_top_down_view_equals_ogbench(chase):
    import ogbench

    env = ogbench.make_env_and_datasets("pointmaze-medium-navigate-v0", env_only=True, ob_type="pixels",
                                        width=64, height=64, render_mode="rgb_array")
    u = env.unwrapped
    u.reset(options=dict(task_id=1))
    u.set_xy(OPEN[1])
    assert np.array_equal(u.render(), FrameRenderer(MEDIUM, camera=None).render(OPEN[1:])[0])
    env.close()


def test_fast_shadow_map_stays_close_to_the_reference(chase):
    """visual.shadowsize=1024 (the default) vs MuJoCo's 4096: only shadow-edge pixels differ."""
    rng = np.random.default_rng(0)
    cells = np.array([[0, 0], [4, 0], [20, 0], [0, 16], [12, 12], [20, 20], [16, 4], [8, 12]], dtype=float)
    xy = cells + rng.uniform(-1.3, 1.3, size=cells.shape)
    ref = chase.render(xy).astype(int)
    fast = FrameRenderer(MEDIUM, shadowsize=1024).render(xy).astype(int)
    d = np.abs(fast - ref)
    assert d.mean() < 1.0  # measured 0.19 (medium) / 0.30 (large) over 60 frames
    assert (d.max(-1) > 8).mean() < 0.01  # measured 0.2-0.3% of pixels


def test_visual_env_shares_the_point_maze_protocol():
    env = VisualPointMaze(MEDIUM, shadowsize=1024)
    r = env.reset(task_id=1, seed=0)
    np.testing.assert_array_equal(r.obs, [0.0, 0.0])
    np.testing.assert_array_equal(r.goal, [20.0, 20.0])
    img = env.image()
    assert img.shape == (64, 64, 3) and img.dtype == np.uint8
    env.step(np.array([1.0, 0.0]))
    assert not np.array_equal(env.image(), img)
    assert env.goal_image().shape == (64, 64, 3)
    env.close()


def test_bad_names_and_inputs(chase):
    with pytest.raises(ConfigError, match="did you mean 'visual-pointmaze-medium'"):
        FrameRenderer("visual-pointmaze-meduim")
    with pytest.raises(ConfigError, match="visual maze renderer"):
        point_env_name("pointmaze-medium")
    with pytest.raises(ValueError, match=r"\[N, 2\]"):
        chase.render(np.zeros(2))
    with pytest.raises(ValueError, match="finite"):
        chase.render(np.array([[np.nan, 0.0]]))


def test_no_gl_is_one_clear_error(monkeypatch):
    import mujoco

    def no_gl(*args, **kwargs):
        raise ImportError("Cannot initialize a EGL device display")

    monkeypatch.setattr(mujoco, "Renderer", no_gl)
    with pytest.raises(DeviceError, match="MUJOCO_GL=egl.*libegl1"):
        FrameRenderer(MEDIUM)


def test_visual_env_is_refused_by_maze_only_code():
    """Maze-only code gets one ConfigError naming the visual maze's own jobs, not a crash deeper down."""
    with pytest.raises(ConfigError, match=r"is a visual-pointmaze env.*jobs/train_visual.py"):
        from fmctd_dist.families.maze.geometry import maze_geometry

        maze_geometry(MEDIUM)
    cfg = load_config([f"env={MEDIUM}"])
    assert cfg.env.name == MEDIUM and cfg.visual.shadowsize == 1024
    with pytest.raises(ConfigError, match="visual.frames"):
        load_config([f"env={MEDIUM}", "visual.frames=0"])


def _visual_cfg(root, *extra):
    words = [w for w in TINY_DATA if not w.startswith("env=")]
    return load_config([f"env={MEDIUM}", *words, f"data.root={root}", "visual.frames=6", *extra],
                       method="mctd")


def test_frames_store_round_trip(tiny_dataset, tmp_path):
    from fmctd_dist.families.visual.frame_sets import (episode_frames, episode_subset, frames_dir, load_frames,
                                                       make_frames)

    data_cfg, _ = tiny_dataset
    cfg = _visual_cfg(data_cfg.data.root)
    copy = tmp_path / "copy"
    path, m = make_frames(cfg, progress=False)
    shutil.copytree(path, copy)
    shutil.rmtree(path)
    path2, m2 = make_frames(cfg, progress=False)  # rendered again from scratch
    assert m2["sha256"] == m["sha256"] == hashlib.sha256((copy / "frames.npz").read_bytes()).hexdigest()
    data = load_dataset(data_cfg)
    for split, n in (("train", 6), ("val", 1)):  # val: 6 x data.val_fraction, at least 1
        images, index, _ = load_frames(cfg, split)
        assert images.shape == (n, 64, 64, 3) and index.tolist() == m["frame_index" if n == 6 else "val_frame_index"]
        e, s = divmod(index, data_cfg.data.episode_steps)
        xy = getattr(data, split)[e, s]
        assert np.array_equal(images, render_states(MEDIUM, xy, shadowsize=1024))  # state -> image
    other = _visual_cfg(data_cfg.data.root, "visual.frames_seed=1")
    assert frames_dir(other) != path
    few = _visual_cfg(data_cfg.data.root, "visual.episodes=2")
    ids = episode_subset(few)
    assert len(ids) == 2 and np.array_equal(ids, episode_subset(few))

    class Positions:  # stands in for FrameRenderer: a frame is its position (rendering is tested above)
        render = staticmethod(lambda xy: xy)

    got = list(episode_frames(few, data, Positions()))
    assert [g[0] for g in got] == ids.tolist()
    for e, frames in got:
        np.testing.assert_array_equal(frames, data.train[e])  # every step of the episode, in order
    np.testing.assert_array_equal(episode_subset(_visual_cfg(data_cfg.data.root, "visual.episodes=0")),
                                  np.arange(data_cfg.data.episodes))
    with open(path / "frames.npz", "r+b") as f:  # one flipped byte -> refused
        f.seek(-1, 2)
        b = f.read(1)
        f.seek(-1, 2)
        f.write(bytes([b[0] ^ 1]))
    with pytest.raises(DatasetError, match="sha256"):
        load_frames(cfg)


def test_frames_need_the_point_dataset(tmp_path):
    from fmctd_dist.families.visual.frame_sets import make_frames

    with pytest.raises(DatasetError, match="make_dataset.py env=pointmaze-medium"):
        make_frames(_visual_cfg(tmp_path), progress=False)
    with pytest.raises(ConfigError, match="visual.episodes=20 exceeds"):
        from fmctd_dist.families.visual.frame_sets import episode_subset

        episode_subset(_visual_cfg(tmp_path, "visual.episodes=20"))


def test_render_frames_job_refuses_and_names_the_fix(tmp_path):
    """The job as a subprocess: a missing point dataset is one `error:` line with the command."""
    out = subprocess.run([sys.executable, "jobs/render_frames.py", f"env={MEDIUM}", f"data.root={tmp_path}"],
                         cwd=REPO_ROOT, capture_output=True, text=True, timeout=120)
    assert out.returncode == 2, out.stderr
    assert out.stderr.startswith("error: ") and "jobs/make_dataset.py env=pointmaze-medium" in out.stderr


def test_a_gl_backend_that_fails_to_load_is_one_error_line(tiny_dataset):
    """A real failure, not a monkeypatch: MUJOCO_GL names no backend -> the job's one `error:` line."""
    import os

    data_cfg, _ = tiny_dataset
    env = {**os.environ, "MUJOCO_GL": "no-such-backend"}
    out = subprocess.run([sys.executable, "jobs/render_frames.py", f"env={MEDIUM}", f"data.root={data_cfg.data.root}",
                          *[w for w in TINY_DATA if not w.startswith("env=")], "visual.frames=2"],
                         cwd=REPO_ROOT, capture_output=True, text=True, timeout=120, env=env)
    assert out.returncode == 2, out.stderr
    assert "error: MuJoCo could not open a GL context (MUJOCO_GL=no-such-backend)" in out.stderr
    assert "libegl1" in out.stderr and "Traceback" not in out.stderr


def test_an_optimizer_after_rendering_does_not_crash_the_process():
    # Mesa's EGL loads LLVM; triton (imported by torch's first optimizer) then segfaulted in the same process.
    # A fresh interpreter, since this test process has already imported torch's compiler stack (conftest).
    code = ("from fmctd_dist.families.visual.env import FrameRenderer\n"
            "import numpy as np, torch\n"
            "FrameRenderer('visual-pointmaze-medium').render(np.zeros((1, 2)))\n"
            "torch.optim.AdamW([torch.nn.Parameter(torch.zeros(2))])\n"
            "print('ok')\n")
    out = subprocess.run([sys.executable, "-c", code], cwd=REPO_ROOT, capture_output=True, text=True, timeout=300,
                         env={**os.environ, "MUJOCO_GL": "egl", "OMP_NUM_THREADS": "1"})
    assert out.returncode == 0 and out.stdout.strip().endswith("ok"), (out.returncode, out.stderr[-2000:])
